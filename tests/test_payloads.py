"""The message log reads each message's value as named fields (actors/firmware/payloads.py),
in the live console (tui/activity.py) and in a replay (tui/replay/index.py)."""

from __future__ import annotations

import pytest

from actors import EventKind, Message
from actors.firmware.commands import Cmd
from actors.firmware.payloads import PAYLOADS, message_text, named_text
from tui.activity import ActivityLog


def test_every_command_has_its_payload_written_down() -> None:
    assert set(Cmd) <= set(PAYLOADS)


@pytest.mark.parametrize(("message", "text"), [
    (Message.pair(Cmd.NAV_POSE_XY, 120, -40), "NAV_POSE_XY x=120 mm y=-40 mm"),
    (Message.pair(Cmd.LIDAR_SAMPLE, 1805, 250), "LIDAR_SAMPLE angle=180.5 deg distance=250 cm"),
    (Message.handle(Cmd.WIFLY_SEND_UNRELIABLE, (1 << 16) | 204),
     "WIFLY_SEND_UNRELIABLE frame=buffer 204"),
    (Message.float(Cmd.MOTOR_TURN, -90.0), "MOTOR_TURN angle=-90 deg"),
    (Message.int(Cmd.MOTOR_TICK, 2), "MOTOR_TICK tread=left backward"),
    (Message.uint(Cmd.NAV_TREAD_FAULT, 6), "NAV_TREAD_FAULT both treads count short"),
    (Message.int(Cmd.NAV_LINK, 0), "NAV_LINK link=down"),
    (Message.int(Cmd.IR_SAMPLE, 4095), "IR_SAMPLE adc=4095 of 4095"),
    (Message.int(Cmd.NAV_TIMER, 0), "NAV_TIMER"),
    (Message.int(0x7777, 5), "0x7777 value=5"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_a_value_reads_as_its_named_fields(message: Message, text: str) -> None:
    assert message_text(message) == text


def test_the_consoles_log_shows_fields_not_raw_integers() -> None:
    log = ActivityLog(lambda: 0.0)
    raw = Message.pair(Cmd.NAV_POSE_XY, -5, 7)
    log.on_message(1.0, EventKind.SEND, "mapper/nav", raw, 1)
    (line,) = log.log_lines()
    assert line.text == "NAV_POSE_XY x=-5 mm y=7 mm" and str(raw.value) not in line.text


def test_a_recorded_message_reads_the_same_as_a_live_one() -> None:
    """The replay's log decodes a recording's row (command and type by name) alike."""
    m = Message.pair(Cmd.MAP_TREAD_FAULT, 12, -3)
    assert named_text("MAP_TREAD_FAULT", "INT16X2", m.value) == message_text(m)
    assert named_text("SOMETHING_NEW", "INT32", 5) == "SOMETHING_NEW 5"
