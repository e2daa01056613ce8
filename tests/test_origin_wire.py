"""Poses on the wire as two messages (the pose halves), and the mapper's origin so sent."""

from __future__ import annotations

import math

import pytest

from actors import Message
from actors.firmware.commands import Cmd
from actors.firmware.origin_wire import (
    CM,
    MM,
    PoseHalves,
    pose_messages,
    xy_half,
)
from server.protocol.pose import Pose


def test_an_origin_goes_over_as_millimetres_and_degrees_and_comes_back() -> None:
    xy, heading = pose_messages(Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING,
                                Pose(12.34, -5.66, 2.5))
    assert (xy.command, heading.command) == (Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING)
    assert xy.as_pair() == (123, -57)
    halves = PoseHalves()
    halves.take_xy(xy)
    assert halves.take_heading(heading) == Pose(12.3, -5.7, 2.5)


def test_a_translation_beyond_int16_millimetres_is_clamped() -> None:
    xy, _ = pose_messages(Cmd.MAP_ORIGIN_XY, Cmd.MAP_ORIGIN_HEADING, Pose(5000.0, -5000.0, 0))
    assert xy.as_pair() == (32767, -32767)


def test_a_heading_without_its_translation_or_not_finite_is_no_origin() -> None:
    halves = PoseHalves()
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, 3.0)) is None
    halves.take_xy(Message.pair(Cmd.MAP_ORIGIN_XY, 10, 20))
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, math.nan)) is None
    # the translation was used up: a later heading alone is no origin either
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, 3.0)) is None


def test_a_heading_alone_keeps_the_translation_it_is_given_as_unchanged() -> None:
    """Motor Control's pose: a heading without a translation before it is the pose with its
    translation unchanged (centimetres for the LIDAR's stamps, millimetres for navigation)."""
    last = Pose(4.0, -2.0, 10.0)
    halves = PoseHalves(CM)
    assert halves.take_heading(Message.float(Cmd.NAV_POSE_HEADING, 15.0), last) == Pose(
        4.0, -2.0, 15.0)
    halves.take_xy(Message.pair(Cmd.LIDAR_POSE_XY, 7, 8))
    assert halves.take_heading(Message.float(Cmd.NAV_POSE_HEADING, 20.0), last) == Pose(
        7.0, 8.0, 20.0)


def test_pose_halves_round_as_the_links_did_before_the_helper() -> None:
    # half-way values (banker's rounding), negatives, the int16 clamp: the helper's
    # integers equal the per-link formulas bit for bit, in mm and in cm
    for v in (0.05, 0.15, -0.25, 2.5, -3.5, 12.3449, 1e-9, -0.0, 3276.7, 3276.75, 1e5):
        for per_cm in (MM, CM):
            xy, heading = pose_messages(Cmd.NAV_POSE_XY, Cmd.NAV_POSE_HEADING,
                                        Pose(v, -v, 10.0), per_cm)
            scaled = v * 10 if per_cm == MM else v
            want = max(-32767, min(32767, round(scaled)))
            wanty = max(-32767, min(32767, round(-scaled)))
            assert xy.as_pair() == (want, wanty)
            assert xy_half(xy, per_cm) == ((want / 10.0, wanty / 10.0) if per_cm == MM
                                           else (float(want), float(wanty)))
            assert float(heading.value) == 10.0


def test_motor_controls_pose_reaches_navigation_and_the_lidar_in_their_units() -> None:
    pose = Pose(123.456, -78.9, 45.0)
    nav_xy, _ = pose_messages(Cmd.NAV_POSE_XY, Cmd.NAV_POSE_HEADING, pose, MM)
    lidar_xy, _ = pose_messages(Cmd.LIDAR_POSE_XY, Cmd.LIDAR_POSE_HEADING, pose, CM)
    assert nav_xy.as_pair() == (1235, -789)
    assert lidar_xy.as_pair() == (123, -79)
    assert xy_half(nav_xy, MM) == (123.5, -78.9)
    assert xy_half(lidar_xy, CM) == (123.0, -79.0)


def test_a_translation_half_that_is_not_an_int16_pair_is_refused() -> None:
    with pytest.raises(ValueError, match="INT16X2"):
        xy_half(Message.float(Cmd.NAV_POSE_XY, 1.0))
