"""Planar poses and the angle algebra every layer shares: room, map and rover frames.

A pose ``(x, y, heading)`` is a position [cm] and a heading [deg,
counter-clockwise from +x]. This module is the one definition: the rovers'
firmware (dead reckoning, mapping, navigation), the server (start poses, spots,
reports) and the console all use it. The world keeps its own ground-truth
record (``world.geometry.Pose``) because it may import nothing of the server;
it holds no angle algebra.

Angle convention
    Headings are wrapped to (-180, 180] [deg]: a heading of 180 stays 180, -180
    becomes 180. `wrap_deg` returns an angle already in range unchanged (bit for
    bit), so wrapping a wrapped angle, a pose read from the wire or a heading the
    operator typed changes nothing; only angles out of range are reduced (with
    ``math.fmod``, which is exact). `angle_diff_deg` is the smallest signed turn,
    in the same range: a half turn is +180 (counter-clockwise).

Frames
    ``compose(a, b)`` is "b expressed in the frame whose origin is a" (the SE(2)
    product): a rover whose start pose in the map frame is ``origin`` and whose
    dead-reckoned pose (relative to its start) is ``p`` stands at
    ``compose(origin, p)`` in the map frame. The map frame is the mapper's start
    frame, so the origin of rover R in the map frame is
    ``compose(inverse(mapper_start_room), R_start_room)``. Pure functions.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

__all__ = ["Pose", "ZERO_POSE", "wrap_deg", "angle_diff_deg", "compose", "inverse",
           "relative"]


def wrap_deg(angle_deg: float) -> float:
    """An angle wrapped into (-180, 180] [deg]; one already in range is returned as is.

    Args:
        angle_deg: any finite angle [deg].
    """
    a = math.fmod(angle_deg, 360.0)
    if a <= -180.0:
        a += 360.0
    elif a > 180.0:
        a -= 360.0
    return a


def angle_diff_deg(a_deg: float, b_deg: float) -> float:
    """Smallest signed turn from ``b`` to ``a`` [deg], in (-180, 180].

    Positive means ``a`` lies counter-clockwise of ``b``: turning by the result
    from heading ``b`` reaches heading ``a``.
    """
    return wrap_deg(a_deg - b_deg)


def _finite(name: str, value: object) -> float:
    """``value`` as a float, or ValueError naming the coordinate."""
    if not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"Pose.{name} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True, slots=True, init=False)
class Pose:
    """A pose: position [cm] and heading [deg], in whichever frame the holder says.

    Immutable, so a pose can be passed between actors and kept as "the last
    known pose" without copies. Coordinates are stored as floats and the heading
    wrapped on construction.

    Raises:
        ValueError: a coordinate that is not a finite number (the message names it).
    """

    x: float
    """Position along the frame's +x [cm]."""
    y: float
    """Position along the frame's +y [cm]."""
    heading_deg: float
    """Heading, counter-clockwise from +x [deg], in (-180, 180]."""

    def __init__(self, x: float = 0.0, y: float = 0.0, heading_deg: float = 0.0) -> None:
        # Written out rather than generated with a ``__post_init__``: the firmware makes
        # tens of thousands of poses a game, and the common case (three finite floats, a
        # heading in range, which `wrap_deg` returns as is) sets each field once.
        if type(x) is float and type(y) is float and type(heading_deg) is float \
                and math.isfinite(x + y + heading_deg):
            if not -180.0 < heading_deg <= 180.0:
                heading_deg = wrap_deg(heading_deg)
        else:
            x, y, heading_deg = (_finite(name, value) for name, value in
                                 (("x", x), ("y", y), ("heading_deg", heading_deg)))
            heading_deg = wrap_deg(heading_deg)
        _set = object.__setattr__
        _set(self, "x", x)
        _set(self, "y", y)
        _set(self, "heading_deg", heading_deg)

    @property
    def heading_rad(self) -> float:
        """Heading [rad]."""
        return math.radians(self.heading_deg)

    def to_parent(self, x: float, y: float) -> tuple[float, float]:
        """A point given in this pose's frame, expressed in the parent frame [cm]."""
        rad = math.radians(self.heading_deg)
        c, s = math.cos(rad), math.sin(rad)
        return self.x + c * x - s * y, self.y + s * x + c * y

    def distance_to(self, other: Pose) -> float:
        """Euclidean distance between the two positions [cm]."""
        return math.hypot(other.x - self.x, other.y - self.y)


ZERO_POSE = Pose(0.0, 0.0, 0.0)
"""(0, 0) @ 0 [deg]: where every rover starts in its own frame, and the map frame's origin."""


def compose(a: Pose, b: Pose) -> Pose:
    """Pose ``b`` given in ``a``'s frame, expressed in ``a``'s parent frame (``a (+) b``)."""
    x, y = a.to_parent(b.x, b.y)
    return Pose(x, y, a.heading_deg + b.heading_deg)


def inverse(a: Pose) -> Pose:
    """The parent frame's origin expressed in ``a``'s frame: ``compose(a, inverse(a))``
    is the identity (within float rounding)."""
    rad = math.radians(a.heading_deg)
    c, s = math.cos(rad), math.sin(rad)
    return Pose(-(c * a.x + s * a.y), -(-s * a.x + c * a.y), -a.heading_deg)


def relative(a: Pose, b: Pose) -> Pose:
    """Pose ``b`` (in the parent frame) seen from ``a``: ``compose(inverse(a), b)``."""
    return compose(inverse(a), b)
