"""Dead reckoning from tread distances (the pose algebra is `server.protocol.pose`).

Algorithm
    Differential-drive odometry with midpoint (second-order Runge-Kutta)
    integration: for tread increments ``dl``, ``dr`` [cm] and track width
    ``w`` [cm], the heading changes by ``dtheta = (dr - dl) / w`` [rad] and the
    rover advances ``ds = (dr + dl) / 2`` [cm] along the heading at the middle
    of the step, ``theta + dtheta / 2``. The error per step on a constant-
    curvature arc is ``ds * (1 - sinc(dtheta / 2))``, negligible for the few-cm
    steps of the ADP loop.

Reference
    Siegwart, Nourbakhsh, Scaramuzza, *Introduction to Autonomous Mobile
    Robots*, 2nd ed., section 5.2.4 (odometric position estimation).

Frame and units
    Each rover works in its own frame: it starts at (0, 0) @ 0 [deg]. ``x`` and
    ``y`` are [cm]; the heading is [deg], counter-clockwise from +x, with the
    angle convention of `server.protocol.pose` (wrapped to (-180, 180]).
"""

from __future__ import annotations

import math

from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["advance", "Odometer", "tread_travel"]


def advance(pose: Pose, d_left_cm: float, d_right_cm: float, track_width_cm: float) -> Pose:
    """Dead-reckon one step from the distances each tread travelled.

    Args:
        pose: pose before the step.
        d_left_cm: signed distance of the left tread [cm], negative backwards.
        d_right_cm: signed distance of the right tread [cm].
        track_width_cm: distance between the treads' contact lines [cm].

    Returns:
        The pose after the step (midpoint integration, see module docstring).

    Raises:
        ValueError: if ``track_width_cm`` is not a positive finite number or a
            distance is not finite.
    """
    if not (math.isfinite(track_width_cm) and track_width_cm > 0):
        raise ValueError(f"track_width_cm must be positive, got {track_width_cm!r}")
    if not (math.isfinite(d_left_cm) and math.isfinite(d_right_cm)):
        raise ValueError(f"tread distances must be finite, got {d_left_cm!r}, {d_right_cm!r}")
    dtheta = (d_right_cm - d_left_cm) / track_width_cm  # [rad]
    ds = 0.5 * (d_right_cm + d_left_cm)  # [cm]
    mid = pose.heading_rad + 0.5 * dtheta
    return Pose(
        pose.x + ds * math.cos(mid),
        pose.y + ds * math.sin(mid),
        pose.heading_deg + math.degrees(dtheta),
    )


class Odometer:
    """Tread increments counted since the last integration step, and that step.

    Why one step per batch: integrating each tread's Int E alone would zigzag
    the heading by one interrupt's angle and drift sideways; Motor Control
    integrates once per burst of interrupts (one world step's worth).

    Args:
        unit_cm: tread travel per Int E [cm].
        track_width_cm: distance between the treads' contact lines [cm].
    """

    __slots__ = ("unit_cm", "track_width_cm", "pending")

    def __init__(self, unit_cm: float, track_width_cm: float) -> None:
        self.unit_cm = unit_cm
        self.track_width_cm = track_width_cm
        self.pending = [0.0, 0.0]
        """Signed tread travel not yet integrated, left and right [cm]."""

    def count(self, tread: int, forward: bool) -> float:
        """One Int E of ``tread`` (0 left, 1 right); returns its signed travel [cm]."""
        d = self.unit_cm if forward else -self.unit_cm
        self.pending[tread] += d
        return d

    def integrate(self, pose: Pose) -> Pose | None:
        """``pose`` advanced by the pending travel (which is then cleared), or None when
        nothing is pending."""
        left, right = self.pending
        if left or right:
            self.pending = [0.0, 0.0]
            return advance(pose, left, right, self.track_width_cm)
        return None


def tread_travel(before: Pose, after: Pose, track_width_cm: float) -> tuple[float, float]:
    """The (left, right) tread travel [cm] that takes ``before`` to ``after`` by the
    midpoint rule of `advance`: its inverse (what the encoders counted between two
    dead-reckoned poses)."""
    dtheta = math.radians(angle_diff_deg(after.heading_deg, before.heading_deg))
    mid = before.heading_rad + 0.5 * dtheta
    ds = (after.x - before.x) * math.cos(mid) + (after.y - before.y) * math.sin(mid)
    half = 0.5 * track_width_cm * dtheta
    return ds - half, ds + half
