"""Running one incarnation of an actor: start, serve, stop (runtime and supervisor use).

`run_actor` is the whole life of one incarnation as the contract in
`actors.actor` describes it, in three steps: make the actor and attach its
context (`_make`), run its start hooks (`_start_hooks`), serve its mailbox
(`actors.serving.serve`), and at the end, however it came, settle what the
incarnation leaves behind (`_end`): its timers, the calls it held, its state,
its exit reason, its monitors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import trio

from .actor import Actor, ActorContext
from .call import CallEnvelope, CallFailed
from .cell import ActorState, Cell
from .exits import IGNORE, KILLED, ExitReason, Ignore
from .serving import serve
from .trace import EventKind, Trace

if TYPE_CHECKING:
    from .system import ActorSystem

__all__ = ["run_actor"]


async def run_actor(system: ActorSystem, cell: Cell, factory: Any, *,
                    init: Callable[[Actor], Any] | None = None,
                    task_status: trio.TaskStatus[ExitReason | Ignore | None]
                    = trio.TASK_STATUS_IGNORED) -> ExitReason | Ignore:
    """Run one incarnation of the actor registered as ``cell`` (runtime/supervisor use).

    ``init(actor)`` (sync or async, optional) runs after ``ctx`` is attached and
    before ``on_start``: the per-child start hook of a `ChildSpec`.

    Reports ``task_status.started(None)`` once ``on_start`` succeeded,
    ``started(IGNORE)`` when a start hook returned `IGNORE`, or
    ``started(reason)`` with a ``start_failed``/``killed`` reason when the start
    failed, so ``await nursery.start(run_actor, ...)`` returns None on success.
    ``cell.scope`` is the incarnation's kill switch (cancel it: reason ``killed``).
    What the start does not survive it does not report: a ``KeyboardInterrupt`` or a
    cancellation from outside leaves through ``nursery.start`` as itself, so a
    Ctrl-C during a start stops the program as Ctrl-C, not as a failed start.

    Returns:
        The exit reason (`IGNORE` when ignored).
    """
    trace = system.trace
    started = False
    leaving = False  # a BaseException (Ctrl-C, an outer cancel) is on its way out
    reason: ExitReason | Ignore = KILLED
    ctx: ActorContext | None = None
    cell.state = ActorState.STARTING
    cell.stop_requested = False
    try:
        with trio.CancelScope() as scope:
            cell.scope = scope
            async with trio.open_nursery() as timers:
                try:
                    actor = _make(system, cell, factory, timers)
                    if actor is IGNORE:
                        reason = IGNORE
                        return reason
                    ctx = actor.ctx
                    if await _start_hooks(actor, init) is IGNORE:
                        reason = IGNORE
                        timers.cancel_scope.cancel()
                        return reason
                except Exception as exc:
                    reason = ExitReason.start_failed(f"{type(exc).__name__}: {exc}")
                    timers.cancel_scope.cancel()
                    return reason
                cell.state = ActorState.RUNNING
                trace.emit(EventKind.START, cell.name, cell.name, None, cell.mailbox.depth)
                started = True
                task_status.started(None)
                reason = await serve(cell, actor, ctx, trace, system.max_burst)
                timers.cancel_scope.cancel()
            ctx._timers = None
            cell.fail_calls(reason)  # calls left in the mailbox: fail them now, not after on_stop
            try:
                await actor.on_stop(reason)
            except Exception as exc:
                trace.emit(EventKind.CRASH, cell.name, detail=f"in on_stop: {exc!r}")
        if scope.cancelled_caught:
            reason = KILLED  # the supervisor traces why it killed
        return reason
    except BaseException:
        leaving = True
        raise
    finally:
        _end(cell, ctx, reason, trace, started=started,
             unstarted=None if started or leaving else task_status)


def _make(system: ActorSystem, cell: Cell, factory: Any, timers: trio.Nursery) -> Actor | Ignore:
    """Make the actor and attach its context (its timers run in ``timers``).

    Raises:
        TypeError: the factory returned neither an `Actor` nor `IGNORE`.
    """
    actor = factory()
    if actor is IGNORE:
        return IGNORE
    if not isinstance(actor, Actor):
        raise TypeError(f"the factory must return an Actor, got {actor!r}")
    ctx = ActorContext(system, cell)
    ctx._timers = timers
    actor.ctx = ctx
    cell.actor = actor
    return actor


async def _start_hooks(actor: Actor, init: Callable[[Actor], Any] | None) -> Ignore | None:
    """Run the child spec's ``init`` hook (sync or async), then ``on_start``; `IGNORE`
    from either means "do not start" (``on_start`` is not run after an ignoring hook)."""
    if init is not None:
        hooked = init(actor)
        if hasattr(hooked, "__await__"):
            hooked = await hooked
        if hooked is IGNORE:
            return IGNORE
    return IGNORE if await actor.on_start() is IGNORE else None


def _end(cell: Cell, ctx: ActorContext | None, reason: ExitReason | Ignore, trace: Trace, *,
         started: bool, unstarted: trio.TaskStatus[ExitReason | Ignore | None] | None) -> None:
    """Settle what an incarnation leaves, however it ended: its timers stop, calls it
    held fail, its exit is recorded; an incarnation that never started reports its
    reason to ``unstarted`` (its task status; None when an exception carries the news
    out of ``nursery.start``), a started one traces its stop and notifies its
    monitors."""
    if ctx is not None:
        ctx._timers = None
        ctx._cancel_timers()  # timers stop with the incarnation, however it ended
    cell.scope = None
    cell.actor = None
    if cell.current is not None:  # killed while handling: its callers learn it now
        _fail_held(cell, reason)
    cell.state = ActorState.STOPPED
    if type(reason) is ExitReason:
        cell.last_exit = reason
        cell.fail_calls(reason)
    if not started:
        if unstarted is not None:
            unstarted.started(reason)
    else:
        trace.emit(EventKind.STOP, cell.name, cell.name, None, cell.mailbox.depth, str(reason))
        cell.notify_down(reason)


def _fail_held(cell: Cell, reason: Any) -> None:
    """Fail the calls in the message (or burst) the incarnation held when it ended."""
    held, cell.current = cell.current, None
    for item in held if isinstance(held, list) else (held,):
        if type(item) is CallEnvelope:
            item.fail(CallFailed(cell.name, reason if type(reason) is ExitReason else KILLED))
