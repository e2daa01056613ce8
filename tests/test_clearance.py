"""Spot clearance and obstacle-ahead tests (actors.firmware.planning.clearance)."""

from __future__ import annotations

import numpy as np
import pytest

from actors.firmware.planning.clearance import (
    check_spot,
    obstacle_ahead,
    passage_width,
    turning_radius_cm,
)
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose

RES = 5.0
BODY = (20.0, 15.0, 5.0)
"""The bench body (length, width [cm]) and the spot margin [cm]."""
AHEAD = {"half_angle_deg": 30.0, "half_width_cm": 12.5}
"""A cone of +-30 deg and a corridor the body's half-diagonal wide [deg, cm]."""


def room() -> np.ndarray:
    """A 2 m x 2 m known-free room with walls, origin at (0, 0)."""
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    return cells


def test_turning_radius_is_half_diagonal():
    """20 x 15 cm body turns within 12.5 cm."""
    assert turning_radius_cm(20, 15) == pytest.approx(12.5)


def test_open_spot_is_ok():
    """The middle of an empty room fits."""
    assert check_spot(room(), RES, (0, 0), 100, 100, 30, *BODY) == (True, "ok")


def test_spot_near_wall_needs_radius_plus_margin():
    """The wall face is at x = 5 cm; 17.5 cm needed: x = 22.4 fails, x = 22.6 fits."""
    ok, reason = check_spot(room(), RES, (0, 0), 22.4, 100, 0, *BODY)
    assert not ok and reason.startswith("obstacle 17.4 cm from the spot")
    assert check_spot(room(), RES, (0, 0), 22.6, 100, 0, *BODY) == (True, "ok")


def test_heading_does_not_matter_for_a_turning_disc():
    """Any heading gives the same answer: the rover must be able to turn there."""
    answers = {check_spot(room(), RES, (0, 0), 30, 30, h, *BODY)[0] for h in (0, 45, 90, 135)}
    assert answers == {True}


def test_unknown_ground_under_the_rover_is_refused():
    """An unmapped cell inside the disc refuses the spot with reason 'unknown ground'."""
    cells = room()
    cells[20, 22] = UNKNOWN
    ok, reason = check_spot(cells, RES, (0, 0), 100, 100, 0, *BODY)
    assert not ok and reason.startswith("unknown ground")


def test_unknown_cells_only_in_the_margin_band_are_accepted():
    """Unmapped cells 12.5..17.5 cm from the spot (margin, not body) do not refuse it."""
    cells = room()
    cells[20, 23] = UNKNOWN  # nearest point 15 cm from (100, 100): in the 5 cm margin band
    assert check_spot(cells, RES, (0, 0), 100, 100, 0, *BODY) == (True, "ok")
    cells[20, 22] = UNKNOWN  # 10 cm: under the turning body
    ok, reason = check_spot(cells, RES, (0, 0), 100, 100, 0, *BODY)
    assert not ok and reason == "unknown ground: 1 unmapped cells within 12.5 cm"


def test_obstacle_beats_unknown_in_the_reason():
    """When both are present the obstacle is reported."""
    cells = room()
    cells[20, 22] = UNKNOWN
    cells[20, 18] = OCCUPIED
    assert check_spot(cells, RES, (0, 0), 100, 100, 0, *BODY)[1].startswith("obstacle")


@pytest.mark.parametrize(("x", "y"), [(-50, 100), (100, 250), (10, 100)])
def test_outside_the_map_is_refused(x, y):
    """A spot whose disc leaves the map is refused with 'outside the map'."""
    ok, reason = check_spot(room(), RES, (0, 0), x, y, 0, *BODY)
    assert not ok and reason.startswith("outside the map")


def test_origin_shifts_the_map():
    """With the origin at (-100, -100) the room's centre is (0, 0)."""
    assert check_spot(room(), RES, (-100, -100), 0, 0, 0, *BODY) == (True, "ok")
    assert not check_spot(room(), RES, (-100, -100), 100, 100, 0, *BODY)[0]


def test_bad_spot_is_a_reason_and_bad_map_an_error():
    """A NaN spot is refused with a reason; a malformed map raises ValueError."""
    ok, reason = check_spot(room(), RES, (0, 0), float("nan"), 100, 0, *BODY)
    assert not ok and reason == "bad spot: x must be a finite number, got nan"
    with pytest.raises(ValueError, match="cells must be a non-empty 2-D array"):
        check_spot(np.zeros(5, dtype=np.int8), RES, (0, 0), 1, 1, 0, *BODY)
    with pytest.raises(ValueError, match="resolution_cm must be a positive number"):
        check_spot(room(), 0, (0, 0), 100, 100, 0, *BODY)


def test_obstacle_ahead_finds_the_nearest_cell_in_front_only():
    """A wall 40 cm ahead is found at 20..45 cm; behind or beyond range it is not."""
    m = GridMap(room(), RES, (0, 0))
    facing_wall = Pose(160, 102.5, 0)  # wall cells at x in [195, 200)
    ob = obstacle_ahead(m, facing_wall, 40, **AHEAD)
    assert ob is not None
    assert ob.forward_cm == pytest.approx(37.5)
    assert abs(ob.bearing_deg) < 1
    assert obstacle_ahead(m, facing_wall, 30, **AHEAD) is None
    assert obstacle_ahead(m, Pose(160, 102.5, 180), 40, **AHEAD) is None


def test_obstacle_ahead_sees_a_box_to_the_side_within_the_cone():
    """A post 20 cm ahead and 10 cm left is in the corridor; 30 cm left at 20 cm is not."""
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[22, 24] = OCCUPIED  # centre (122.5, 112.5)
    m = GridMap(cells, RES, (0, 0))
    ob = obstacle_ahead(m, Pose(100, 100, 0), 30, **AHEAD)
    assert ob is not None and ob.bearing_deg > 0
    cells2 = np.full((40, 40), FREE, dtype=np.int8)
    cells2[26, 24] = OCCUPIED  # centre (122.5, 132.5): lateral 32.5 > max(12.5, 22.5 tan 30)
    assert obstacle_ahead(GridMap(cells2, RES, (0, 0)), Pose(100, 100, 0), 30,
                          **AHEAD) is None


def test_obstacle_ahead_leaves_out_cells_beside_the_body():
    """A wall beside the body (cell centres up to its half length ahead) is not ahead of
    it; the same wall further along still is, and so is a wall across the way."""
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[18, 19:22] = OCCUPIED  # centres (97.5..107.5, 92.5): 7.5 cm right of the line
    m = GridMap(cells, RES, (0, 0))
    pose = Pose(100, 100, 0)
    assert obstacle_ahead(m, pose, 30, half_angle_deg=0.0, half_width_cm=7.5,
                          beyond_cm=10.0) is None
    cells[18, 22] = OCCUPIED  # centre 12.5 cm ahead: beyond the nose
    m = GridMap(cells, RES, (0, 0))
    ob = obstacle_ahead(m, pose, 30, half_angle_deg=0.0, half_width_cm=7.5, beyond_cm=10.0)
    assert ob is not None and ob.forward_cm == pytest.approx(12.5)
    with pytest.raises(ValueError, match="beyond_cm"):
        obstacle_ahead(m, pose, 30, half_angle_deg=0.0, half_width_cm=7.5, beyond_cm=30.0)


def test_passage_width_across_the_heading():
    """A 30 cm corridor along x (walls' cells from y 165 and below y 135): about 30 cm
    across it anywhere inside; along it, or in the open, no wall on both sides (None)."""
    cells = np.zeros((60, 140), np.int8)
    cells[:27, 50:90] = OCCUPIED  # y < 135, x 250..450
    cells[33:, 50:90] = OCCUPIED  # y >= 165
    grid = GridMap(cells, 5.0, (0.0, 0.0))
    w = passage_width(grid, 300.0, 150.0, 0.0)
    assert w is not None and 29.0 <= w <= 32.0
    off = passage_width(grid, 300.0, 143.0, 180.0)
    assert off is not None and abs(off - w) <= 1.0  # off-centre, reversed: the same width
    assert passage_width(grid, 300.0, 150.0, 90.0) is None  # along the corridor
    assert passage_width(grid, 100.0, 150.0, 0.0) is None  # the open room
    assert passage_width(grid, 300.0, 150.0, 0.0, max_cm=10.0) is None  # beyond reach
