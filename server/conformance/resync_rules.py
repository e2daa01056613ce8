"""Reconnection and resync: ``reconnect.resume`` and ``resync.hello_first``.

Both leave a reliable frame of the rover unacknowledged (``pending``) and
expect, after the new hello, ``seq_base`` = that frame's ``seq`` (or the
rover's next ``seq`` when nothing is pending) and the frame resent unchanged.
The resync also claims a restarted server: its welcome says ``seq_base`` 1 and a
new ``session``, and the next frame of the checker, numbered 1, must be taken and
acknowledged. A rover whose first hello said a ``session`` must say the same one
in both hellos (it kept its numbering).
"""

from __future__ import annotations

import trio

from .context import Checker
from .peer import Seen

__all__ = ["reconnect", "resync"]

_RESEND_WAIT_S = 9.0
"""A pending frame is resent within the longest resend timeout (8 s) [s]."""
_HELLO_WAIT_S = 1.0
"""'send hello first' is answered at once [s]."""


def _next_seq(c: Checker) -> int:
    seqs = [s.frame.seq for s in c.tx.frames() if s.frame.seq is not None]
    return max(seqs, default=int(c.hello.get("seq_base") or 1) - 1) + 1


async def _rehello(c: Checker, rule: str, since: int, pending: Seen | None,
                   wait_s: float) -> Seen | None:
    """The hello from transcript index ``since``, its seq_base checked; None (and the rule
    failed) when none came or it is wrong. A session other than the first hello's
    (when that said one: it must not change while the rover keeps its numbering)
    fails the rule too, but the phase goes on, so no other rule pays for it."""
    hello = await c.tx.wait_cmd("hello", wait_s, since)
    if hello is None:
        c.found.fail(rule, f"no hello within {wait_s:g} s", c.tx.rover(since)[:3])
        return None
    base = hello.frame.data.get("seq_base", 1) if isinstance(hello.frame.data, dict) else None
    want = pending.frame.seq if pending is not None else _next_seq(c)
    if base != want:
        what = f"its unacknowledged {pending.frame.cmd}" if pending else "its next seq"
        c.found.fail(rule, f"hello says seq_base {base}, {what} is {want}",
                     [hello] + ([pending] if pending else []))
        return None
    first = c.hello.get("session")
    said = hello.frame.data.get("session") if isinstance(hello.frame.data, dict) else None
    if first is not None and said != first:
        c.found.fail(rule, f"hello says session {said}, the rover's numbering is session "
                     f"{first} (a new session restarts the server's reception: frames it "
                     "took already would be taken twice)", [hello])
    return hello


async def _resent(c: Checker, rule: str, since: int, pending: Seen) -> Seen | None:
    seq = pending.frame.seq
    again = await c.tx.wait_for(lambda s: s.frame is not None and s.frame.seq == seq,
                                c.slack(_RESEND_WAIT_S), since)
    if again is None:
        c.found.fail(rule, f"{pending.frame.cmd} seq {seq} was not resent after the welcome",
                     [pending])
    return again  # whether it came back unchanged is resend.same's business


async def reconnect(c: Checker, pending: Seen | None) -> None:
    """Drop the link and take the rover back (``reconnect.resume``)."""
    if not c.link.can_drop:
        c.found.skip("reconnect.resume", f"a {c.link.spec.text.split(':')[0]} link has no "
                     "connection to drop (resync.hello_first covers the resync)")
        return
    c.auto_welcome = False
    t0 = c.tx.now()
    await c.peer.detach()
    stream = await c.link.reopen(c.opts.connect_s)
    if stream is None:
        c.found.fail("reconnect.resume", f"the rover did not come back within "
                     f"{c.opts.connect_s:g} s")
        c.lost_link = "the rover did not come back after the link dropped"
        c.quiet.append((t0, float("inf")))
        return
    since = len(c.tx.lines)
    await c.serve(stream)
    if c.link.speaks_first:
        await c.hello_first()
    else:  # as the server: a frame before hello on a new connection is answered
        first = await c.tx.wait_for(lambda s: True, c.opts.connect_s, since)
        if first is not None and (first.frame is None or first.frame.cmd != "hello"):
            await c.hello_first()
    hello = await _rehello(c, "reconnect.resume", since, pending, c.opts.connect_s)
    if hello is None:
        c.quiet.append((t0, c.tx.now()))
        c.auto_welcome = True
        return
    c.peer.reset_rover_seq(hello.frame.data.get("seq_base") or 1)
    unacked = c.peer.unacked()
    at = await c.welcome(unacked[0] if unacked else c.peer.next_seq)
    c.quiet.append((t0, c.tx.lines[at].t))
    c.auto_welcome = True
    if pending is None:
        c.found.ok("reconnect.resume", f"hello again after {hello.t - t0:.2f} s, seq_base "
                   "right", [hello])
        return
    again = await _resent(c, "reconnect.resume", at, pending)
    if again is not None:
        c.found.ok("reconnect.resume", f"hello again after {hello.t - t0:.2f} s with seq_base "
                   f"{pending.frame.seq}; {pending.frame.cmd} resent", [hello, again])


async def resync(c: Checker, pending: Seen | None) -> None:
    """'send hello first', then a welcome of a restarted server (``resync.hello_first``)."""
    rule = "resync.hello_first"
    if pending is None:  # let what is in flight be acknowledged: seq_base is then the next
        await trio.sleep(c.slack(1.0))
    c.auto_welcome = False
    t0 = c.tx.now()
    since = await c.hello_first()
    hello = await _rehello(c, rule, since, pending, c.slack(_HELLO_WAIT_S))
    if hello is None:
        c.quiet.append((t0, c.tx.now()))
        c.auto_welcome = True
        return
    c.peer.reset_rover_seq(hello.frame.data.get("seq_base") or 1)
    c.peer.restart_numbering()
    c.epoch += 1
    at = await c.welcome(1)
    c.quiet.append((t0, c.tx.lines[at].t))
    c.auto_welcome = True
    shown = [hello]
    if pending is not None:
        again = await _resent(c, rule, at, pending)
        if again is None:
            return
        shown.append(again)
    c.peer.auto_ack = True
    c.peer.ack_now()
    seq, index = await c.send("stop", "none")
    ack = await c.tx.wait_for(lambda s: s.frame is not None and s.frame.ack is not None
                              and s.frame.ack >= seq, c.slack(_HELLO_WAIT_S), index)
    if ack is None:
        c.found.fail(rule, "after a welcome with seq_base 1, stop seq 1 was not acknowledged",
                     [*shown, c.tx.lines[index]])
        return
    c.found.ok(rule, f"hello {hello.t - t0:.2f} s after 'send hello first'"
               + (f"; {pending.frame.cmd} resent" if pending else "")
               + "; seq 1 of a restarted server acknowledged", [*shown, ack])
