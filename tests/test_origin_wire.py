"""The mapper's origin on the wire: two messages, paired by the receiver."""

from __future__ import annotations

import math

from actors import Message
from actors.firmware.commands import Cmd
from actors.firmware.origin_wire import OriginHalves, origin_messages
from server.protocol.pose import Pose


def test_an_origin_goes_over_as_millimetres_and_degrees_and_comes_back() -> None:
    xy, heading = origin_messages(Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING,
                                  Pose(12.34, -5.66, 2.5))
    assert (xy.command, heading.command) == (Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING)
    assert xy.as_pair() == (123, -57)
    halves = OriginHalves()
    halves.take_xy(xy)
    assert halves.take_heading(heading) == Pose(12.3, -5.7, 2.5)


def test_a_translation_beyond_int16_millimetres_is_clamped() -> None:
    xy, _ = origin_messages(Cmd.MAP_ORIGIN_XY, Cmd.MAP_ORIGIN_HEADING, Pose(5000.0, -5000.0, 0))
    assert xy.as_pair() == (32767, -32767)


def test_a_heading_without_its_translation_or_not_finite_is_no_origin() -> None:
    halves = OriginHalves()
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, 3.0)) is None
    halves.take_xy(Message.pair(Cmd.MAP_ORIGIN_XY, 10, 20))
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, math.nan)) is None
    # the translation was used up: a later heading alone is no origin either
    assert halves.take_heading(Message.float(Cmd.MAP_ORIGIN_HEADING, 3.0)) is None
