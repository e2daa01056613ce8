"""Ground truth raster and the map metrics of DESIGN.md section 8."""

from __future__ import annotations

import numpy as np
import pytest

from world.geometry import Pose
from world.metrics import accuracy, coverage, path_length, t90, t99, time_to_coverage
from world.scenario import load_scenario
from world.truth import truth_raster


def perfect_map(name: str) -> tuple:
    """A firmware-style map equal to the truth, in the mapper's frame (start at (0, 0))."""
    s = load_scenario(name)
    truth = truth_raster(s)
    cells = np.where(truth.occupied, 100, 0).astype(np.int8)
    start = s.starts["mapper"]
    # heading 0: the room's cell [0, 0] lies at (-start.x, -start.y) in the mapper frame
    return cells, (-start.x, -start.y), start, truth


def test_truth_marks_obstacles_and_reachable_floor() -> None:
    truth = truth_raster(load_scenario("l_shaped"))
    assert truth.occupied.shape == (100, 120)
    assert truth.occupied[75, 90] and not truth.occupied[25, 30]  # the missing quarter
    assert truth.occupied.sum() == 60 * 50
    assert truth.reachable.sum() == 120 * 100 - 60 * 50


def test_unreachable_pocket_is_not_counted() -> None:
    """Floor enclosed by obstacles is free but not reachable from the mapper."""
    from world.scenario import parse_scenario
    s = parse_scenario("""
name = "pocket"
[room]
size_cm = [300, 200]
[[obstacles]]
box = [200, 50, 80, 10]
[[obstacles]]
box = [200, 140, 80, 10]
[[obstacles]]
box = [200, 60, 10, 80]
[[obstacles]]
box = [270, 60, 10, 80]
[rovers]
mapper = [50, 50, 0]
hider = [50, 100, 0]
seeker = [50, 150, 0]
""")
    truth = truth_raster(s)
    assert not truth.occupied[20, 48] and not truth.reachable[20, 48]  # inside the ring
    assert truth.reachable[10, 10]


def test_perfect_map_scores_one() -> None:
    cells, origin, start, truth = perfect_map("furniture")
    assert coverage(cells, 5.0, origin, start, truth) == pytest.approx(1.0)
    assert accuracy(cells, 5.0, origin, start, truth) == pytest.approx(1.0)


def test_unknown_map_scores_zero_coverage() -> None:
    cells, origin, start, truth = perfect_map("furniture")
    unknown = np.full_like(cells, -1)
    assert coverage(unknown, 5.0, origin, start, truth) == 0.0
    assert accuracy(unknown, 5.0, origin, start, truth) == 1.0


def test_half_known_map_scores_half_coverage() -> None:
    cells, origin, start, truth = perfect_map("empty")
    cells[:, cells.shape[1] // 2:] = -1
    assert coverage(cells, 5.0, origin, start, truth) == pytest.approx(0.5, abs=0.01)


def test_one_cell_shift_is_tolerated_two_cells_are_not() -> None:
    cells, origin, start, truth = perfect_map("cluttered")
    one = (origin[0] + 5.0, origin[1])
    two = (origin[0] + 10.0, origin[1])
    assert accuracy(cells, 5.0, one, start, truth) == pytest.approx(1.0)
    assert accuracy(cells, 5.0, two, start, truth) < 0.99


def test_wrong_claims_lower_accuracy() -> None:
    cells, origin, start, truth = perfect_map("furniture")
    bad = cells.copy()
    bad[60:70, 10:20] = 100  # a phantom obstacle in open floor
    assert accuracy(bad, 5.0, origin, start, truth) == pytest.approx(1 - 100 / cells.size)


def test_map_in_a_rotated_mapper_frame() -> None:
    """A mapper that started facing +y draws the room rotated; the metrics undo it."""
    _, _, _, truth = perfect_map("empty")
    start = Pose(200.0, 150.0, 90.0)
    # the room (400 x 300) in that frame: x_m = y - 150, y_m = -(x - 200)
    occ = np.rot90(truth.occupied, k=-1)  # rows: -x, cols: y
    cells = np.where(occ, 100, 0).astype(np.int8)
    origin = (-150.0, -200.0)
    assert coverage(cells, 5.0, origin, start, truth) == pytest.approx(1.0)
    assert accuracy(cells, 5.0, origin, start, truth) == pytest.approx(1.0)
    assert coverage(cells, 5.0, origin, Pose(200.0, 150.0, 0.0), truth) < 0.9


def test_t90_t99_and_path_length() -> None:
    series = [(0.0, 0.1), (10.0, 0.5), (20.0, 0.91), (30.0, 0.98), (40.0, 0.995)]
    assert t90(series) == 20.0 and t99(series) == 40.0
    assert time_to_coverage(series[:3], 0.99) is None
    assert path_length([Pose(0, 0, 0), Pose(3, 4, 10), Pose(3, 10, 0)]) == pytest.approx(11.0)
    assert path_length([(1.0, 1.0)]) == 0.0


def test_bad_map_is_refused() -> None:
    _, origin, start, truth = perfect_map("empty")
    with pytest.raises(ValueError, match="cells must be a 2-D array"):
        coverage(np.zeros(5, dtype=np.int8), 5.0, origin, start, truth)


def test_cells_under_a_rover_body_count_neither_right_nor_wrong() -> None:
    """A parked rover the LIDAR outlined is not an error: the truth raster has no rovers."""
    cells, origin, start, truth = perfect_map("furniture")
    marked = cells.copy()
    marked[60:64, 10:14] = 100  # a rover's outline, 20 x 20 cm, in open floor
    centre = Pose(12 * 5.0, 62 * 5.0, 0.0)  # room frame: the box's centre
    assert accuracy(marked, 5.0, origin, start, truth) < 1.0
    assert accuracy(marked, 5.0, origin, start, truth,
                    [(centre, 20.0, 20.0)]) == pytest.approx(1.0)
