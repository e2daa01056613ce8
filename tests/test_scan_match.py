"""Scan-to-map matching: a perturbed guess is pulled back onto the map, bad matches refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.mapping.scan_match import (
    MatchFields,
    MatchOptions,
    OccupancyField,
    hits_to_local,
    match_scan,
    relocalise,
)
from server.protocol.pose import Pose

RES = 5.0
ORIGIN = (-100.0, -100.0)


def room_map() -> np.ndarray:
    """Occupied cells of a 400 x 300 cm room with a 60 x 40 box inside, origin (-100, -100)."""
    occ = np.zeros((80, 100), dtype=bool)  # rows: y -100..300, cols: x -100..400
    occ[20, 20:101 - 20] = True  # y = 0 wall (row 20), x 0..400
    occ[80 - 20, 20:81] = True  # y = 200 wall
    occ[20:61, 20] = True  # x = 0 wall
    occ[20:61, 80] = True  # x = 300 wall
    occ[40:48, 60:72] = True  # a box
    return occ


def ray_scan(occ: np.ndarray, pose: Pose, n: int = 180) -> tuple[np.ndarray, np.ndarray]:
    """Ranges [cm] at n angles from ``pose`` by marching 0.5 cm through the cell raster."""
    angles = np.arange(n) * (360.0 / n)
    ranges = np.zeros(n)
    for i, a in enumerate(angles):
        t = math.radians(a + pose.heading_deg)
        for d in np.arange(1.0, 600.0, 0.5):
            x, y = pose.x + d * math.cos(t), pose.y + d * math.sin(t)
            r, c = math.floor((y - ORIGIN[1]) / RES), math.floor((x - ORIGIN[0]) / RES)
            if 0 <= r < occ.shape[0] and 0 <= c < occ.shape[1] and occ[r, c]:
                ranges[i] = d
                break
    return angles, ranges


@pytest.mark.parametrize("dx, dy, dh", [(5.0, -3.0, 2.5), (-6.0, 4.0, -3.5), (0.0, 0.0, 4.0)])
def test_a_perturbed_guess_is_pulled_back_to_the_true_pose(dx, dy, dh) -> None:
    """From a guess several cm and degrees off, the match lands within 2 cm and 0.7 deg."""
    occ = room_map()
    truth = Pose(120.0, 80.0, 20.0)
    angles, ranges = ray_scan(occ, truth)
    pts = hits_to_local(angles, ranges, MatchOptions())
    guess = Pose(truth.x + dx, truth.y + dy, truth.heading_deg + dh)
    result = match_scan(MatchFields(occ, ORIGIN, RES), pts, guess)
    assert result.accepted, result.reason
    assert math.hypot(result.pose.x - truth.x, result.pose.y - truth.y) < 2.0
    assert abs(result.pose.heading_deg - truth.heading_deg) < 0.7
    assert result.score > result.score_guess


def test_a_scan_of_unmapped_space_is_not_matched() -> None:
    """Hits where the map has no obstacle: the guess is kept, with the reason."""
    occ = room_map()
    pts = np.column_stack([np.full(50, 30.0), np.linspace(-20, 20, 50)])
    guess = Pose(150.0, 100.0, 0.0)  # a wall 30 cm ahead that the map does not have
    result = match_scan(MatchFields(occ, ORIGIN, RES), pts, guess)
    assert not result.accepted and result.pose == guess
    assert "mapped obstacles" in result.reason


def test_too_few_hits_keep_the_guess() -> None:
    """Fewer hits than ``MIN_POINTS``: refused without trying."""
    fields = MatchFields(room_map(), ORIGIN, RES)
    result = match_scan(fields, np.zeros((3, 2)) + 50.0, Pose(10, 10, 0))
    assert not result.accepted and "need" in result.reason


def test_options_are_checked() -> None:
    """Nonsense tunables are refused with the rule."""
    with pytest.raises(ValueError, match="max_shift_cm and max_turn_deg must be > 0"):
        MatchOptions(max_turn_deg=0.0)
    with pytest.raises(ValueError, match="min_range_cm and prior_per_point must be >= 0"):
        MatchOptions(min_range_cm=-1.0)


@pytest.mark.parametrize("dx, dy, dh", [(0.0, 0.0, 15.0), (8.0, -6.0, -20.0), (3.0, 3.0, 10.0)])
def test_relocalise_finds_a_pose_10_to_20_deg_off(dx, dy, dh) -> None:
    """A heading 10-20 deg off (a stuck encoder's spin), beyond the local match's reach:
    relocalise finds the true pose within 2 cm and 1 deg."""
    occ = room_map()
    truth = Pose(120.0, 80.0, 20.0)
    angles, ranges = ray_scan(occ, truth)
    pts = hits_to_local(angles, ranges, MatchOptions())
    fields = MatchFields(occ, ORIGIN, RES)
    guess = Pose(truth.x + dx, truth.y + dy, truth.heading_deg + dh)
    result = relocalise(fields, pts, guess)
    assert result.accepted, result.reason
    assert math.hypot(result.pose.x - truth.x, result.pose.y - truth.y) < 2.0
    assert abs(result.pose.heading_deg - truth.heading_deg) < 1.0


def test_relocalise_finds_a_guess_that_was_right() -> None:
    """A wide belief whose mean is the truth: the search's winner is at the guess, and
    no other heading rivals it, so it is accepted (the guess is no rival to itself)."""
    occ = room_map()
    truth = Pose(120.0, 80.0, 20.0)
    angles, ranges = ray_scan(occ, truth)
    pts = hits_to_local(angles, ranges, MatchOptions())
    result = relocalise(MatchFields(occ, ORIGIN, RES), pts, truth, turn_deg=180.0)
    assert result.accepted, result.reason
    assert abs(result.pose.heading_deg - truth.heading_deg) < 1.0


def test_relocalise_refuses_an_ambiguous_view() -> None:
    """In a round room every heading fits as well: nothing to re-localise by."""
    yy, xx = np.mgrid[0:80, 0:100]
    cx, cy = (150.0 - ORIGIN[0]) / RES - 0.5, (100.0 - ORIGIN[1]) / RES - 0.5
    occ = np.abs(np.hypot(xx - cx, yy - cy) - 30.0) < 0.6  # a circle, radius 150 cm
    truth = Pose(150.0, 100.0, 0.0)
    angles, ranges = ray_scan(occ, truth)
    pts = hits_to_local(angles, ranges, MatchOptions())
    result = relocalise(MatchFields(occ, ORIGIN, RES), pts, Pose(150.0, 100.0, 15.0))
    assert not result.accepted
    assert "ambiguous" in result.reason


def test_value_xy_gives_sample_xys_value_bit_for_bit() -> None:
    """The value-only lookup that scoring uses is the same floats as the full one's value,
    also for points outside the crop (0)."""
    rng = np.random.default_rng(11)
    field = OccupancyField(rng.random((30, 40)) > 0.9, (-20.0, 35.0), 5.0, 2)
    xy = rng.uniform(-80.0, 260.0, size=(2, 150))
    value = field.value_xy(xy.copy())
    full, _, _ = field.sample_xy(xy.copy())
    out = np.empty((3, 150))
    field.sample_xy(xy.copy(), out=out)
    assert value.tobytes() == full.tobytes() == out[0].tobytes()
    assert (value == 0.0).any() and (value > 0.0).any()
