"""The mapper's own body marked in the map it uploads (`mapping.parked_body`)."""

from __future__ import annotations

import numpy as np

from actors.firmware.mapping.parked_body import with_parked_body
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose


def _free_map() -> GridMap:
    return GridMap(np.zeros((40, 40), dtype=np.int8), 5.0, (-100.0, -100.0))


def test_a_parked_body_occupies_the_cells_it_covers_and_no_others() -> None:
    grid = with_parked_body(_free_map(), Pose(0.0, 0.0, 0.0), 20.0, 15.0)
    occupied = grid.cells == OCCUPIED
    # 20 x 15 cm grown by half a 5 cm cell each side: 30 x 25 cm of cell centres round (0, 0)
    rows, cols = np.nonzero(occupied)
    xs = -100.0 + (cols + 0.5) * 5.0
    ys = -100.0 + (rows + 0.5) * 5.0
    assert xs.min() == -12.5 and xs.max() == 12.5
    assert ys.min() == -7.5 and ys.max() == 7.5
    assert occupied.sum() == 6 * 4
    assert (grid.cells[~occupied] == FREE).all()


def test_a_parked_body_turned_across_the_grid_lies_along_its_heading() -> None:
    grid = with_parked_body(_free_map(), Pose(0.0, 0.0, 90.0), 20.0, 15.0)
    rows, cols = np.nonzero(grid.cells == OCCUPIED)
    assert np.ptp(rows) > np.ptp(cols)  # long along y


def test_a_parked_body_leaves_the_given_map_unchanged_and_clips_at_its_edge() -> None:
    base = GridMap(np.full((10, 10), UNKNOWN, dtype=np.int8), 5.0, (0.0, 0.0))
    grid = with_parked_body(base, Pose(2.0, 2.0, 30.0), 20.0, 15.0)
    assert (base.cells == UNKNOWN).all()
    assert grid.cells[0, 0] == OCCUPIED and grid.shape == base.shape
