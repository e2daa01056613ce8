"""Next-best-view exploration: poses from which the LIDAR sees the unknown, scored by
what they would reveal per unit of travel.

Why poses, not frontier cells
    Driving to a frontier cell does not mean seeing past it: a pocket behind furniture
    is seen only from where a ray enters it steeply enough, and a frontier that no
    reachable pose sees is not worth a trip at all. So exploration chooses a
    *viewpoint*: a reachable cell with a clear, not too grazing line of sight to the
    unknown, within the sensor's useful range.

Model (physical quantities)
    * The frontier's *face*: unknown cells with a known-free 4-neighbour (where a ray
      leaves the known free space), except gaps of one or two cells in a mapped
      surface (`face_mask`). Its normal, pointing into the unknown, is the
      gradient of the blurred unknown mask.
    * A candidate pose sees along ``RAYS`` rays (the LIDAR spins: heading does not
      matter) out to ``range_cm``, stepping one cell. A ray crosses known-free cells;
      the first cell it meets that is not free must be a face cell (an occupied cell
      ends it, and an unknown cell that is not on the face is one seen through a gap
      between cells), met at an incidence (angle between the ray and the face's
      normal) of at most ``max_incidence_deg``: grazing rays clear nothing near the
      surface they reach (`mapping.sensor_model`'s grazing margin) and a fraction of
      a degree of pose error moves them a cell.
    * What such a ray reveals: the unknown cells along it, from the face up to
      ``REVEAL_DEPTH_CELLS`` into the unknown, the first occupied cell, or the first
      unknown cell beside an occupied one (that one counted): behind a mapped surface's
      edge lies most likely more of that surface, or the obstacle's inside, not open
      ground (a ragged edge along a wall is worth its own cells, not a doorway's).
      Each step is
      weighed by the area it stands for (``r * d_theta * dr``, in cells), so the gain
      is the visible unknown area [cells], whatever the number of rays.
    * Candidates (bounded): the standable cell nearest a point a few cells back from a
      face cell along its normal and along two directions turned from it (the views
      that see a pocket), for at most
      ``FACE_SAMPLES`` face cells, and at most ``LATTICE_SAMPLES`` reachable cells within
      range of the face; both spread over the map in blocks (`_spread`).
    * Reachable: the rover's centre may be there (obstacles inflated by the rover's
      footprint, unknown blocked) and a breadth-first search from the rover reaches it;
      its travel is that search's step distance. The rover may pass a narrow gap on
      the way, but it stands only where it can turn (its turning radius known clear:
      an unknown cell may be an obstacle's unseen back), to leave again.
    * Score: gain per unit of travel, ``gain / (travel + TRAVEL_FLOOR_CM)``; the floor
      is the travel a stop costs anyway (turning, slowing, a revolution's wait), so a
      tiny gain next to the rover does not beat a large one a little farther.

Cost
    One breadth-first search and one gather of ``candidates x RAYS x steps`` cells
    (at most 72 x 72 x 50) per decision, then ``REVEAL_DEPTH_CELLS`` more cells for each
    ray that enters the face steeply (about one in seven): about 3 ms on the known part
    of a room's map.

Reference
    Gonzalez-Banos and Latombe, "Navigation Strategies for Exploring Indoor
    Environments", IJRR 21(10), 2002 (visible unknown area against travel);
    Bircher et al., "Receding Horizon Next-Best-View Planner for 3D Exploration",
    ICRA 2016 (ray-cast information gain, unknown seen through the frontier).

Frame and units
    Positions [cm] in the map frame; gains [cells]; grids as in
    `actors.firmware.mapping.occupancy`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from actors.firmware.arrays import distinct, nonzero_2d, pad_border
from actors.firmware.planning.frontier import steps_from
from actors.firmware.planning.planner import inflate
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

__all__ = ["Viewpoint", "FaceField", "face_field", "viewpoints", "seen_face", "face_mask",
           "face_normals", "RAYS", "REVEAL_DEPTH_CELLS", "FACE_SAMPLES", "LATTICE_SAMPLES",
           "TRAVEL_FLOOR_CM"]

RAYS = 72
"""Rays per candidate pose (5 deg apart: a 20 cm gap subtends more than that from 2 m)."""
REVEAL_DEPTH_CELLS = 16
"""How far past the face a ray's unknown cells count [cells]: what lies deeper is not
known to be open (a wall may stand one cell behind the face), and a cap keeps a ragged
edge from weighing like a doorway into the unknown."""
FACE_SAMPLES = 16
"""Face cells whose views are candidates, at most."""
LATTICE_SAMPLES = 24
"""Candidates spread over the reachable cells within range of the face, at most."""
TRAVEL_FLOOR_CM = 100.0
"""Travel a stop costs anyway [cm] (turning toward the route, the moves' stops, waiting
for a revolution): the score's denominator is travel plus this."""
_BACKOFF_CELLS = (3, 6, 10, 16)
"""Distances [cells] back from a face cell along a view direction tried for its candidate,
nearest first: the first with a standable cell within ``_SNAP_CELLS`` is taken."""
_SNAP_CELLS = 3
"""How far a point back along a view direction may move to a standable cell [cells] (a
pose beside a wall that looks down a pocket along it)."""
_VIEW_TURNS_DEG = (0.0, -40.0, 40.0)
"""Directions from a face cell to its candidate poses, from its normal [deg]: head-on, and
turned within the incidence a ray may have (a pocket's mouth may be seen only from one
side)."""
_CODE_FREE, _CODE_OCC, _CODE_UNKNOWN, _CODE_FACE = 0, 1, 2, 3
_KIND, _EDGE = 3, 4
"""A cell's code: its kind (the low two bits), plus ``_EDGE`` for an unknown cell beside an
occupied one."""


@dataclass(frozen=True, slots=True)
class Viewpoint:
    """A pose to drive to and what it would show."""

    point_cm: tuple[float, float]
    """The cell's centre (x, y) [cm]."""
    gain_cells: float
    """Unknown area it would reveal [cells]."""
    travel_cm: float
    """Step distance from the rover [cm]."""
    face_cells: int = 0
    """Distinct face cells its rays enter [cells]."""

    @property
    def score(self) -> float:
        """Gain per unit of travel [cells per cm]."""
        return self.gain_cells / (self.travel_cm + TRAVEL_FLOOR_CM)


def face_mask(cells: np.ndarray) -> np.ndarray:
    """Unknown cells with a free 4-neighbour, except those in a gap of one or two cells
    between occupied cells along a row or a column: bool, the shape of ``cells``.

    Why the gaps go: a mapped surface missing a cell or two is a surface the scans did
    not hit squarely there, not a way into the unknown; behind it lies the obstacle's
    unknown inside, which no pose reveals. A pocket's mouth is wider (20 cm between a
    sofa and a wall maps three or four cells wide)."""
    free = pad_border(cells == FREE, 1, False)
    near = free[:-2, 1:-1] | free[2:, 1:-1] | free[1:-1, :-2] | free[1:-1, 2:]
    occ = pad_border(cells == OCCUPIED, 2, False)
    ny, nx = cells.shape
    pinched = np.zeros(cells.shape, dtype=bool)
    for dr, dc in ((0, 1), (1, 0)):
        def at(k: int, dr: int = dr, dc: int = dc) -> np.ndarray:
            return occ[2 + k * dr:2 + k * dr + ny, 2 + k * dc:2 + k * dc + nx]
        pinched |= at(-1) & (at(1) | at(2))
        pinched |= at(1) & at(-2)
    return (cells == UNKNOWN) & near & ~pinched


def face_normals(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (x, y) of the unknown region, pointing into it, per cell (0 where the
    unknown mask is flat): the gradient of the unknown mask blurred by [1, 2, 1]^2."""
    u = pad_border((cells == UNKNOWN).astype(np.float32), 2, 1.0)
    u = u[:-2] + 2.0 * u[1:-1] + u[2:]
    u = u[:, :-2] + 2.0 * u[:, 1:-1] + u[:, 2:]
    gx = 0.5 * (u[1:-1, 2:] - u[1:-1, :-2])
    gy = 0.5 * (u[2:, 1:-1] - u[:-2, 1:-1])
    norm = np.hypot(gx, gy)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(norm > 1e-6, 1.0 / norm, 0.0)
    return gx * scale, gy * scale


def _ray_offsets(steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per ray and step (RAYS, steps): row and column offsets [cells] from the pose's cell
    centre, the ray's direction (x, y), and each step's area weight [cells]."""
    theta = np.arange(RAYS) * (2.0 * math.pi / RAYS)
    r = np.arange(1, steps + 1, dtype=np.float64)
    dx, dy = np.cos(theta), np.sin(theta)
    dc = np.rint(np.outer(dx, r)).astype(np.int64)
    dr = np.rint(np.outer(dy, r)).astype(np.int64)
    weight = r * (2.0 * math.pi / RAYS)  # r * d_theta * dr with dr one cell
    return dr, dc, np.column_stack([dx, dy]), weight


@dataclass(frozen=True, slots=True, eq=False)
class FaceField:
    """What every pose's view of one map needs, made once per map (`face_field`): the
    known part of the map, its face and normals, and the cells coded and padded for the
    ray gathers."""

    grid: GridMap
    """The whole map."""
    sub: GridMap
    """Its known part, with a margin."""
    face: np.ndarray
    """`face_mask` of ``sub``, less the unseeable cells."""
    nxn: np.ndarray
    """Face normal x per cell of ``sub``."""
    nyn: np.ndarray
    """Face normal y per cell of ``sub``."""
    n_steps: int
    """Ray steps within the range [cells]."""
    code: np.ndarray
    """Flat cell codes of ``sub`` padded by ``pad`` cells of unknown."""
    pad: int
    """Padding [cells]."""
    offsets: np.ndarray
    """Flat offsets per ray and step (RAYS, n_steps + REVEAL_DEPTH_CELLS) in ``code``."""
    direction: np.ndarray
    """Each ray's direction (x, y), (RAYS, 2)."""
    weight: np.ndarray
    """Each step's area weight [cells]."""


def face_field(grid: GridMap, *, range_cm: float,
               unseeable_cm: Sequence[tuple[float, float]] = ()) -> FaceField:
    """The `FaceField` of ``grid`` for a sensor of ``range_cm``, without the face cells
    holding an ``unseeable_cm`` point [cm] (`seen_face`)."""
    res = grid.resolution_cm
    n_steps = max(1, math.ceil(range_cm / res))
    sub = grid.crop_known(margin_cells=2)
    cells = sub.cells
    face = _face(sub, unseeable_cm)
    nxn, nyn = face_normals(cells)
    pad = n_steps + REVEAL_DEPTH_CELLS + 1
    code = np.full(cells.shape, _CODE_UNKNOWN, dtype=np.int8)
    code[cells == FREE] = _CODE_FREE
    code[cells == OCCUPIED] = _CODE_OCC
    code[face] = _CODE_FACE
    code[(code >= _CODE_UNKNOWN) & _beside(cells == OCCUPIED)] += _EDGE
    code = pad_border(code, pad, _CODE_UNKNOWN).reshape(-1)
    width = cells.shape[1] + 2 * pad
    dr, dc, direction, weight = _ray_offsets(n_steps + REVEAL_DEPTH_CELLS)
    offsets = (dr * width + dc).astype(np.intp)
    return FaceField(grid, sub, face, nxn, nyn, n_steps, code, pad, offsets, direction,
                     weight)


def viewpoints(
    field: FaceField,
    rover_cm: tuple[float, float],
    *,
    robot_radius_cm: float,
    margin_cm: float,
    max_incidence_deg: float,
    stand_radius_cm: float | None = None,
    min_gain_cells: float = 1.0,
    min_face_cells: int = 1,
    blacklist: Iterable[tuple[float, float]] = (),
    blacklist_radius_cm: float = 0.0,
    snap_radius_cm: float = 30.0,
    also_cm: Sequence[tuple[float, float]] = (),
) -> list[Viewpoint]:
    """Reachable viewpoints revealing at least ``min_gain_cells``, best score first.

    Args:
        field: the map's `FaceField` (its range is the sensor's useful range).
        rover_cm: rover position (x, y) [cm].
        robot_radius_cm: the rover's footprint radius for reachability [cm].
        margin_cm: extra clearance from obstacles [cm].
        max_incidence_deg: steepest angle between a ray and the face's normal that
            still reveals what lies behind [deg].
        stand_radius_cm: a viewpoint needs this much known-free ground around it [cm]
            (the turning radius: the rover turns there to leave); None: only
            reachability counts.
        min_gain_cells: a viewpoint revealing less is left out [cells]...
        min_face_cells: ...and one seeing fewer face cells [cells] (a gap of a cell or
            two in a mapped surface, with an obstacle's unknown inside behind it, looks
            deep from anywhere).
        blacklist: points [cm] near which no viewpoint is offered...
        blacklist_radius_cm: ...within this distance [cm].
        snap_radius_cm: how far the rover's cell may move to a passable one [cm].
        also_cm: more points [cm] to score where reachable (the current target, so
            that it can be compared with the others).

    Returns:
        The viewpoints in decreasing score (ties: row-major order of their cells);
        empty when the map has no face or the rover reaches no cell that sees one.
    """
    sub, face = field.sub, field.face
    cells = sub.cells
    res = sub.resolution_cm
    if not face.any():
        return []
    travel = steps_from(sub, rover_cm, robot_radius_cm, margin_cm, snap_radius_cm)
    reach = travel >= 0
    if stand_radius_cm is not None:
        # the ground within the turning radius must be known clear: an unknown cell may
        # be the back of an obstacle
        reach &= ~inflate(cells != FREE, stand_radius_cm / res)
    if not reach.any():
        return []
    # samples are spread in blocks of the whole grid's cells, so they do not move as the
    # known part (the crop) grows
    grid = field.grid
    anchor = (round((sub.origin_cm[1] - grid.origin_cm[1]) / res),
              round((sub.origin_cm[0] - grid.origin_cm[0]) / res))
    extra = [sub.world_to_cell(*p) for p in also_cm]
    cand = _candidates(face, reach, field.nxn, field.nyn, field.n_steps, anchor, extra)
    if cand.size == 0:
        return []
    gain, _, faces = _gains(field, cand, max_incidence_deg)
    ny, nx = cells.shape
    rows, cols = cand // nx, cand % nx
    out: list[Viewpoint] = []
    bl = list(blacklist)
    for i in np.argsort(-gain / (travel[rows, cols] * res + TRAVEL_FLOOR_CM), kind="stable"):
        if gain[i] < min_gain_cells or faces[i] < min_face_cells:
            continue
        point = sub.cell_to_world(int(rows[i]), int(cols[i]))
        if any(math.dist(point, b) <= blacklist_radius_cm for b in bl):
            continue
        out.append(Viewpoint(point, float(gain[i]), float(travel[rows[i], cols[i]]) * res,
                             int(faces[i])))
    return out


def seen_face(field: FaceField, point_cm: tuple[float, float], *,
              max_incidence_deg: float) -> list[tuple[float, float]]:
    """The face cells [cm] a pose at ``point_cm`` sees (rays meet them first, steeply
    enough, within the field's range): what a viewpoint was chosen to reveal. Those
    still unknown after the rover looked at them cannot be revealed, and leave the
    face."""
    sub = field.sub
    r, c = sub.world_to_cell(*point_cm)
    ny, nx = sub.cells.shape
    if not (field.face.any() and 0 <= r < ny and 0 <= c < nx):
        return []
    _, entries, _ = _gains(field, np.array([r * nx + c]), max_incidence_deg)
    # centres rounded to a mm, so that the same cell gives the same point in every crop
    return [(round(x, 1), round(y, 1)) for x, y in (
        sub.cell_to_world(int(k) // nx, int(k) % nx) for k in distinct(entries))]


def _face(sub: GridMap, unseeable_cm: Sequence[tuple[float, float]]) -> np.ndarray:
    """`face_mask` of ``sub`` less the cells holding an ``unseeable_cm`` point."""
    face = face_mask(sub.cells)
    if len(unseeable_cm):
        pts = np.asarray(unseeable_cm, dtype=np.float64)
        ox, oy = sub.origin_cm
        rows = np.floor((pts[:, 1] - oy) / sub.resolution_cm).astype(np.int64)
        cols = np.floor((pts[:, 0] - ox) / sub.resolution_cm).astype(np.int64)
        ny, nx = face.shape
        keep = (rows >= 0) & (rows < ny) & (cols >= 0) & (cols < nx)
        face[rows[keep], cols[keep]] = False
    return face


def _candidates(face: np.ndarray, reach: np.ndarray, nxn: np.ndarray, nyn: np.ndarray,
                n_steps: int, anchor: tuple[int, int], extra: Sequence[tuple[int, int]]
                ) -> np.ndarray:
    """Flat indices (sorted, unique) of the candidate cells: head-on poses of face cells,
    reachable cells within range of the face (both spread by `_spread`), and the
    reachable ``extra`` cells."""
    ny, nx = face.shape
    fr, fc = _spread(face, FACE_SAMPLES, anchor)
    # per face cell and view direction (the normal, and turned either way by
    # _VIEW_TURNS), the standable cell nearest a point back along it (within
    # _SNAP_CELLS), the nearest such point first
    back = np.asarray(_BACKOFF_CELLS, dtype=np.float64)
    turn = np.radians(np.asarray(_VIEW_TURNS_DEG, dtype=np.float64))
    cos_t, sin_t = np.cos(turn), np.sin(turn)
    ux, uy = nxn[fr, fc], nyn[fr, fc]
    vx = ux[:, None] * cos_t - uy[:, None] * sin_t  # (faces, turns)
    vy = ux[:, None] * sin_t + uy[:, None] * cos_t
    pr = np.rint(fr[:, None, None] - vy[..., None] * back).astype(np.int64)
    pc = np.rint(fc[:, None, None] - vx[..., None] * back).astype(np.int64)
    k = _SNAP_CELLS
    dr, dc = np.mgrid[-k:k + 1, -k:k + 1]
    order = np.argsort(dr.ravel() ** 2 + dc.ravel() ** 2, kind="stable")
    dr, dc = dr.ravel()[order], dc.ravel()[order]  # nearest offsets first
    sr, sc = pr[..., None] + dr, pc[..., None] + dc  # (faces, turns, backs, offsets)
    inside = (sr >= 0) & (sr < ny) & (sc >= 0) & (sc < nx)
    ok = np.zeros(sr.shape, dtype=bool)
    ok[inside] = reach[sr[inside], sc[inside]]
    ok[(ux == 0) & (uy == 0)] = False
    flat_ok = ok.reshape(*ok.shape[:2], -1)  # backs x offsets, nearest back first
    first = np.argmax(flat_ok, axis=2)[..., None]
    has = np.take_along_axis(flat_ok, first, axis=2)[..., 0]
    head_on = (np.take_along_axis(sr.reshape(flat_ok.shape), first, axis=2)[..., 0][has] * nx
               + np.take_along_axis(sc.reshape(flat_ok.shape), first, axis=2)[..., 0][has])

    # reachable cells with a face cell in the square of half-side n_steps around them
    integral = np.zeros((ny + 1, nx + 1), dtype=np.int32)
    integral[1:, 1:] = face.astype(np.int32).cumsum(0).cumsum(1)
    r = np.arange(ny)
    c = np.arange(nx)
    r0, r1 = np.clip(r - n_steps, 0, ny), np.clip(r + n_steps + 1, 0, ny)
    c0, c1 = np.clip(c - n_steps, 0, nx), np.clip(c + n_steps + 1, 0, nx)
    near = (integral[r1][:, c1] - integral[r0][:, c1] - integral[r1][:, c0]
            + integral[r0][:, c0]) > 0
    lr, lc = _spread(reach & near, LATTICE_SAMPLES, anchor)
    lattice_idx = lr * nx + lc
    more = [r * nx + c for r, c in extra if 0 <= r < ny and 0 <= c < nx and reach[r, c]]
    return distinct(np.concatenate([head_on, lattice_idx, np.asarray(more, dtype=np.int64)]))


def _spread(mask: np.ndarray, most: int, anchor: tuple[int, int]
            ) -> tuple[np.ndarray, np.ndarray]:
    """At most ``most`` cells of ``mask`` spread over it: the first (row-major) in each
    square block of the whole grid's cells (``anchor``: the crop's first cell there),
    the blocks growing until few enough are left. Why blocks: a room's face is mostly
    ragged edges along walls, and cells taken evenly along the list would miss a short
    frontier; every part of the face gets its sample."""
    rows, cols = nonzero_2d(mask)
    side = max(1, math.isqrt(rows.size // max(1, most)))  # blocks of side^2 cells hold
    # at least one each, so fewer sides are never enough
    if rows.size > most:
        # count the blocks a side makes on a dense table of them (no sort), until few
        # enough; the cells are then picked as below
        r, c = rows + anchor[0], cols + anchor[1]
        r_low, c_low, c_high = int(r.min()), int(c.min()), int(c.max())
        while True:
            width = c_high // side - c_low // side + 1
            block = (r // side - r_low // side) * width
            block += c // side - c_low // side
            if np.count_nonzero(np.bincount(block)) <= most:
                break
            side += 1
    key = ((rows + anchor[0]) // side) * (1 << 20) + (cols + anchor[1]) // side
    _, first = np.unique(key, return_index=True)
    first.sort()
    return rows[first], cols[first]


def _gains(field: FaceField, cand: np.ndarray, max_incidence_deg: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unknown area [cells] each candidate would reveal (module docstring), the flat crop
    indices of the face cells the counted rays enter (unsorted, repeated), and per
    candidate how many distinct face cells they enter.

    Only the rays that enter the face steeply enough (about one in seven) are followed
    past their entry cell; the others count zero. Indices are ``intp``: numpy gathers
    with them several times faster than with 32-bit ones, which it converts first."""
    ny, nx = field.sub.cells.shape
    pad, code, offsets, n_steps = field.pad, field.code, field.offsets, field.n_steps
    direction, weight, nxn, nyn = field.direction, field.weight, field.nxn, field.nyn
    width = nx + 2 * pad
    base = (cand // nx + pad) * width + cand % nx + pad
    seen = code[base[:, None, None] + offsets[None, :, :n_steps]]  # (N, RAYS, steps)
    first = np.argmax(seen != _CODE_FREE, axis=2)  # the first cell that is not free
    n, rays = first.shape
    entry = np.take_along_axis(seen, first[..., None], axis=2)[..., 0]
    who, ray = nonzero_2d((entry & _KIND) == _CODE_FACE)  # rays entering the face
    first = first[who, ray]
    # the entry cell's normal: a face cell lies inside the crop
    hit = base[who] + offsets[ray, first]
    er, ec = hit // width - pad, hit % width - pad
    enx, eny = nxn[er, ec], nyn[er, ec]
    cos_in = direction[ray, 0] * enx + direction[ray, 1] * eny
    steep = np.flatnonzero((cos_in >= math.cos(math.radians(max_incidence_deg)))
                           | ((enx == 0) & (eny == 0)))
    who, ray, first = who[steep], ray[steep], first[steep]
    entries = er[steep] * nx + ec[steep]
    # the unknown cells from the entry on, up to the depth, the first occupied cell or
    # the first unknown cell beside an occupied one (that one counted)
    depth = first[:, None] + np.arange(REVEAL_DEPTH_CELLS)  # (counted rays, depth)
    after = code[base[who, None] + offsets[ray[:, None], depth]]
    go_on = after != _CODE_OCC
    go_on[:, 1:] &= after[:, :-1] < _EDGE
    open_ = np.logical_and.accumulate(go_on, axis=1) & ((after & _KIND) >= _CODE_UNKNOWN)
    area = np.zeros((n, rays))
    area[who, ray] = (open_ * weight[depth]).sum(axis=1)
    n_cells = ny * nx
    pairs = distinct(who * n_cells + entries)  # distinct (candidate, face cell)
    return area.sum(axis=1), entries, np.bincount(pairs // n_cells, minlength=n)


def _beside(mask: np.ndarray) -> np.ndarray:
    """Cells with a ``mask`` cell among their 8 neighbours or themselves."""
    pad = pad_border(mask, 1, False)
    ny, nx = mask.shape
    out = np.zeros(mask.shape, dtype=bool)
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            out |= pad[dr:dr + ny, dc:dc + nx]
    return out
