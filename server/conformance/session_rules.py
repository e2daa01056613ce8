"""Rules of the reliable session: ``seq.numbering``, ``ack.prompt``, ``resend.same``,
``resend.timeout``, ``duplicate.suppressed``, ``heartbeat.interval``.

The phases (`withhold`, `duplicate`) act on the link; the judges read the
whole transcript at the end.
"""

from __future__ import annotations

from collections.abc import Callable

from ..protocol import CATALOGUE, Frame
from .context import Checker
from .peer import Seen

__all__ = ["withhold", "resume_acks", "duplicate", "judge_seq", "judge_acks",
           "judge_heartbeat", "RELIABLE_EXTRA", "UNRELIABLE_EXTRA"]

ACK_WITHIN_S = 0.5
"""A reliable frame is acknowledged within this [s] ("promptly")."""
HEARTBEAT_S = 1.0
RTO_MIN_S, RTO_MAX_S = 0.3, 8.0
"""docs/protocol.md section 4: the resend timeout's bounds [s]."""
RELIABLE_EXTRA = frozenset({"fault_reply", "fault"})
"""Reliable cmds of the fault section, beyond the catalogue."""
UNRELIABLE_EXTRA = frozenset({"tm_mailboxes", "tm_tree", "tm_map", "tm_pose", "tm_event"})
"""Unreliable cmds of the telemetry section, beyond the catalogue."""


def _reliable(cmd: str) -> bool | None:
    """Whether ``cmd`` is reliable; None for a cmd no section names."""
    spec = CATALOGUE.get(cmd)
    if spec is not None:
        return spec.reliable
    if cmd in RELIABLE_EXTRA:
        return True
    if cmd in UNRELIABLE_EXTRA:
        return False
    return None


def _same(a: Frame, b: Frame) -> bool:
    return (a.cmd, a.type, a.data) == (b.cmd, b.type, b.data)


async def withhold(c: Checker, timeout_s: float,
                   match: Callable[[Seen], bool] = lambda s: True) -> Seen | None:
    """Stop acknowledging; the first new reliable frame of the rover that ``match`` takes
    and its next two sends judge ``resend.same`` and ``resend.timeout``. Acks stay off
    (the frame stays unacknowledged) until `resume_acks`.

    Returns the frame (its first send), None when none came within ``timeout_s`` [s].
    """
    tx, peer = c.tx, c.peer
    peer.auto_ack = False
    start = len(tx.lines)
    first = await tx.wait_for(lambda s: s.frame is not None and s.frame.seq is not None
                              and s.frame.seq > peer.acked and match(s), timeout_s, start)
    if first is None:
        return None
    assert first.frame is not None
    seq = first.frame.seq
    sends = [first]
    budget = c.slack(RTO_MAX_S) * 2
    while len(sends) < 3:
        nxt = await tx.wait_for(lambda s, seq=seq: s.frame is not None and s.frame.seq == seq,
                                budget, tx.index(sends[-1]) + 1)
        if nxt is None:
            break
        sends.append(nxt)
    what = f"{first.frame.cmd} seq {seq}"
    if len(sends) < 2:
        c.found.fail("resend.same", f"{what} was never resent in {budget:g} s without an ack",
                     sends)
        c.found.skip("resend.timeout", "nothing was resent")
        return first
    bad = [s for s in sends[1:] if not _same(s.frame, first.frame)]
    if bad:
        c.found.fail("resend.same", f"{what} came back with other content", [first, *bad])
    else:
        c.found.ok("resend.same", f"{what} sent {len(sends)} times unchanged", sends)
    gaps = [b.t - a.t for a, b in zip(sends, sends[1:], strict=False)]
    shown = ", ".join(f"{g:.2f}" for g in gaps)
    slack = c.opts.slack_s
    if gaps[0] < RTO_MIN_S - slack / 4 or any(g > RTO_MAX_S + slack for g in gaps):
        c.found.fail("resend.timeout", f"resent after {shown} s: outside {RTO_MIN_S:g}.."
                     f"{RTO_MAX_S:g} s", sends)
    elif len(gaps) == 2 and gaps[0] < RTO_MAX_S / 2 and not (
            2 * gaps[0] - 2 * slack <= gaps[1] <= 2 * gaps[0] + 2 * slack):
        c.found.fail("resend.timeout", f"resent after {shown} s: the wait did not double",
                     sends)
    elif len(gaps) < 2:
        c.found.fail("resend.timeout", f"resent once after {shown} s, not again", sends)
    else:
        c.found.ok("resend.timeout", f"resent after {shown} s", sends)
    return first


async def resume_acks(c: Checker) -> None:
    """Acknowledge again, at once, what came in order."""
    c.peer.auto_ack = True
    c.peer.ack_now()
    await c.peer.send(Frame("ack", "ack", None), bare_ack=True)


async def duplicate(c: Checker, frame: Frame, seq: int, acted: Callable[[Seen], bool],
                    what: str, watch_s: float = 3.0) -> None:
    """Send ``frame`` again with its acknowledged ``seq``: the rover must acknowledge it at
    again (within a heartbeat: how promptly is ``ack.prompt``'s business) and, for
    ``watch_s`` [s], send nothing ``acted`` takes (``what`` it would do)."""
    tx = c.tx
    index = len(tx.lines)
    await c.peer.send_with_seq(frame, seq, resend=False)
    ack = await tx.wait_for(lambda s: s.frame is not None and s.frame.ack is not None
                            and s.frame.ack >= seq, c.slack(HEARTBEAT_S), index)
    again = await tx.wait_for(acted, watch_s, index)
    dup = tx.lines[index]
    if again is not None:
        c.found.fail("duplicate.suppressed", f"{frame.cmd} seq {seq} received twice was "
                     f"acted on twice: {what} again", [dup, again])
    elif ack is None:
        c.found.fail("duplicate.suppressed", f"{frame.cmd} seq {seq} received again was not "
                     f"acknowledged again within {HEARTBEAT_S:g} s", [dup])
    else:
        c.found.ok("duplicate.suppressed", f"{frame.cmd} seq {seq} again: re-acknowledged "
                   f"after {ack.t - dup.t:.2f} s, not acted on", [dup, ack])


def judge_seq(c: Checker) -> None:
    """``seq.numbering`` over the transcript."""
    bad: list[Seen] = []
    why = ""
    highest: int | None = None
    for s in c.tx.rover():
        f = s.frame
        if f is None:
            continue
        if f.cmd == "hello" and isinstance(f.data, dict):
            base = f.data.get("seq_base") or 1
            if isinstance(base, int):
                if highest is not None and base > highest + 1 and not bad:
                    bad, why = [s], f"hello's seq_base {base} skips past {highest + 1}"
                highest = base - 1 if highest is None else highest
            continue
        reliable = _reliable(f.cmd)
        if reliable is None:
            continue
        if reliable and f.seq is None and not bad:
            bad, why = [s], f"{f.cmd} is reliable but came without seq"
        elif not reliable and f.seq is not None and not bad:
            bad, why = [s], f"{f.cmd} is unreliable but came with seq {f.seq}"
        elif reliable and f.seq is not None and highest is not None:
            if f.seq > highest + 1 and not bad:
                bad, why = [s], f"seq {f.seq} skips {highest + 1}"
            highest = max(highest, f.seq)
    if bad:
        c.found.fail("seq.numbering", why, bad)
    elif highest is None:
        c.found.skip("seq.numbering", "no hello, nothing to count")
    else:
        c.found.ok("seq.numbering", f"reliable frames numbered without a gap up to {highest}")


def judge_acks(c: Checker) -> None:
    """``ack.prompt`` over the transcript: every expected ack came within
    `ACK_WITHIN_S`, bare acks carry the field, no ack is beyond what was sent."""
    tx = c.tx
    bare = [s for s in tx.frames(0, "ack") if s.frame.ack is None]
    if bare:
        c.found.fail("ack.prompt", "a bare ack frame without its ack field", bare)
        return
    sent_seq = {e.seq for e in c.expects}
    slow: list[tuple[float, Seen, Seen | None]] = []
    worst = 0.0
    for e in c.expects:
        sent = tx.lines[e.index]
        later = [s for s in tx.rover(e.index) if s.frame is not None and s.frame.ack is not None
                 and s.frame.ack >= e.seq and s.link == sent.link]
        ack = later[0] if later else None
        delay = ack.t - e.t if ack else float("inf")
        worst = max(worst, delay)
        if delay > c.slack(ACK_WITHIN_S):
            slow.append((delay, sent, ack))
    beyond = [s for s in tx.rover() if s.frame is not None and s.frame.ack is not None
              and s.frame.ack > max(sent_seq | {c.peer.next_seq - 1}, default=0)]
    if beyond:
        c.found.fail("ack.prompt", f"ack {beyond[0].frame.ack} names a seq never sent", beyond)
    elif slow:
        delay, sent, ack = slow[0]
        shown = [sent] + ([ack] if ack else [])
        when = "never" if ack is None else f"after {delay:.2f} s"
        c.found.fail("ack.prompt", f"{len(slow)} of {len(c.expects)} reliable frames "
                     f"acknowledged late or never (first: {when}, limit "
                     f"{ACK_WITHIN_S:g} s)", shown)
    elif not c.expects:
        c.found.skip("ack.prompt", "no reliable frame was sent")
    else:
        c.found.ok("ack.prompt", f"{len(c.expects)} reliable frames acknowledged, the "
                   f"slowest after {worst:.2f} s")


def judge_heartbeat(c: Checker) -> None:
    """``heartbeat.interval``: the longest silence of the rover while the link was up."""
    tx = c.tx
    if not c.welcomes:
        return
    bad_form = [s for s in tx.frames(0, "heartbeat") if s.frame.type != "beat"
                or s.frame.data is not None or s.frame.seq is not None]
    if bad_form:
        c.found.fail("heartbeat.interval", "a heartbeat that is not heartbeat/beat/null "
                     "without seq", bad_form)
        return
    first_t = c.welcomes[0][1]
    end = tx.now()
    quiet = sorted(c.quiet)
    worst, pair = 0.0, None
    prev: Seen | None = None
    for s in tx.rover():
        if s.t < first_t:
            continue
        start_t = prev.t if prev is not None else first_t
        if any(q0 < s.t and q1 > start_t for q0, q1 in quiet):
            prev = s  # a span the rover need not speak in lies between
            continue
        if s.t - start_t > worst:
            worst, pair = s.t - start_t, (prev, s)
        prev = s
    if prev is not None and not any(q1 > prev.t for _, q1 in quiet) and end - prev.t > worst:
        worst, pair = end - prev.t, (prev, None)
    shown = [p for p in (pair or ()) if p is not None]
    if worst > c.slack(HEARTBEAT_S):
        c.found.fail("heartbeat.interval", f"silent for {worst:.2f} s (limit "
                     f"{HEARTBEAT_S:g} s)", shown)
    else:
        c.found.ok("heartbeat.interval", f"longest silence {worst:.2f} s", shown)
