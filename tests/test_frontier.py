"""Frontier detection, clustering and choice (actors.firmware.planning.frontier)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.hardware import HardwareSpec
from actors.firmware.planning.clearance import turning_radius_cm
from actors.firmware.planning.frontier import (
    Frontier,
    find_frontiers,
    frontier_mask,
    label_clusters,
)
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

BENCH = HardwareSpec.bench("mapper")
RADIUS_CM = turning_radius_cm(BENCH.length_cm, BENCH.width_cm)
"""The bench rover's turning radius (half its 20 x 15 cm body's diagonal: 12.5 cm)."""


def test_frontier_mask_is_free_cells_next_to_unknown():
    """Only free cells with an unknown 4-neighbour are frontier; the grid edge is not unknown."""
    cells = np.array([
        [0, 0, 0, -1],
        [0, 0, 0, 100],
        [0, 0, 0, 0],
    ], dtype=np.int8)
    mask = frontier_mask(cells)
    expected = np.zeros_like(mask)
    expected[0, 2] = True
    np.testing.assert_array_equal(mask, expected)


def test_label_clusters_uses_eight_connectivity():
    """Diagonal neighbours join a cluster; separate blobs get separate labels in row order."""
    mask = np.array([
        [1, 0, 0, 0, 1],
        [0, 1, 0, 0, 1],
        [0, 0, 0, 0, 0],
        [1, 1, 0, 0, 0],
    ], dtype=bool)
    labels, count = label_clusters(mask)
    assert count == 3
    assert labels[0, 0] == labels[1, 1] == 1
    assert labels[0, 4] == labels[1, 4] == 2
    assert labels[3, 0] == labels[3, 1] == 3
    assert (labels[~mask] == 0).all()


def explored_room() -> GridMap:
    """A 3 m x 2 m walled room, left part known free, right part unknown."""
    cells = np.full((40, 60), UNKNOWN, dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    cells[1:-1, 1:30] = FREE
    return GridMap(cells, 5.0, (0.0, 0.0))


def test_find_frontiers_reports_the_boundary_with_distance_and_target():
    """The known/unknown boundary is one cluster; its target is reachable and near it."""
    m = explored_room()
    fs = find_frontiers(m, (50.0, 100.0), robot_radius_cm=RADIUS_CM, split_cm=None)
    assert len(fs) == 1
    f = fs[0]
    assert f.size == 38  # rows 1..38 at column 29
    assert f.centroid_cm == pytest.approx((147.5, 100.0))
    assert f.reachable
    tx, ty = f.target_cm
    assert 147.5 - 30 - 1e-9 <= tx <= 147.5  # within approach_cm of the frontier
    # 8-connected steps from the rover's cell centre (52.5, 102.5): Chebyshev length
    assert f.distance_cm == pytest.approx(max(abs(tx - 52.5), abs(ty - 102.5)))
    assert f.distance_cm <= math.dist((52.5, 102.5), (tx, ty))
    assert 0.4 < f.unknown_share < 0.7


def test_walled_off_frontier_is_unreachable():
    """A frontier behind a wall is not reachable."""
    cells = explored_room().cells.copy()
    cells[:, 15] = OCCUPIED
    fs = find_frontiers(GridMap(cells, 5.0, (0, 0)), (30.0, 100.0), robot_radius_cm=RADIUS_CM,
                        split_cm=None)
    assert len(fs) == 1 and not fs[0].reachable


def test_a_long_frontier_is_split_into_pieces_with_their_own_targets():
    """The 190 cm boundary, cut by a 100 cm grid: pieces that together hold every frontier
    cell, each with a target near its own part (not all at the point nearest the rover)."""
    m = explored_room()
    whole = find_frontiers(m, (50.0, 100.0), robot_radius_cm=RADIUS_CM, split_cm=None)[0]
    fs = find_frontiers(m, (50.0, 100.0), robot_radius_cm=RADIUS_CM, split_cm=100.0)
    assert len(fs) >= 2
    assert sum(f.size for f in fs) == whole.size
    assert all(f.reachable for f in fs)
    ys = sorted(f.target_cm[1] for f in fs)
    assert ys[-1] - ys[0] >= 50.0  # the targets are spread along the boundary
    for f in fs:
        assert min(abs(f.target_cm[1] - y) for y in f.cells_cm[:, 1]) <= 30.0


def test_fully_known_room_has_no_frontier():
    """A closed, fully mapped room has no frontier at all."""
    cells = explored_room().cells.copy()
    cells[1:-1, 1:-1] = FREE
    assert find_frontiers(GridMap(cells, 5.0, (0, 0)), (50.0, 100.0),
                          robot_radius_cm=RADIUS_CM) == []


def make(size: int, distance: float, share: float, at=(0.0, 0.0), target=(0.0, 0.0)) -> Frontier:
    return Frontier(size, at, np.zeros((size, 2)), distance, target, share, 5.0)


def test_open_share_tells_an_edge_in_the_open_from_one_along_a_wall():
    """A frontier with no obstacle within 30 cm is in the open (1.0); one running along a
    wall is not (0.0): after futile visits only the first kind still counts."""
    cells = np.full((60, 60), UNKNOWN, dtype=np.int8)
    cells[10:50, 10:30] = FREE  # known free; its east edge (col 29) faces the unknown
    cells[10:50, 9] = OCCUPIED  # a wall along the west side ...
    cells[9, 10:30] = OCCUPIED
    cells[50, 10:30] = OCCUPIED
    cells[10:50, 10] = FREE
    cells[20:40, 11] = UNKNOWN  # ... with a ragged unknown strip right beside it
    grid = GridMap(cells, 5.0, (-50.0, -100.0))
    fronts = find_frontiers(grid, (0.0, 0.0), robot_radius_cm=5.0, margin_cm=0.0,
                            split_cm=None)
    by_side = {("east" if f.centroid_cm[0] > 50.0 else "west"): f for f in fronts}
    assert by_side["west"].open_share == 0.0
    assert by_side["east"].open_share > 0.5
