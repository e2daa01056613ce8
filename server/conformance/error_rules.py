"""The rover's answer to malformed frames: ``malformed.answered``, ``malformed.reliable``,
``malformed.survives``."""

from __future__ import annotations

import trio

from ..protocol import MAX_LINE_BYTES, Fault, Frame
from .context import Checker, Expect
from .peer import Seen

__all__ = ["MALFORMED", "malformed"]

MALFORMED: tuple[tuple[bytes, str], ...] = (
    (b"this is not json\n", Fault.NOT_JSON),
    (b'{"cmd":"' + b"x" * MAX_LINE_BYTES + b'"}\n', Fault.TOO_LONG),
    (b'{"cmd":"dance","type":"none","data":null}\n', Fault.UNKNOWN_CMD),
    (b'{"cmd":"stop","type":"pose","data":null}\n', Fault.BAD_TYPE),
    (b'["cmd","stop"]\n', Fault.BAD_FRAME),
)
"""Lines that are not frames the rover takes, and the fault each should be answered with."""
_ANSWER_S = 1.0  # errors come at once; allow a tick and a heartbeat [s]
_ALIVE_S = 2.0  # how long the rover must go on speaking afterwards [s]


def _errors(c: Checker, since: int) -> list[Seen]:
    return [s for s in c.tx.frames(since, "error") if isinstance(s.frame.data, dict)]


async def malformed(c: Checker) -> None:
    """Send the `MALFORMED` lines, then a reliable frame with bad data and the same seq
    right; watch the answers and that the link stays."""
    tx = c.tx
    since = len(tx.lines)
    for line, _fault in MALFORMED:
        await c.peer.send_raw(line)
    await trio.sleep(c.slack(_ANSWER_S))
    if not c.peer.connected:
        c.lost_link = "the rover closed the link after malformed lines"
        c.quiet.append((tx.now(), float("inf")))
        c.found.fail("malformed.answered", c.lost_link, tx.rover(since)[-2:])
        c.found.fail("malformed.survives", c.lost_link, tx.rover(since)[-2:])
        return
    errors = _errors(c, since)
    faults = [s.frame.data.get("fault") for s in errors]
    if len(errors) < len(MALFORMED):
        c.found.fail("malformed.answered", f"{len(errors)} error frame(s) for "
                     f"{len(MALFORMED)} malformed lines", tx.lines[since:since + 2] + errors)
    elif any(f not in Fault.ALL for f in faults):
        c.found.fail("malformed.answered", f"errors name faults {faults}", errors)
    else:
        c.found.ok("malformed.answered", f"{len(MALFORMED)} malformed lines answered: "
                   f"{', '.join(str(f) for f in faults[:len(MALFORMED)])}", errors)
    # a reliable frame that does not fit: neither acknowledged nor acted on
    seq = c.peer.next_seq
    bad = Frame("origin", "pose", {"x": "left", "y": 0.0, "heading": 0.0})
    index = len(tx.lines)
    await c.peer.send_with_seq(bad, seq, resend=False)
    c.peer.next_seq = seq + 1
    answer = await tx.wait_for(lambda s: s.frame is not None and s.frame.cmd == "error",
                               c.slack(_ANSWER_S), index)
    await trio.sleep(c.slack(0.5))
    acked = [s for s in tx.rover(index) if s.frame is not None and s.frame.ack is not None
             and s.frame.ack >= seq]
    good = Frame("origin", "pose", {"x": 0.0, "y": 0.0, "heading": 0.0})
    again = len(tx.lines)
    await c.peer.send_with_seq(good, seq)
    c.expects.append(Expect(seq, again, tx.lines[again].t, c.epoch))
    ack = await tx.wait_for(lambda s: s.frame is not None and s.frame.ack is not None
                            and s.frame.ack >= seq, c.slack(_ANSWER_S), again)
    data = answer.frame.data if answer is not None and isinstance(answer.frame.data, dict) \
        else {}
    if answer is None or data.get("fault") != Fault.BAD_DATA:
        c.found.fail("malformed.reliable", "origin with x \"left\" was not answered bad_data",
                     [tx.lines[index]] + ([answer] if answer else []))
    elif acked:
        c.found.fail("malformed.reliable", f"origin seq {seq} with bad data was acknowledged",
                     [tx.lines[index], acked[0]])
    elif ack is None:
        c.found.fail("malformed.reliable", f"origin seq {seq} sent right was not acknowledged",
                     [tx.lines[again]])
    else:
        c.found.ok("malformed.reliable", f"bad data answered {data.get('detail', '')[:60]!r}, "
                   f"not acknowledged; seq {seq} sent right acknowledged", [answer, ack])
    # the link stays: still open, and the rover speaks after the last of those lines
    await trio.sleep(_ALIVE_S)
    late = tx.rover(again + 1)
    if not c.peer.connected:
        c.lost_link = "the rover closed the link after malformed lines"
        c.found.fail("malformed.survives", c.lost_link, tx.rover(since)[-2:])
    elif not late:
        c.found.fail("malformed.survives", "the rover went silent after the malformed lines",
                     tx.rover(since)[-2:])
    else:
        c.found.ok("malformed.survives", f"link open, the rover still speaking "
                   f"{late[-1].t - tx.lines[again].t:.1f} s later", late[-1:])
