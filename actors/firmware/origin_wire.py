"""The mapper's map -> odometry transform on the wire, as two messages.

Map Management tells navigation the correction its scan matching found
(``NAV_MAP_ORIGIN_XY`` + ``NAV_MAP_ORIGIN_HEADING``), and navigation hands it
back to a restarted Map Management (``MAP_ORIGIN_XY`` + ``MAP_ORIGIN_HEADING``).
One seed message carries 64 bits of value, so a pose takes two: the translation
as an int16 pair [mm] (clamped: +-327 m), then the rotation as a float32 [deg].
The receiver pairs them (`OriginHalves`); a heading without its translation is
not a pose (the translation went to a dead incarnation, or was dropped) and is
ignored, and the next correction supersedes it.
"""

from __future__ import annotations

import math

from actors import Message
from server.protocol.pose import Pose

__all__ = ["OriginHalves", "origin_messages"]

_INT16 = 32767


def origin_messages(xy_command: int, heading_command: int, origin: Pose
                    ) -> tuple[Message, Message]:
    """The two messages that carry ``origin``: translation [mm], then heading [deg]."""
    x_mm = max(-_INT16, min(_INT16, round(origin.x * 10)))
    y_mm = max(-_INT16, min(_INT16, round(origin.y * 10)))
    return (Message.pair(xy_command, x_mm, y_mm),
            Message.float(heading_command, origin.heading_deg))


class OriginHalves:
    """Pairs a translation message with the heading message that follows it."""

    __slots__ = ("_xy",)

    def __init__(self) -> None:
        self._xy: tuple[float, float] | None = None

    def take_xy(self, message: Message) -> None:
        """The translation half (int16 pair [mm]); kept until its heading arrives."""
        x_mm, y_mm = message.as_pair()
        self._xy = (x_mm / 10.0, y_mm / 10.0)

    def take_heading(self, message: Message) -> Pose | None:
        """The heading half: the whole origin, or None when no translation came first
        or the heading is not finite (nothing is kept either way)."""
        xy, self._xy = self._xy, None
        heading = float(message.value)
        if xy is None or not math.isfinite(heading):
            return None
        return Pose(xy[0], xy[1], heading)
