"""The distance field: its capped transform gives scipy's floats, and its reads (one pass
for distance and knownness) the floats of a point-by-point reading of the definition
(bilinear between the four nearest cell centres, the cap where that box leaves the
window; the cell holding the point for knownness)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from actors.firmware.localisation.capped_edt import capped_distance
from actors.firmware.localisation.distance_field import DistanceField
from tests.localisation_rooms import room


def _reference(field: DistanceField, x: float, y: float) -> tuple[float, bool]:
    """The distance and knownness at one point, read cell by cell in plain floats."""
    ox, oy = field.origin_cm
    res = field.resolution_cm
    d = field.distance_cm
    ny, nx = d.shape
    gx, gy = (x - ox) / res - 0.5, (y - oy) / res - 0.5
    c0, r0 = math.floor(gx), math.floor(gy)
    fx, fy = gx - c0, gy - r0
    if 0 <= c0 < nx - 1 and 0 <= r0 < ny - 1:
        dist = float((1 - fx) * (1 - fy) * d[r0, c0] + fx * (1 - fy) * d[r0, c0 + 1]
                     + (1 - fx) * fy * d[r0 + 1, c0] + fx * fy * d[r0 + 1, c0 + 1])
    else:
        dist = field.max_dist_cm
    c, r = math.floor((x - ox) / res), math.floor((y - oy) / res)
    known = bool(0 <= c < nx and 0 <= r < ny and field.known[r, c])
    return dist, known


def _points(field: DistanceField, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random points over the window and two cells beyond it, plus points exactly on
    cell edges and centres and one ulp either side of the window's edges."""
    rng = np.random.default_rng(seed)
    ox, oy = field.origin_cm
    res = field.resolution_cm
    ny, nx = field.distance_cm.shape
    x = rng.uniform(ox - 2 * res, ox + (nx + 2) * res, n)
    y = rng.uniform(oy - 2 * res, oy + (ny + 2) * res, n)
    ex = ox + res * np.array([0.0, 0.5, 1.0, nx - 1.0, nx - 0.5, nx])
    ey = oy + res * np.array([0.0, 0.5, 1.0, ny - 1.0, ny - 0.5, ny])
    ex = np.concatenate([ex, np.nextafter(ex, -np.inf), np.nextafter(ex, np.inf)])
    ey = np.concatenate([ey, np.nextafter(ey, -np.inf), np.nextafter(ey, np.inf)])
    gx, gy = np.meshgrid(ex, ey)
    return np.concatenate([x, gx.ravel()]), np.concatenate([y, gy.ravel()])


def _fields() -> list[DistanceField]:
    walled = room(300.0, 200.0, (120.0, 60.0, 40.0, 30.0))
    rng = np.random.default_rng(5)
    d = rng.uniform(0.0, 30.0, (7, 9))
    d[rng.random(d.shape) < 0.2] = 0.0
    return [
        DistanceField.from_grid(walled),  # unknown cells round the known ones
        DistanceField.from_grid(room(300.0, 200.0, margin_cm=0.0)),  # walls on the grid's edge
        DistanceField(d, rng.random(d.shape) < 0.5, 5.0, (-12.5, 3.0), 30.0),
        DistanceField(np.zeros((1, 4)), np.ones((1, 4), bool), 5.0, (0.0, 0.0), 50.0),
    ]


def test_the_fields_cover_both_ways_of_finding_the_cell() -> None:
    # the first field's outermost cells are unknown (the cell follows from the bilinear
    # box), the second's walls lie on the grid's edge (the cell is found apart)
    rims = [f._rim_unknown for f in _fields()]
    assert rims[0] and not rims[1]


@pytest.mark.parametrize("index", range(4))
def test_one_pass_reads_the_same_floats_as_the_definition(index: int) -> None:
    field = _fields()[index]
    x, y = _points(field, 3000, index)
    dist, known = field.at_known(x, y)
    assert known is not None
    want = [_reference(field, float(a), float(b)) for a, b in zip(x, y, strict=True)]
    assert dist.tolist() == [w[0] for w in want]
    assert known.tolist() == [w[1] for w in want]
    assert np.array_equal(field.at(x, y), dist)
    assert np.array_equal(field.known_at(x, y), known)


def test_reads_keep_the_points_shape() -> None:
    field = _fields()[0]
    x, y = _points(field, 1200, 1)
    x2, y2 = x[:57 * 19].reshape(19, 57), y[:57 * 19].reshape(19, 57)
    dist, known = field.at_known(x2, y2)
    assert dist.shape == known.shape == (19, 57)
    flat, flat_known = field.at_known(x2.ravel(), y2.ravel())
    assert np.array_equal(dist.ravel(), flat) and np.array_equal(known.ravel(), flat_known)
    one = field.at(np.float64(x[0]), np.float64(y[0]))
    assert np.shape(one) == () and float(one) == _reference(field, x[0], y[0])[0]


@pytest.mark.parametrize(("resolution", "cap"), [(5.0, 50.0), (5.0, 47.0), (2.5, 30.0),
                                                 (3.3, 40.0), (5.0, 1000.0)],
                         ids=["5cm-50cm", "5cm-47cm", "2.5cm", "3.3cm", "wide-cap"])
def test_the_capped_transform_gives_scipys_floats(resolution: float, cap: float) -> None:
    """Separable and limited to the cap, or scipy's where offsets of one squared length
    round apart: the distances are scipy's, capped, bit for bit (sparse obstacles, walls,
    a single cell, a full row, a grid too wide for 16-bit column numbers)."""
    rng = np.random.default_rng(int(resolution * 10 + cap))
    masks = [rng.random((60, 75)) < p for p in (0.002, 0.02, 0.3)]
    walls = np.zeros((50, 40), bool)
    walls[5, 3:30] = walls[5:45, 30] = True
    one = np.zeros((30, 1), bool)
    one[17, 0] = True
    row = np.zeros((3, 50), bool)
    row[1] = True
    wide = np.zeros((4, 17_000), bool)  # column numbers beyond 16-bit integers
    wide[2, ::997] = True
    for occupied in [*masks, walls, one, row, wide]:
        if not occupied.any():
            continue
        want = np.minimum(distance_transform_edt(~occupied, sampling=resolution), cap)
        got = capped_distance(occupied, resolution, cap)
        assert got.dtype == np.float64 and np.array_equal(got, want)


@pytest.mark.parametrize("index", range(4))
def test_known_or_near_is_known_or_within_the_distance(index: int) -> None:
    """With ``near_cm``, the second answer is "known, or within ``near_cm`` of an
    obstacle", whether every point is that near (no cell looked up) or not."""
    field = _fields()[index]
    x, y = _points(field, 2000, 10 + index)
    dist, known = field.at_known(x, y)
    assert known is not None
    for near_cm in (0.0, 7.5, 15.0, field.max_dist_cm + 1.0):
        got_dist, judged = field.at_known(x, y, near_cm=near_cm)
        assert np.array_equal(got_dist, dist)
        assert np.array_equal(judged, known | (dist <= near_cm))
