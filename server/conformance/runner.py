"""`check_rover`: play the server's side against a rover and judge every rule.

The order of a check (each phase in its rule module):

1. hello: wait for hello, let it be said again, welcome (asking for telemetry
   when hello lists streams);
2. the role's work: a mapper maps and uploads, a hider or seeker downloads the
   map and reports. On the way a reliable frame of the rover is left
   unacknowledged (resends watched), the link is dropped and made again
   (reconnect), and a frame already acknowledged is sent again (duplicate);
3. 'send hello first' and a welcome of a restarted server (resync);
4. fault commands, when hello lists faults;
5. malformed lines, last (a rover that breaks on them spoils nothing else);
6. the judges that read the whole transcript: seq, acks, heartbeats,
   telemetry, the welcome.

Every wait is bounded, and the whole check by ``Options.timeout_s``; a rule
the check did not reach is skipped with the reason.
"""

from __future__ import annotations

import trio

from .context import Checker, Options
from .error_rules import malformed
from .fault_rules import faults
from .hello_rules import greet, judge_welcome
from .link import LinkUnreachable, RoverLink
from .peer import Peer, Transcript
from .resync_rules import resync
from .role_rules import run_hider_seeker, run_mapper
from .rules import RULES, Finding, Findings
from .session_rules import judge_acks, judge_heartbeat, judge_seq
from .telemetry_rules import judge_telemetry

__all__ = ["check_rover"]


async def check_rover(link: RoverLink, opts: Options) -> tuple[list[Finding], Transcript]:
    """Check the rover at the end of ``link``; every rule's finding, in registry order,
    and the transcript.

    Raises:
        LinkUnreachable: the link cannot be opened, or no rover came to it.
    """
    try:
        return await _check(link, opts)
    except BaseExceptionGroup as group:  # the link's opening fails inside the nursery
        unreachable = group.subgroup(LinkUnreachable)
        if unreachable is None:
            raise
        while isinstance(unreachable, BaseExceptionGroup):
            unreachable = unreachable.exceptions[0]
        raise unreachable from None


async def _check(link: RoverLink, opts: Options) -> tuple[list[Finding], Transcript]:
    tx = Transcript()
    peer = Peer(tx)
    found = Findings()
    timed_out = False
    async with trio.open_nursery() as nursery:
        stream = await link.open(nursery, opts.connect_s)
        c = Checker(opts, link, peer, tx, found, nursery)
        peer.on_frame = c.on_frame
        await c.serve(stream)
        with trio.move_on_after(opts.timeout_s) as scope:
            await _phases(c)
        timed_out = scope.cancelled_caught
        if c.lost_link:
            c.quiet.append((tx.now(), float("inf")))
        if c.welcomes:  # else nothing was played: the rules are not reached
            for judge in (judge_welcome, judge_seq, judge_acks, judge_heartbeat,
                          judge_telemetry):
                judge(c)
        _skip_other_roles(c)
        nursery.cancel_scope.cancel()
    await peer.detach()
    await link.aclose()
    why = (f"not reached: the check's --timeout of {opts.timeout_s:g} s ran out" if timed_out
           else f"not reached: {c.lost_link}" if c.lost_link else "not reached")
    return found.final(why), tx


async def _phases(c: Checker) -> None:
    if not await greet(c):
        return
    if c.role == "mapper":
        await run_mapper(c)
    else:
        await run_hider_seeker(c)
    if c.lost_link or not c.peer.connected:
        c.lost_link = c.lost_link or ("the rover flooded the link" if c.peer.flooded
                                      else "the rover closed the link")
        return
    await resync(c, c.pending)
    c.peer.auto_ack = True
    await faults(c)
    await malformed(c)


def _skip_other_roles(c: Checker) -> None:
    role = c.role
    for rule in RULES:
        if role and role not in rule.roles:
            c.found.skip(rule.id, f"for {' and '.join(rule.roles)}; this rover is a {role}")
