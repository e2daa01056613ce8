"""Log-odds occupancy grid, its sensor model and map snapshots
(actors.firmware.mapping.occupancy, sensor_model)."""

from __future__ import annotations

import numpy as np
import pytest

from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.mapping.sensor_model import grazing_shortening
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose


def small_grid() -> OccupancyGrid:
    """2 m x 2 m, 5 cm cells, centred on the start."""
    return OccupancyGrid(200, 200, 5)


def test_default_grid_covers_24_m_square_centred_on_start():
    """The default extent is 24 m x 24 m of 5 cm cells with (0, 0) in the middle."""
    g = OccupancyGrid()
    assert g.shape == (480, 480)
    assert g.origin_cm == (-1200.0, -1200.0)
    assert g.world_to_cell(0, 0) == (240, 240)
    assert g.cell_to_world(240, 240) == (2.5, 2.5)
    assert (g.cells() == UNKNOWN).all()


def test_one_ray_marks_the_hit_and_two_rays_free_the_cells_before_it():
    """A ray along +x of 50 cm marks cell 10 occupied at once; cells 0..9 turn free only
    when a second batch confirms them (one stray ray cannot open a wall)."""
    g = small_grid()
    changed = g.integrate(Pose(2.5, 2.5, 0), np.array([0.0]), np.array([50.0]))
    cells = g.cells()
    r, c = g.world_to_cell(2.5, 2.5)
    assert (cells[r, c:c + 10] == UNKNOWN).all()
    assert cells[r, c + 10] == OCCUPIED
    assert changed == 1
    changed = g.integrate(Pose(2.5, 2.5, 0), np.array([0.0]), np.array([50.0]))
    cells = g.cells()
    assert (cells[r, c:c + 10] == FREE).all()
    assert cells[r, c + 10] == OCCUPIED
    assert cells[r, c + 11] == UNKNOWN
    assert cells[r + 1, c] == UNKNOWN
    assert changed == 10


def test_angles_are_relative_to_the_heading():
    """A rover facing +y with a ray at -90 deg looks along +x."""
    g = small_grid()
    g.integrate(Pose(2.5, 2.5, 90), np.array([-90.0]), np.array([30.0]))
    r, c = g.world_to_cell(32.5, 2.5)
    assert g.cells()[r, c] == OCCUPIED


def test_no_return_clears_up_to_max_range_without_a_hit():
    """Range 0 means nothing within range: free along max_range_cm, nothing occupied."""
    g = small_grid()
    for _ in range(2):
        g.integrate(Pose(2.5, 2.5, 0), np.array([0.0]), np.array([0.0]))
    cells = g.cells()
    assert not (cells == OCCUPIED).any()
    r, c = g.world_to_cell(2.5, 2.5)
    assert (cells[r, c:] == FREE).all()  # max range 600 cm runs past the 1 m edge


def test_repeated_hits_clamp_and_one_free_pass_cannot_erase_a_confident_wall():
    """Log-odds are clamped; a confident wall survives one contrary ray but not many."""
    g = small_grid()
    pose = Pose(2.5, 2.5, 0)
    for _ in range(20):
        g.integrate(pose, np.array([0.0]), np.array([50.0]))
    assert g.log_odds().max() == pytest.approx(g.model.l_max)
    r, c = g.world_to_cell(52.5, 2.5)
    g.integrate(pose, np.array([0.0]), np.array([80.0]))
    assert g.cells()[r, c] == OCCUPIED
    for _ in range(20):
        g.integrate(pose, np.array([0.0]), np.array([80.0]))
    assert g.cells()[r, c] == FREE


def test_a_hit_is_not_cleared_by_another_ray_of_the_same_batch():
    """A grazing ray through a hit cell does not erase it within one batch."""
    g = small_grid()
    # both rays pass through / end in the cell at x in [50, 55)
    g.integrate(Pose(2.5, 2.5, 0), np.array([0.0, 0.0]), np.array([50.0, 90.0]))
    r, c = g.world_to_cell(52.5, 2.5)
    assert g.cells()[r, c] == OCCUPIED


def test_change_count_drops_to_zero_for_a_repeated_scan():
    """Integrating the same revolution again changes no cell's class."""
    g = small_grid()
    angles = np.arange(0, 360, 1.0)
    ranges = np.full(360, 80.0)
    first = g.integrate(Pose(0, 0, 0), angles, ranges)  # the hits
    second = g.integrate(Pose(0, 0, 0), angles, ranges)  # the free space, confirmed
    again = g.integrate(Pose(0, 0, 0), angles, ranges)
    assert first > 50 and second > 500
    assert again == 0
    assert g.changed_total == first + second
    assert g.batches == 3 and g.rays == 1080


def test_rays_leaving_the_grid_are_clipped():
    """Rays ending outside the grid update only the cells inside it."""
    g = small_grid()
    g.integrate(Pose(90, 90, 45), np.array([0.0, 180.0]), np.array([500.0, 10.0]))
    assert g.cells().shape == (40, 40)
    assert (g.cells() == OCCUPIED).sum() == 1  # only the short ray's hit is inside


@pytest.mark.parametrize(("angles", "ranges", "message"), [
    ([0.0, 1.0], [10.0], "must be 1-D of one length"),
    ([0.0], [-1.0], "ranges_cm must be finite and >= 0"),
    ([float("nan")], [10.0], "angles_deg must be finite"),
])
def test_integrate_rejects_bad_batches(angles, ranges, message):
    """A malformed batch is a ValueError with a clear message."""
    with pytest.raises(ValueError, match=message):
        small_grid().integrate(Pose(), np.array(angles), np.array(ranges))


def test_a_ray_grazing_its_wall_stops_clearing_farther_before_the_hit():
    """Returns from a flat wall 100 cm ahead, one every degree: the ray square on to it
    stops clearing half a cell before its hit, a ray meeting it at 70 deg about three
    times as far (0.5 / sin 20 deg), a ray with no hit not at all; no pull-back is
    longer than its ray."""
    angles = np.arange(-70.0, 71.0, 1.0)
    ranges = 100.0 / np.cos(np.radians(angles))
    has_hit = np.ones(angles.size, dtype=bool)
    has_hit[angles == 30.0] = False
    pull = grazing_shortening(angles, ranges, has_hit, 5.0, 0.5)
    by_angle = dict(zip(angles.tolist(), pull.tolist(), strict=True))
    assert by_angle[0.0] == pytest.approx(0.5, abs=0.01)
    assert by_angle[70.0] == pytest.approx(0.5 / np.sin(np.radians(20.0)), rel=0.1)
    assert by_angle[30.0] == 0.0
    assert (pull <= ranges / 5.0).all()


def test_cropped_cells_and_from_cells_round_trip():
    """The cropped upload rebuilds a grid with the same cells at the same places."""
    g = small_grid()
    g.integrate(Pose(10, -20, 30), np.arange(0, 360, 2.0), np.full(180, 40.0))
    cells, origin = g.cropped_cells()
    r0, r1, c0, c1 = g.bounds()
    assert cells.shape == (r1 - r0, c1 - c0)
    assert (cells != UNKNOWN).any(axis=1).all()  # no empty row: tight crop
    rebuilt = OccupancyGrid.from_cells(cells, g.resolution_cm, origin)
    np.testing.assert_array_equal(rebuilt.cells(), cells)
    # a point maps to the same class in both
    x, y = g.cell_to_world(r0 + 3, c0 + 5)
    rr, rc = rebuilt.world_to_cell(x, y)
    gr, gc = g.world_to_cell(x, y)
    assert rebuilt.cells()[rr, rc] == g.cells()[gr, gc]


def test_from_cells_rejects_out_of_range_values():
    """A received map with a value outside -1..100 is refused with its position."""
    bad = np.zeros((3, 3), dtype=np.int16)
    bad[1, 2] = 120
    with pytest.raises(ValueError, match=r"cells must hold -1..100, got 120 at \[1, 2\]"):
        OccupancyGrid.from_cells(bad, 5, (0, 0))


def test_gridmap_is_read_only_and_normalises_probabilities():
    """A snapshot's cells cannot be written; 0..49 read free, 50..100 occupied."""
    m = GridMap(np.array([[-1, 10, 49], [50, 99, 100]]), 5.0, (0, 0))
    np.testing.assert_array_equal(m.cells, [[-1, 0, 0], [100, 100, 100]])
    with pytest.raises(ValueError):
        m.cells[0, 0] = 0
    assert m.known_bounds() == (0, 2, 0, 3)
    assert m.crop(1, 2, 1, 3).origin_cm == (5.0, 5.0)


def test_known_bounds_is_the_box_of_the_known_cells_on_any_grid():
    """The box of the known cells, whether a row is read eight cells at a time (an int8
    grid of whole words) or cell by cell, on crops (views) too; None when none is known."""
    rng = np.random.default_rng(12)
    for trial in range(200):
        ny, nx = int(rng.integers(1, 30)), 8 * int(rng.integers(1, 6)) + int(trial % 3 == 0)
        cells = np.full((ny, nx), UNKNOWN, dtype=np.int8)
        if trial % 7:
            r0, c0 = int(rng.integers(0, ny)), int(rng.integers(0, nx))
            r1, c1 = int(rng.integers(r0, ny)) + 1, int(rng.integers(c0, nx)) + 1
            block = rng.choice([UNKNOWN, FREE, OCCUPIED], size=(r1 - r0, c1 - c0))
            block[0, int(rng.integers(0, c1 - c0))] = FREE  # every side of the box known
            block[-1, int(rng.integers(0, c1 - c0))] = OCCUPIED
            block[int(rng.integers(0, r1 - r0)), 0] = FREE
            block[int(rng.integers(0, r1 - r0)), -1] = FREE
            cells[r0:r1, c0:c1] = block
            want = (r0, r1, c0, c1)
        else:
            want = None
        grid = GridMap(cells, 5.0, (0.0, 0.0))
        assert grid.known_bounds() == want, trial
        wide = GridMap(cells.astype(np.int16), 5.0, (0.0, 0.0))
        assert wide.known_bounds() == want, trial
        wider = np.full((ny, nx + 9), UNKNOWN, dtype=np.int8)
        wider[:, 1:1 + nx] = cells
        view = GridMap(wider, 5.0, (0.0, 0.0)).crop(0, ny, 1, 1 + nx)  # not contiguous
        assert view.known_bounds() == want, trial
        assert ny == 1 or not view.cells.flags.c_contiguous


def test_bounds_of_empty_grid_is_none():
    """A grid with nothing known has no bounds."""
    assert small_grid().bounds() is None


def _classified(g: OccupancyGrid) -> np.ndarray:
    """The classes computed afresh from the log-odds (what the kept classes must equal)."""
    m = g.model
    lo = g.log_odds()
    return np.where(lo < m.free_threshold, FREE, np.where(lo > m.occ_threshold, OCCUPIED,
                                                          UNKNOWN)).astype(np.int8)


def test_kept_classes_follow_every_update_and_fill():
    """The classes the grid keeps per cell (snapshots read them) equal a fresh
    classification of the log-odds after scans that free, hit and re-clear cells, and
    after seeding unknown cells; an unchanged grid gives the same snapshot again."""
    rng = np.random.default_rng(3)
    g = small_grid()
    for i in range(40):
        pose = Pose(rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(0, 360))
        ranges = rng.uniform(10, 90, 90) * (rng.random(90) > 0.1)
        g.integrate(pose, np.arange(0, 360, 4.0), ranges)
        snap = g.snapshot()
        np.testing.assert_array_equal(snap.cells, _classified(g), err_msg=f"batch {i}")
    assert g.snapshot() is snap  # nothing changed class since
    seed = np.full((10, 12), FREE, dtype=np.int8)
    seed[2:4] = OCCUPIED
    before = g.cells()[:10, :12]
    assert (before == UNKNOWN).any()
    assert g.fill_unknown(0, 0, seed)  # unknown cells of the grid's corner get seeded
    np.testing.assert_array_equal(g.snapshot().cells, _classified(g))
    np.testing.assert_array_equal(g.cells()[:10, :12],
                                  np.where(before == UNKNOWN, seed, before))
    assert not g.fill_unknown(0, 0, seed)  # now known: nothing to seed
    with pytest.raises(ValueError, match="off the grid"):
        g.fill_unknown(35, 0, seed)


def _reference_integrate(g: OccupancyGrid, pose: Pose, angles: np.ndarray,
                         ranges: np.ndarray) -> None:
    """The batch update written plainly: every sample of every ray, `np.unique`,
    `np.add.at` for the hits, their bilinear weights in the counts' float32 (what
    `integrate` must equal, bit for bit)."""
    m, res = g.model, g.resolution_cm
    ox, oy = g.origin_cm
    ny, nx = g.shape
    has_hit = (ranges > 0) & (ranges <= m.max_range_cm)
    length_c = np.where(has_hit, ranges, m.max_range_cm) / res
    theta = np.radians(angles + pose.heading_deg)
    cos, sin = np.cos(theta), np.sin(theta)
    px, py = (pose.x - ox) / res, (pose.y - oy) / res
    free_c = length_c - grazing_shortening(angles, ranges, has_hit, res,
                                           m.grazing_margin_cells)
    cells: set[int] = set()
    for c, s, f in zip(cos, sin, free_c, strict=True):
        t = np.arange(int(np.ceil(max(f, 0.0) / m.ray_step))) * m.ray_step
        col, row = np.floor(c * t + px).astype(int), np.floor(s * t + py).astype(int)
        ok = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
        cells.update((row[ok] * nx + col[ok]).tolist())
    hx = px + cos[has_hit] * length_c[has_hit]
    hy = py + sin[has_hit] * length_c[has_hit]
    hr, hc = np.floor(hy).astype(int), np.floor(hx).astype(int)
    ok = (hr >= 0) & (hr < ny) & (hc >= 0) & (hc < nx)
    hit = np.unique(hr[ok] * nx + hc[ok])
    free = np.array(sorted(cells - set(hit.tolist())), dtype=np.int64)
    lo = g._log_odds.reshape(-1)
    lo[free] = np.clip(lo[free] + np.float32(m.l_free), m.l_min, m.l_max)
    lo[hit] = np.clip(lo[hit] + np.float32(m.l_occ), m.l_min, m.l_max)
    gx, gy = hx - 0.5, hy - 0.5
    c0, r0 = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    fx, fy = gx - c0, gy - r0
    for dr, dc, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                      (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        rr, cc = r0 + dr, c0 + dc
        ok = (rr >= 0) & (rr < ny) & (cc >= 0) & (cc < nx)
        np.add.at(g._hits.reshape(-1), rr[ok] * nx + cc[ok], w[ok].astype(np.float32))


@pytest.mark.parametrize("where", ["middle", "edge"])
def test_integrate_equals_the_plain_per_sample_update_bit_for_bit(where):
    """Batches of rays in and out of angle order, with hits crowding one cell, update
    the log-odds and the splatted hits exactly as the plain per-sample computation does:
    in the middle of the grid (every ray on it), and where rays leave it (also rays
    with no return, cleared up to the longest range)."""
    rng = np.random.default_rng(17)
    fast, plain = small_grid(), small_grid()
    for _ in range(30):
        if where == "middle":
            pose = Pose(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0, 360))
        else:
            pose = Pose(rng.uniform(70, 95), rng.uniform(-95, 95), rng.uniform(0, 360))
        start = rng.uniform(0, 360)
        angles = (start + np.arange(0.0, 100.0, 1.0)) % 360.0
        ranges = rng.uniform(3.0, 95.0 if where == "middle" else 300.0, angles.size)
        if where == "edge":
            ranges[rng.random(angles.size) < 0.1] = 0.0
        ranges[40:60] = 20.0  # a patch of returns crowding a few cells
        fast.integrate(pose, angles, ranges)
        _reference_integrate(plain, pose, angles, ranges)
        np.testing.assert_array_equal(fast.log_odds(), plain.log_odds())
        np.testing.assert_array_equal(fast.hit_counts(), plain.hit_counts())


@pytest.mark.parametrize("where", ["middle", "edge"])
def test_batches_fused_in_one_call_are_each_one_observation(where):
    """Several batches fused by `integrate_batches`, each from its own pose, give the grid
    that fusing them one by one gives (while no cell reaches a clamp): each batch updates
    a cell once, a cell one batch hits is still cleared by another batch's rays, and the
    hits' counts are the same. Where rays leave the grid it goes batch by batch."""
    rng = np.random.default_rng(23)
    together, apart = small_grid(), small_grid()
    m = apart.model
    for _ in range(2):
        poses, parts = [], []
        for k in range(rng.integers(2, 5)):
            if where == "middle":
                pose = Pose(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0, 360))
            else:
                pose = Pose(rng.uniform(70, 95), rng.uniform(-95, 95), rng.uniform(0, 360))
            # (apart in angle: a ray's incidence comes from its neighbours, which in one
            # call include the next batch's first ray)
            angles = (k * 90.0 + np.arange(0.0, 80.0, 1.0)) % 360.0
            ranges = rng.uniform(3.0, 95.0 if where == "middle" else 300.0, angles.size)
            ranges[30:34] = 20.0  # returns crowding a cell
            poses.append(pose)
            parts.append((angles, ranges))
            apart.integrate(pose, angles, ranges)
        sizes = [a.size for a, _ in parts]
        origins = np.array([[p.x, p.y, p.heading_deg] for p in poses]).T.repeat(sizes, axis=1)
        together.integrate_batches(origins, sizes, np.concatenate([a for a, _ in parts]),
                                   np.concatenate([r for _, r in parts]))
        assert m.l_min < apart.log_odds().min() and apart.log_odds().max() < m.l_max
        np.testing.assert_allclose(together.log_odds(), apart.log_odds(), atol=1e-5)
        np.testing.assert_array_equal(together.cells(), apart.cells())
        np.testing.assert_allclose(together.hit_counts(), apart.hit_counts(), atol=1e-5)
        # some cell one batch hit was cleared by another's ray (l_occ + l_free)
        assert np.any(np.isclose(together.log_odds(), m.l_occ + m.l_free))
    assert together.batches == apart.batches


def test_batches_fused_in_one_call_need_matching_sizes_and_origins():
    """Origins of the wrong shape, or sizes that do not add up to the beams, are refused
    with one clear error."""
    g = small_grid()
    a, r = np.arange(10.0), np.full(10, 50.0)
    with pytest.raises(ValueError, match="sizes"):
        g.integrate_batches(np.zeros((3, 10)), [4, 4], a, r)
    with pytest.raises(ValueError, match="origins"):
        g.integrate_batches(np.zeros((2, 10)), [5, 5], a, r)
