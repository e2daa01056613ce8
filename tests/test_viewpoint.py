"""The viewpoint model of exploration (`planning/viewpoint.py`) and how exploration uses it:
poses that see the frontier, and the end of exploring when no reachable pose does."""

from __future__ import annotations

import math

import numpy as np

from actors import BufferPool
from actors.firmware.nav.factory import make_nav
from actors.firmware.planning.viewpoint import (
    RAYS,
    REVEAL_DEPTH_CELLS,
    FaceField,
    _gains,
    face_field,
    face_mask,
    seen_face,
    viewpoints,
)
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

RES = 5.0
VIEW = {"robot_radius_cm": 7.5, "margin_cm": 0.0, "stand_radius_cm": 12.5,
        "max_incidence_deg": 70.0, "min_face_cells": 2}
RANGE_CM = 250.0


def _views(grid: GridMap, rover: tuple[float, float], **kw: object) -> list:
    """`viewpoints` of ``grid`` with the mapper's quantities, ``kw`` overriding them."""
    return viewpoints(face_field(grid, range_cm=RANGE_CM), rover, **{**VIEW, **kw})


def _seen(grid: GridMap, point: tuple[float, float], max_incidence_deg: float = 70.0
          ) -> list[tuple[float, float]]:
    return seen_face(face_field(grid, range_cm=RANGE_CM), point,
                     max_incidence_deg=max_incidence_deg)


def _room(rows: int, cols: int) -> np.ndarray:
    """A free room of ``rows`` x ``cols`` cells inside one-cell walls, unknown outside,
    with two cells of unknown border round the walls."""
    cells = np.full((rows + 6, cols + 6), UNKNOWN, dtype=np.int8)
    cells[2:rows + 4, 2:cols + 4] = OCCUPIED
    cells[3:rows + 3, 3:cols + 3] = FREE
    return cells


def _grid(cells: np.ndarray, origin_cm: tuple[float, float] = (0.0, 0.0)) -> GridMap:
    return GridMap(cells, RES, origin_cm)


AT_ROVER = (-100.0, -100.0)
"""A map origin that puts the mapper's start pose (0, 0) on cell (20, 20)."""


def _shadowed_room() -> np.ndarray:
    """A 3 x 2 m room with a 50 cm box in the middle and, behind it (seen from the west),
    the unknown shadow the box cast: 50 cm deep, as wide as the box."""
    cells = _room(40, 60)
    cells[20:30, 25:35] = OCCUPIED  # the box: rows (y) 20-29, cols (x) 25-34
    cells[21:29, 26:34] = UNKNOWN  # its inside, never seen
    cells[20:30, 35:45] = UNKNOWN  # the shadow east of it
    return cells


def test_a_frontier_hidden_behind_an_obstacle_is_approached_from_a_pose_that_sees_it() -> None:
    """The rover west of the box: the best viewpoint lies beside or beyond the box, where
    its rays enter the shadow steeply, not on the rover's side where they would only
    graze past the box."""
    grid = _grid(_shadowed_room())
    rover = (40.0, 125.0)
    views = _views(grid, rover)
    assert views
    best = views[0]
    assert best.point_cm[0] > 25 * RES  # east of the box's west face
    seen = _seen(grid, best.point_cm)
    assert len(seen) >= 2
    assert all(175.0 <= x <= 225.0 and 100.0 <= y <= 150.0 for x, y in seen)  # the shadow
    # it stands where the rover can turn: its turning radius (2.5 cells) all known free
    r, c = grid.world_to_cell(*best.point_cm)
    window = grid.cells[r - 2:r + 3, c - 2:c + 3]
    assert np.all(window == FREE)


def test_rays_that_graze_the_frontier_do_not_count() -> None:
    """An unknown patch in the open seen from the north-west, a little above its northern
    face: the rays meeting the western face are steep and count at any limit; those
    meeting the northern face farther east graze it, and count only when grazing is
    allowed."""
    cells = _room(40, 60)
    cells[20:30, 35:45] = UNKNOWN
    grid = _grid(cells)
    point = grid.cell_to_world(34, 28)
    steep = set(_seen(grid, point, 60.0))
    loose = set(_seen(grid, point, 89.0))
    north_row = grid.cell_to_world(29, 0)[1]
    assert steep and steep < loose
    assert all(y == north_row and x > grid.cell_to_world(0, 36)[0] for x, y in loose - steep)


def _nook_room() -> np.ndarray:
    """A room with a corridor 20 cm wide leaving its east wall and turning north after
    50 cm; its end is unknown. No pose the rover can stand on sees round the bend."""
    cells = _room(40, 40)
    cells = np.pad(cells, ((0, 20), (0, 30)), constant_values=UNKNOWN)
    cells[17:23, 42:60] = OCCUPIED  # the corridor's walls...
    cells[18:22, 43:55] = FREE  # ...its eastward leg, 4 cells wide
    cells[17:45, 54:60] = OCCUPIED
    cells[18:40, 55:59] = FREE  # its northward leg
    cells[40:45, 55:59] = UNKNOWN  # the unseen end
    return cells


def test_a_frontier_no_reachable_pose_can_see_ends_exploration() -> None:
    """The only frontier lies round a bend of a corridor too narrow to stand in: no
    viewpoint, and exploration ends (no frontier) instead of a drive that reveals
    nothing."""
    cells = _nook_room()
    grid = _grid(cells, AT_ROVER)
    assert face_mask(cells)[40, 56:58].all()  # the frontier exists...
    assert _views(grid, (0.0, 0.0)) == []  # ...but no pose sees it
    nav = make_nav("mapper", pool=BufferPool(4))
    nav.grid = grid
    assert not nav.explorer.choose(keep=False)
    assert nav.ex.no_frontier and nav.ex.follower is None


def test_a_gap_of_a_cell_or_two_in_a_mapped_surface_is_not_a_frontier() -> None:
    """A wall with two cells unknown where the rest of it is mapped occupied: the gap is
    the surface's edge, not a way into the unknown; four unknown cells are an opening."""
    for gap, expected in ((2, False), (4, True)):
        cells = _room(30, 30)
        cells[15:15 + gap, 2] = UNKNOWN
        assert face_mask(cells)[15:15 + gap, 2].any() == expected
        assert bool(_views(_grid(cells), (80.0, 80.0))) == expected


def test_face_cells_seen_repeatedly_and_never_revealed_leave_the_face() -> None:
    """The rover stands where it sees the shadow; after three decisions with the map
    unchanged those face cells are unseeable and the shadow is no longer a frontier."""
    cells = _room(40, 60)
    cells[20:30, 35:45] = UNKNOWN  # an unknown patch in the open, nothing to hide it
    nav = make_nav("mapper", pool=BufferPool(4))
    nav.grid = _grid(cells, AT_ROVER)
    for _ in range(2):
        nav.explorer.judge_sightings()
        assert nav.ex.unseeable == []
    nav.explorer.judge_sightings()
    assert len(nav.ex.unseeable) >= 2
    assert nav.ex.sightings == {} or all(n < 3 for n in nav.ex.sightings.values())


def _gains_by_walking(field: FaceField, cand: np.ndarray, max_incidence_deg: float
                      ) -> tuple[np.ndarray, list[int], np.ndarray]:
    """`_gains` ray by ray and cell by cell, as the module docstring states it."""
    ny, nx = field.sub.cells.shape
    width = nx + 2 * field.pad
    steep_cos = math.cos(math.radians(max_incidence_deg))
    gains, entries, distinct = np.zeros(cand.size), [], np.zeros(cand.size, dtype=np.int64)
    for i, k in enumerate(cand.tolist()):
        base = (k // nx + field.pad) * width + k % nx + field.pad
        cells: set[int] = set()
        for ray in range(RAYS):
            path = [int(field.code[base + off]) for off in field.offsets[ray]]
            first = next((s for s in range(field.n_steps) if path[s] != 0), None)
            if first is None or path[first] & 3 != 3:
                continue  # no face cell met within range
            hit = base + int(field.offsets[ray, first])
            er, ec = hit // width - field.pad, hit % width - field.pad
            enx, eny = field.nxn[er, ec], field.nyn[er, ec]
            if not (field.direction[ray, 0] * enx + field.direction[ray, 1] * eny >= steep_cos
                    or (enx == 0 and eny == 0)):
                continue  # grazing
            entries.append(er * nx + ec)
            cells.add(er * nx + ec)
            for d in range(first, first + REVEAL_DEPTH_CELLS):
                if path[d] == 1 or (d > first and path[d - 1] >= 4):
                    break  # an occupied cell, or past the unknown cell beside one
                if path[d] & 3 >= 2:
                    gains[i] += field.weight[d]
        distinct[i] = len(cells)
    return gains, entries, distinct


def test_gains_match_a_ray_by_ray_walk() -> None:
    """Every pose of the shadowed room (reachable or not): the vectorised gains, entered
    face cells and their distinct counts equal those of walking each ray cell by cell."""
    grid = _grid(_shadowed_room())
    field = face_field(grid, range_cm=RANGE_CM)
    ny, nx = field.sub.cells.shape
    cand = np.arange(0, ny * nx, 7, dtype=np.int64)
    for limit in (60.0, 70.0, 89.0):
        gains, entries, distinct = _gains(field, cand, limit)
        want_gains, want_entries, want_distinct = _gains_by_walking(field, cand, limit)
        assert want_gains.max() > 0.0
        np.testing.assert_allclose(gains, want_gains, rtol=1e-12)
        assert entries.tolist() == want_entries
        assert distinct.tolist() == want_distinct.tolist()
