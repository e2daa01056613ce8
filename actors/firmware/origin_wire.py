"""A pose on the wire as two messages ("pose halves"), and the mapper's origin so sent.

One seed message carries 64 bits of value, so a pose takes two: the
translation as an int16 pair, then the rotation as a float32 [deg]. The
translation's unit is chosen per link, as ``per_cm`` (integer units per cm):
millimetres (`MM`) for Motor Control's pose to navigation and for the map
origin, centimetres (`CM`) for the pose that stamps the LIDAR's samples.
`pose_messages` makes both halves and `xy_half` reads the translation back;
`PoseHalves` pairs them again (a missing translation means "unchanged" for
Motor Control's pose, "no origin" for the map origin).

The mapper's map -> odometry transform travels this way: Map Management tells
navigation the correction its scan matching found (``NAV_MAP_ORIGIN_XY`` +
``NAV_MAP_ORIGIN_HEADING``), and navigation hands it back to a restarted Map
Management (``MAP_ORIGIN_XY`` + ``MAP_ORIGIN_HEADING``). The receiver pairs
them (`PoseHalves`); a heading without its translation is not a pose (the
translation went to a dead incarnation, or was dropped) and is ignored, and
the next correction supersedes it.
"""

from __future__ import annotations

import math

from actors import Message
from server.protocol.pose import Pose

__all__ = ["CM", "MM", "PoseHalves", "length_pair", "pose_messages", "xy_half"]

_INT16 = 32767

MM = 10
"""``per_cm`` of a translation in millimetres (clamped: +-32.767 m)."""
CM = 1
"""``per_cm`` of a translation in centimetres (clamped: +-327.67 m)."""


def pose_messages(xy_command: int, heading_command: int, pose: Pose, per_cm: int = MM
                  ) -> tuple[Message, Message]:
    """The two halves of ``pose``: its translation rounded to ``1 / per_cm`` cm and
    clamped to int16, then its heading [deg] as a float."""
    x = max(-_INT16, min(_INT16, round(pose.x * per_cm)))
    y = max(-_INT16, min(_INT16, round(pose.y * per_cm)))
    return (Message.pair(xy_command, x, y),
            Message.float(heading_command, pose.heading_deg))


def length_pair(command: int, a_cm: float, b_cm: float, per_cm: int = MM) -> Message:
    """Two lengths [cm] as one int16 pair message, rounded to ``1 / per_cm`` cm and
    clamped (a pose's translation, or one length per tread); `xy_half` reads it back."""
    return Message.pair(command, max(-_INT16, min(_INT16, round(a_cm * per_cm))),
                        max(-_INT16, min(_INT16, round(b_cm * per_cm))))


def xy_half(message: Message, per_cm: int = MM) -> tuple[float, float]:
    """The translation half made by `pose_messages` (or a `length_pair`), back in cm.

    Raises:
        ValueError: ``message`` is not an int16 pair.
    """
    x, y = message.as_pair()
    return (x / per_cm, y / per_cm)


class PoseHalves:
    """Pairs a translation message with the heading message that follows it.

    Args:
        per_cm: the translation's integer units per cm (`MM`, `CM`).
    """

    __slots__ = ("_xy", "per_cm")

    def __init__(self, per_cm: int = MM) -> None:
        self.per_cm = per_cm
        self._xy: tuple[float, float] | None = None

    def take_xy(self, message: Message) -> None:
        """The translation half (an int16 pair); kept until its heading arrives."""
        self._xy = xy_half(message, self.per_cm)

    def take_heading(self, message: Message, unchanged: Pose | None = None) -> Pose | None:
        """The heading half: the whole pose, its translation ``unchanged``'s when none
        came first; None when neither is there or the heading is not finite (nothing is
        kept either way)."""
        xy, self._xy = self._xy, None
        heading = float(message.value)
        if xy is None and unchanged is not None:
            xy = (unchanged.x, unchanged.y)
        if xy is None or not math.isfinite(heading):
            return None
        return Pose(xy[0], xy[1], heading)
