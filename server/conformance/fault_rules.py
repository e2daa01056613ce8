"""Fault commands: ``fault.reply`` and ``fault.opt_in``.

A rover that lists no ``faults`` in hello (the field absent) has no fault
section to check: both rules are skipped. One that lists some must accept the
first of them and refuse an unknown one as ``unsupported``; one that lists
none (``[]``) must answer every fault ``refused`` or ``unsupported``.
"""

from __future__ import annotations

import trio

from .context import Checker
from .peer import Seen

__all__ = ["faults", "UNKNOWN_FAULT"]

UNKNOWN_FAULT = ("checker", "nonesuch")
"""A target/kind no rover knows."""
_REPLY_S = 2.0  # a fault_reply comes at once [s]
_INJECT_S = 1.0  # how long an accepted fault lasts [s]


async def faults(c: Checker) -> None:
    """Send the faults, wait for the replies, judge both rules."""
    if c.faults is None:
        c.found.skip("fault.reply", "hello lists no faults")
        c.found.skip("fault.opt_in", "hello lists no faults")
        return
    plan: list[tuple[dict, tuple[str, ...]]] = []
    if c.faults:
        target, _, kind = c.faults[0].partition("/")
        plan.append(({"op": "inject", "target": target, "kind": kind, "duration": _INJECT_S},
                     ("accepted",)))
        plan.append(({"op": "clear", "target": target, "kind": "*"}, ("accepted",)))
    else:
        plan.append(({"op": "inject", "target": "lidar", "kind": "dead",
                      "duration": _INJECT_S}, ("refused", "unsupported")))
    plan.append(({"op": "inject", "target": UNKNOWN_FAULT[0], "kind": UNKNOWN_FAULT[1]},
                 ("unsupported",) if c.faults else ("refused", "unsupported")))
    since = len(c.tx.lines)
    sent: list[tuple[int, Seen, tuple[str, ...]]] = []
    for n, (body, want) in enumerate(plan, start=1):
        _, index = await c.send("fault", "inject", {"fault_id": n, **body})
        sent.append((n, c.tx.lines[index], want))
        await c.tx.wait_for(lambda s, n=n: _reply_id(s) == n, c.slack(_REPLY_S), index)
    await trio.sleep(c.slack(0.5))
    replies = [s for s in c.tx.frames(since, "fault_reply")]
    by_id: dict[int, list[Seen]] = {}
    for s in replies:
        by_id.setdefault(_reply_id(s), []).append(s)
    for n, out, _ in sent:
        got = by_id.get(n, [])
        distinct = {s.frame.seq for s in got}  # a resend of one reply is one reply
        if not got:
            c.found.fail("fault.reply", f"fault {n} got no fault_reply", [out])
            break
        if len(distinct) > 1:
            c.found.fail("fault.reply", f"fault {n} got {len(distinct)} replies", [out, *got])
            break
        if None in distinct:
            c.found.fail("fault.reply", f"fault {n}'s reply came without seq", [out, *got])
            break
    else:
        c.found.ok("fault.reply", f"{len(sent)} faults, one reply each", replies)
    for n, out, want in sent:
        got = by_id.get(n, [])
        result = got[0].frame.data.get("result") if got and isinstance(
            got[0].frame.data, dict) else None
        if result not in want:
            c.found.fail("fault.opt_in", f"fault {n} ({out.frame.data.get('target')}/"
                         f"{out.frame.data.get('kind')}) answered {result!r}, want "
                         f"{' or '.join(want)}", [out, *got[:1]])
            return
    c.found.ok("fault.opt_in", "listed faults accepted, others unsupported" if c.faults
               else "every fault refused (no opt-in)", replies)


def _reply_id(s: Seen) -> int | None:
    if s.frame is None or s.frame.cmd != "fault_reply" or not isinstance(s.frame.data, dict):
        return None
    n = s.frame.data.get("fault_id")
    return n if isinstance(n, int) else None
