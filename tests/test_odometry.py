"""Dead reckoning from tread distances (actors.firmware.localisation.odometry)."""

from __future__ import annotations

import math

import pytest

from actors.firmware.localisation.odometry import advance
from server.protocol.pose import ZERO_POSE, Pose, angle_diff_deg


def close(a: Pose, b: Pose, tol: float = 1e-6) -> bool:
    return (math.isclose(a.x, b.x, abs_tol=tol) and math.isclose(a.y, b.y, abs_tol=tol)
            and abs(angle_diff_deg(a.heading_deg, b.heading_deg)) < tol)


def test_advance_straight_and_turn_in_place():
    """Equal treads move straight; opposite treads turn by (dr - dl) / w [rad]."""
    p = advance(ZERO_POSE, 10, 10, 15)
    assert close(p, Pose(10, 0, 0))
    w = 15.0
    quarter = math.pi / 2 * w / 2  # each tread's arc for a 90 deg turn
    p = advance(Pose(5, 5, 0), -quarter, quarter, w)
    assert close(p, Pose(5, 5, 90))


def test_advance_full_circle_returns_home():
    """360 small arc steps on a constant-curvature arc land on the exact arc."""
    w = 15.0
    p = ZERO_POSE
    for _ in range(360):
        p = advance(p, 1.0, 2.0, w)
    # radius = w/2 * (dr+dl)/(dr-dl) = 22.5 cm; total heading change 360 * (1/15) rad
    r = w / 2 * 3.0 / 1.0
    theta = 360 * (1.0 / w)
    exact = Pose(r * math.sin(theta), r * (1 - math.cos(theta)), math.degrees(theta))
    assert close(p, exact, 0.05)


def test_advance_rejects_bad_track_width():
    """A zero track width is a ValueError naming the parameter."""
    with pytest.raises(ValueError, match="track_width_cm must be positive"):
        advance(ZERO_POSE, 1, 1, 0)
