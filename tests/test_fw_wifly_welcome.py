"""WiFly: a welcome and the server's reliable frames that follow it in the same bytes."""

from __future__ import annotations

import pytest
import trio

from actors import BufferPool, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.hardware import Interrupt
from server.protocol import Frame, decode_line, encode_frame, make_frame

from .test_fw_motor import FakeHardware
from .test_fw_wifly import wifly_tree


@pytest.mark.trio
async def test_frames_after_a_welcome_in_the_same_bytes_are_taken_once(autojump_clock) -> None:
    """welcome + start (seq 1) in one read: start goes to navigation once, is acknowledged,
    and its resend is a duplicate (the welcome's seq_base is applied before start)."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    out: list[bytes] = []
    hw.wifly_write = out.append
    async with open_actor_system(1) as system:
        await system.start_supervisor(wifly_tree(hw, pool, log), "hider")
        await trio.sleep(0.5)
        assert b'"hello"' in b"".join(out)
        welcome = encode_frame(make_frame("welcome", {
            "server": "s/1", "heartbeat_s": 1.0, "down_after_s": 5.0, "seq_base": 1}))
        start = encode_frame(Frame("start", "none", None, seq=1))
        isr = hw.handlers[Interrupt.INT_B]
        isr(welcome + start)
        await trio.sleep(0.5)
        isr(start)  # the server's resend, had the ack been lost
        await trio.sleep(0.5)
    starts = [p for c, p in log if c == Cmd.NAV_NET and p.cmd == "start"]
    acks = [decode_line(x).ack for x in b"".join(out).splitlines()]
    assert len(starts) == 1
    assert 1 in acks and 0 not in acks
