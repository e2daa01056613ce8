"""Planar poses and frame changes: room frame, map frame, rover frame.

A pose ``(x, y, heading)`` is a position [cm] and a heading [deg, CCW from
+x]. ``compose(a, b)`` is "b expressed in the frame whose origin is a":
a rover whose start pose in the map frame is ``origin`` and whose
dead-reckoned pose (relative to its start) is ``p`` stands at
``compose(origin, p)`` in the map frame. The map frame is the mapper's start
frame, so the origin of rover R in the map frame is
``compose(inverse(mapper_start_room), R_start_room)``. Pure functions.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["Pose2", "compose", "inverse", "relative", "wrap_deg"]


class Pose2(NamedTuple):
    """A planar pose: x [cm], y [cm], heading [deg]."""

    x: float
    y: float
    heading: float = 0.0


def wrap_deg(a: float) -> float:
    """Angle wrapped into (-180, 180] [deg]."""
    a = math.fmod(a, 360.0)
    if a <= -180.0:
        a += 360.0
    elif a > 180.0:
        a -= 360.0
    return a


def compose(a: Pose2, b: Pose2) -> Pose2:
    """Pose ``b`` (given in frame ``a``) expressed in the frame ``a`` is given in."""
    t = math.radians(a.heading)
    c, s = math.cos(t), math.sin(t)
    return Pose2(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y,
                 wrap_deg(a.heading + b.heading))


def inverse(a: Pose2) -> Pose2:
    """The pose ``i`` with ``compose(a, i) == (0, 0, 0)``."""
    t = math.radians(a.heading)
    c, s = math.cos(t), math.sin(t)
    return Pose2(-c * a.x - s * a.y, s * a.x - c * a.y, wrap_deg(-a.heading))


def relative(frame: Pose2, p: Pose2) -> Pose2:
    """Pose ``p`` expressed in ``frame`` (both given in a common frame)."""
    return compose(inverse(frame), p)
