"""Rules of saying hello: ``hello.first``, ``hello.repeat``, ``hello.welcome``."""

from __future__ import annotations

from .context import TELEMETRY_STREAMS, Checker, read_hello

__all__ = ["greet", "judge_welcome"]

_HELLO_BACKOFF_MAX_S = 8.0  # docs/protocol.md section 4: hellos back off to at most 8 s


async def greet(c: Checker) -> bool:
    """Wait for the rover's hello, let it say it again, and welcome it.

    Returns False when no hello came (the check cannot go on).
    """
    tx = c.tx
    if c.link.speaks_first:
        await c.hello_first()
    first = await tx.wait_for(lambda s: True, c.opts.connect_s)
    if first is None:
        c.found.fail("hello.first", f"the rover sent nothing within {c.opts.connect_s:g} s")
        c.lost_link = "the rover never spoke"
        return False
    h1 = await tx.wait_cmd("hello", c.opts.connect_s)
    if h1 is None:
        c.found.fail("hello.first", "no hello came", tx.rover()[:4])
        c.lost_link = "the rover never said hello"
        return False
    data = read_hello(h1.frame) if h1.frame else None
    before = [s for s in tx.lines[:tx.index(h1)] if s.sender == "R"]
    if c.link.speaks_first:  # a serial port opened mid-line gives a fragment first: noise
        before = [s for s in before if s.frame is not None]
    if data is None:
        c.found.fail("hello.first", "the hello does not fit the catalogue (id, role, "
                     "token, seq_base)", [h1])
        c.lost_link = "the hello was not well-formed"
        return False
    c.hello = dict(data)
    streams, faults = data.get("streams"), data.get("faults")
    if isinstance(streams, list):
        c.streams = tuple(str(s) for s in streams)
    if isinstance(faults, list):
        c.faults = tuple(str(f) for f in faults)
    if c.opts.role and data.get("role") != c.opts.role:
        c.found.fail("hello.first", f"hello says role {data.get('role')!r}, --role asks for "
                     f"{c.opts.role!r}", [h1])
    elif before:
        c.found.fail("hello.first", f"{len(before)} line(s) came before the hello", before)
    # the repeat: leave the hello unanswered for one backoff step at most
    bound = c.slack(_HELLO_BACKOFF_MAX_S) + c.opts.slack_s  # the rover's tick on top
    h2 = await tx.wait_cmd("hello", bound, tx.index(h1) + 1)
    if h2 is None:
        c.found.fail("hello.repeat", f"no second hello within {_HELLO_BACKOFF_MAX_S:g} s of "
                     "the first", [h1])
    else:
        c.found.ok("hello.repeat", f"said again after {h2.t - h1.t:.2f} s", [h1, h2])
    others = [s for s in tx.rover() if s.frame is None or s.frame.cmd != "hello"]
    if others and not c.found.has("hello.first"):
        c.found.fail("hello.first", "a frame other than hello came before the welcome",
                     others[:3])
    elif not c.found.has("hello.first"):
        c.found.ok("hello.first", f"hello from {data['id']!r} as {data['role']}, seq_base "
                   f"{data.get('seq_base', 1)}; nothing else before the welcome", [h1])
    if c.streams:
        known = [s for s in c.streams if s in TELEMETRY_STREAMS]
        wanted = known[:-1] if len(known) > 1 else known  # one left out: is it sent anyway?
        c.asked = {s: (0.0 if s == "events" else c.opts.tm_interval_s) for s in wanted}
    last = tx.frames(0, "hello")[-1]
    c.peer.reset_rover_seq(int(last.frame.data.get("seq_base") or 1))
    await c.welcome(1)
    c.auto_welcome = True
    return True


def judge_welcome(c: Checker) -> None:
    """``hello.welcome``: after the first welcome, the rover's next frame comes within a
    heartbeat, and no hello follows until the checker drops or resyncs the link."""
    if not c.welcomes:
        return
    index, t = c.welcomes[0]
    end = min((q[0] for q in c.quiet), default=float("inf"))
    after = [s for s in c.tx.rover(index) if s.t < end]
    late = [s for s in after if s.frame is not None and s.frame.cmd == "hello"
            and s.t > c.slack(t + 1.0)]
    if not after or after[0].t > c.slack(t + 1.0):
        c.found.fail("hello.welcome", "nothing came within 1 s of the welcome",
                     after[:1])
    elif late:
        c.found.fail("hello.welcome", "the rover said hello again after the welcome", late)
    else:
        what = after[0].frame.cmd if after[0].frame else "a line"
        c.found.ok("hello.welcome", f"session started: {what} {after[0].t - t:.2f} s after "
                   "the welcome", [after[0]])
