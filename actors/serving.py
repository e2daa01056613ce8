"""Serving one incarnation's mailbox: bursts, replies, injected faults, poison messages.

The loop drains bursts (every waiting message taken with ``receive_nowait``
and handled in turn, one checkpoint per burst; `Actor.handle_burst` overrides
get the burst whole), replies to calls, applies pending injected faults, and
turns a crash or a hang into the incarnation's exit reason, dropping and
reporting the message being handled (poison). The watchdog is `actors.watchdog`.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import trio

from .actor import Actor, ActorContext, InjectedCrash
from .call import CallEnvelope, CallFailed
from .cell import Cell
from .exits import HUNG, SHUTDOWN, ExitReason
from .trace import EventKind, Trace
from .watchdog import Guard

__all__ = ["serve"]


async def serve(cell: Cell, actor: Actor, ctx: ActorContext, trace: Trace,
                max_burst: int) -> ExitReason:
    """The message loop; turns a crash into a reason and reports the poison message."""
    try:
        return await _serve(cell, actor, ctx, trace, max_burst)
    except Exception as exc:
        reason = ExitReason.crash(exc)
        trace.emit(EventKind.CRASH, cell.name, cell.name, None, cell.mailbox.depth, reason.detail)
        _drop_poison(cell, actor, trace, reason)
        return reason


def _drop_poison(cell: Cell, actor: Actor, trace: Trace, reason: ExitReason) -> None:
    poison = cell.current
    cell.current = None
    if poison is None:
        return
    for item in poison if isinstance(poison, list) else (poison,):
        if type(item) is CallEnvelope:
            item.fail(CallFailed(cell.name, reason))
            item = item.request
        try:
            actor.discard(item)
        except Exception as exc:  # a broken hook must not hide the crash being reported
            trace.emit(EventKind.POISON, cell.name, cell.name, item, cell.mailbox.depth,
                       f"discard raised {exc!r}")
    trace.emit(EventKind.POISON, cell.name, cell.name, poison, cell.mailbox.depth, str(reason))


async def _serve(cell: Cell, actor: Actor, ctx: ActorContext, trace: Trace,
                 max_burst: int) -> ExitReason:
    """Serve under one watchdog guard per incarnation (see `Guard`); a guard that fired
    while no message was being handled (only possible on a real clock, at a checkpoint
    between bursts) was a false alarm: a new guard is opened and serving goes on."""
    while True:
        guard = Guard(cell.watchdog)
        try:
            with guard.scope:
                return await _serve_loop(cell, actor, ctx, trace, max_burst, guard)
        finally:
            guard.disarm()  # out of Trio's heap with the scope, as the scope's deadline was
        if cell.current is not None:
            return _hung(cell, actor, trace)


async def _serve_loop(cell: Cell, actor: Actor, ctx: ActorContext, trace: Trace,
                      max_burst: int, guard: Guard) -> ExitReason:
    mailbox = cell.mailbox
    queue = mailbox._queue  # read-only peeks on the hot path
    receive = mailbox.receive_nowait
    handle = actor.handle
    arm = guard.arm if guard.watchdog is not None else None  # None: nothing to arm
    burst_mode = type(actor).handle_burst is not Actor.handle_burst
    checkpoint = trio.lowlevel.checkpoint
    while True:
        if cell.stop_requested:
            return SHUTDOWN
        if ctx._stop:
            return ctx._stop
        if cell.crash_pending or cell.hang_pending:
            guard.disarm()
            if not await _slow(cell, actor, trace, None):
                return _hung(cell, actor, trace)
            continue
        if not queue:
            guard.disarm()
            await mailbox.wait()
            continue
        if burst_mode:
            if not await _burst(cell, actor, trace, max_burst, guard):
                return _hung(cell, actor, trace)
        else:
            n = 0
            while queue and n < max_burst:
                item = receive()
                cell.current = item
                if cell.crash_pending or cell.hang_pending:
                    guard.disarm()
                    if not await _slow(cell, actor, trace, item):
                        return _hung(cell, actor, trace)
                elif type(item) is CallEnvelope:
                    if arm is not None:
                        arm()
                    if not item.reply(await handle(item.request)):
                        trace.emit(EventKind.LATE_REPLY, cell.name, cell.name, item, len(queue))
                else:
                    if arm is not None:
                        arm()
                    await handle(item)
                n += 1
                if cell.stop_requested or ctx._stop:
                    break
            cell.current = None
        if queue:
            # one checkpoint per burst; an empty mailbox parks instead (also a checkpoint)
            await checkpoint()


def _hung(cell: Cell, actor: Actor, trace: Trace) -> ExitReason:
    trace.emit(EventKind.HUNG, cell.name, cell.name, None, cell.mailbox.depth,
               f"watchdog {cell.watchdog} s")
    _drop_poison(cell, actor, trace, HUNG)
    return HUNG


async def _slow(cell: Cell, actor: Actor, trace: Trace, item: Any) -> bool:
    """Handle one item (or only pending faults when ``item`` is None) under the watchdog.

    Returns:
        False when the watchdog fired.
    """
    if type(item) is CallEnvelope:
        ok, value = await _guarded(cell, actor.handle, item.request)
        if ok and not item.reply(value):
            trace.emit(EventKind.LATE_REPLY, cell.name, cell.name, item, cell.mailbox.depth)
        return ok
    ok, _ = await _guarded(cell, None if item is None else actor.handle, item)
    return ok


async def _guarded(cell: Cell, work: Callable[[Any], Awaitable[Any]] | None,
                   arg: Any) -> tuple[bool, Any]:
    """Run ``work(arg)`` after the cell's pending injected faults, under its watchdog.

    The one place injected crashes and hangs take effect, for single messages
    and bursts alike. Returns (False, None) when the watchdog fired, else
    (True, the work's value).
    """
    if cell.crash_pending:
        cell.crash_pending = False
        raise InjectedCrash(f"injected crash in {cell.name}")
    value = None
    with trio.CancelScope() as scope:
        if cell.watchdog is not None:
            scope.deadline = trio.current_time() + cell.watchdog
        if cell.hang_pending:
            seconds, cell.hang_pending = cell.hang_pending, 0.0
            await trio.sleep(seconds)
        if work is not None:
            value = await work(arg)
    return not scope.cancelled_caught, value


async def _burst(cell: Cell, actor: Actor, trace: Trace, max_burst: int,
                 guard: Guard) -> bool:
    """Drain a burst for a `handle_burst` override; calls are handled one by one.

    Faults pending take the slow path (`_slow`, its own scope); otherwise the
    burst runs under the incarnation's ``guard``, whose firing `_serve` reports.
    """
    queue = cell.mailbox._queue
    receive = cell.mailbox.receive_nowait
    slow = cell.crash_pending or cell.hang_pending
    if slow:
        guard.disarm()
    batch: list[Any] = []
    while queue and len(batch) < max_burst:
        if type(queue[0]) is CallEnvelope:
            if batch:
                break
            item = receive()
            cell.current = item
            if slow:
                ok = await _slow(cell, actor, trace, item)
            else:
                guard.arm()
                value = await actor.handle(item.request)
                if not item.reply(value):
                    trace.emit(EventKind.LATE_REPLY, cell.name, cell.name, item,
                               cell.mailbox.depth)
                ok = True
            cell.current = None
            return ok
        batch.append(receive())
    cell.current = batch
    if slow:
        ok, _ = await _guarded(cell, actor.handle_burst, batch)
    else:
        guard.arm()
        await actor.handle_burst(batch)
        ok = True
    cell.current = None
    return ok
