"""The one pose type and angle algebra (server.protocol.pose), shared by every layer."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.protocol.pose import (
    ZERO_POSE,
    Pose,
    angle_diff_deg,
    compose,
    inverse,
    relative,
    wrap_deg,
)

coord = st.floats(-2000, 2000, allow_nan=False)
angle = st.floats(-1000, 1000, allow_nan=False)
poses = st.builds(Pose, coord, coord, angle)


def close(a: Pose, b: Pose, tol: float = 1e-6) -> bool:
    return (math.isclose(a.x, b.x, abs_tol=tol) and math.isclose(a.y, b.y, abs_tol=tol)
            and abs(angle_diff_deg(a.heading_deg, b.heading_deg)) < tol)


@pytest.mark.parametrize(("raw", "wrapped"), [(0, 0), (180, 180), (-180, 180), (190, -170),
                                              (-190, 170), (720 + 45, 45), (359.5, -0.5)])
def test_wrap_deg_maps_into_half_open_range(raw, wrapped):
    """Angles wrap to (-180, 180]: a half turn is +180 whichever way it was written."""
    assert wrap_deg(raw) == pytest.approx(wrapped)


@given(angle)
def test_wrap_deg_range_property(a):
    """Every wrapped angle lies in (-180, 180] and points the same way."""
    w = wrap_deg(a)
    assert -180 < w <= 180
    assert math.isclose(math.cos(math.radians(w)), math.cos(math.radians(a)), abs_tol=1e-9)


@given(st.floats(-180, 180, allow_nan=False, exclude_min=True))
def test_an_angle_in_range_is_kept_bit_for_bit(a):
    """Wrapping changes nothing in range: a heading read from the wire or typed by the
    operator is the heading the pose holds, to the last bit."""
    assert wrap_deg(a) == a and Pose(0.0, 0.0, a).heading_deg == a


def test_a_half_turn_is_counter_clockwise():
    """The smallest turn between opposite headings is +180, whichever is which."""
    assert angle_diff_deg(180.0, 0.0) == 180.0 and angle_diff_deg(0.0, 180.0) == 180.0


def test_angle_diff_is_shortest_signed_turn():
    """From 170 to -170 is +20 (counter-clockwise), not -340."""
    assert angle_diff_deg(-170, 170) == pytest.approx(20)
    assert angle_diff_deg(170, -170) == pytest.approx(-20)


def test_pose_rejects_non_finite_and_wraps_heading():
    """A NaN coordinate is a clear ValueError; headings are stored wrapped."""
    with pytest.raises(ValueError, match="Pose.x must be a finite number"):
        Pose(float("nan"), 0, 0)
    assert Pose(0, 0, 270).heading_deg == -90


def test_compose_moves_in_parent_frame():
    """One metre ahead of a rover facing +y is at (x, y + 100)."""
    p = compose(Pose(10, 20, 90), Pose(100, 0, 0))
    assert close(p, Pose(10, 120, 90))


@given(poses)
def test_compose_with_inverse_is_identity(a):
    """a (+) a^-1 and a^-1 (+) a are the identity."""
    assert close(compose(a, inverse(a)), ZERO_POSE, 1e-6)
    assert close(compose(inverse(a), a), ZERO_POSE, 1e-6)


@given(poses, poses, poses)
def test_compose_is_associative(a, b, c):
    """(a (+) b) (+) c == a (+) (b (+) c)."""
    assert close(compose(compose(a, b), c), compose(a, compose(b, c)), 1e-5)


@given(poses, poses)
def test_relative_undoes_compose(a, b):
    """relative(a, a (+) b) == b."""
    assert close(relative(a, compose(a, b)), b, 1e-5)


