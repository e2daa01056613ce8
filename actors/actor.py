"""Actors: the class users subclass, its context, and the loop that runs one incarnation.

An actor handles one message at a time from its bounded mailbox::

    class Echo(Actor):
        async def handle(self, message):
            return message          # the reply when the message came by call()

Life of one incarnation (run by its supervisor through `run_actor`):

1. the factory makes the actor, ``ctx`` is attached, the child spec's ``init``
   hook (if any) and then ``on_start()`` run; a failure here is a failed start
   (the supervisor's start fails); `IGNORE` returned by the factory, the hook or
   ``on_start`` means "do not start" (OTP's ``ignore``): no failure, no exit;
2. the loop drains bursts: every waiting message is taken with
   ``receive_nowait`` and handled in turn, with one checkpoint per burst;
3. on exit ``on_stop(reason)`` runs (not after ``killed``), the actor's timers
   are cancelled, every call it held or that waits in its mailbox fails with
   the exit reason (`CallFailed`) and monitors get a `Down` notice.

Self-chosen exits: ``ctx.stop()`` ends the incarnation with ``normal`` after the
current message, ``ctx.stop("shutdown")`` with ``shutdown`` and
``ctx.stop("shutdown", term)`` with OTP's ``{shutdown, term}``; the supervisor
applies the child's restart type to it as to any exit.

Replies: the value ``handle`` returns is the reply to a ``call``; for other
messages it is ignored.

Poison messages: the message being handled when the actor crashed or hung is
dropped and reported (trace ``poison``), not redelivered, after the dying
incarnation's ``discard`` hook saw it (to release a pool buffer it refers
to); messages still waiting stay in the mailbox for the next incarnation.

Watchdog: with a deadline [s], handling one message (one burst for
`Actor.handle_burst` overrides) that takes longer is cancelled and the actor
exits with reason ``hung``. Trio cancels only at checkpoints: an actor stuck
in a loop that never awaits cannot be cancelled (and blocks the whole run).

Faults (for tests and the console): a pending ``inject_crash`` makes the next
handling (or, when idle, the actor at once) raise `InjectedCrash`; a pending
``inject_hang`` makes it sleep first, at a checkpoint, so the watchdog fires.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import trio

from .call import CallEnvelope, CallFailed
from .cell import ActorState, Cell, Monitor
from .clock import HeapEntry, deadline_heap, sleep
from .exits import HUNG, IGNORE, KILLED, SHUTDOWN, ExitKind, ExitReason, Ignore
from .timers import TaskTimer, Timer
from .trace import EventKind, Trace

if TYPE_CHECKING:
    from .system import ActorSystem

__all__ = ["Actor", "ActorContext", "Timer", "InjectedCrash", "run_actor"]

#: the most timers one actor may have running at once
MAX_TIMERS = 256


class InjectedCrash(Exception):
    """The exception an injected crash fault raises inside an actor."""


class Actor:
    """Base class of actors: override `handle`; the other hooks are optional."""

    ctx: ActorContext
    """Set by the runtime before `on_start`: name, system, trace, rng, timers."""

    async def on_start(self) -> Any:
        """Called once per incarnation before the first message; raising fails the start,
        returning `IGNORE` leaves the child not started without failure (OTP's ``ignore``)."""

    async def handle(self, message: Any) -> Any:
        """Handle one message; the return value is the reply when it came by ``call``."""
        raise NotImplementedError(f"{type(self).__name__} must define handle()")

    async def handle_burst(self, messages: list[Any]) -> None:
        """Handle a drained burst (never contains calls); the default calls `handle` for each.

        Override to process a burst at once (e.g. vectorise LIDAR points). If it
        raises, the whole burst is the poison and is reported.
        """
        for message in messages:
            await self.handle(message)

    async def on_stop(self, reason: ExitReason) -> None:
        """Called when the incarnation ends (not when it was killed)."""

    def discard(self, message: Any) -> None:
        """Called for each message the runtime drops unhandled: the poison of a crash or hang.

        Override to release what the message refers to (a `BufferPool` slot
        behind a handle), which would otherwise leak. It runs synchronously
        on the dying incarnation and must not raise (a raise is traced and
        ignored); the handler may already have released the resource.
        """


class ActorContext:
    """What an actor can reach: its name, the system, the trace, its rng, timers."""

    def __init__(self, system: ActorSystem, cell: Cell) -> None:
        self.name: str = cell.name
        """The registered name, e.g. ``mapper/motor``."""
        self.system = system
        """The actor system: registry, send/cast/call by name, monitors, faults."""
        self.trace: Trace = system.trace
        """The run's trace hub."""
        self.rng: np.random.Generator = cell.rng
        """This actor's generator, derived from the run's seed and the name (kept across
        restarts)."""
        self._cell = cell
        self._timers: trio.Nursery | None = None  # set while the incarnation runs
        self._live_timers: dict[Timer | TaskTimer, None] = {}  # running timers, in start order
        self._stop: ExitReason | None = None  # the exit the actor chose, once it chose one

    # ---------------------------------------------------------------- messaging
    async def send(self, name: str, message: Any) -> None:
        """`ActorSystem.send`."""
        await self.system.send(name, message)

    def send_nowait(self, name: str, message: Any) -> bool:
        """`ActorSystem.send_nowait`."""
        return self.system.send_nowait(name, message)

    async def cast(self, name: str, message: Any) -> bool:
        """`ActorSystem.cast`."""
        return await self.system.cast(name, message)

    async def call(self, name: str, request: Any, *, timeout: float) -> Any:
        """`ActorSystem.call` (an actor calling itself would deadlock until the timeout)."""
        return await self.system.call(name, request, timeout=timeout)

    def monitor(self, name: str, capacity: int = 16) -> Monitor:
        """`ActorSystem.monitor`."""
        return self.system.monitor(name, capacity)

    @property
    def mailbox_depth(self) -> int:
        """Messages waiting in this actor's mailbox."""
        return self._cell.mailbox.depth

    def stop(self, kind: str = "normal", term: object = None) -> None:
        """End this incarnation after the current message, with a reason of its choice.

        ``stop()`` exits ``normal``, ``stop("shutdown")`` exits ``shutdown`` and
        ``stop("shutdown", term)`` exits OTP's ``{shutdown, term}`` (kind ``shutdown``,
        detail ``str(term)``). The supervisor applies the restart type: a
        ``permanent`` child is restarted, a ``transient`` or ``temporary`` one is not.
        To exit abnormally, raise.

        Raises:
            ValueError: ``kind`` is not ``normal`` or ``shutdown``, or a term with ``normal``.
        """
        if kind == ExitKind.NORMAL and term is None:
            self._stop = ExitReason(ExitKind.NORMAL)
        elif kind == ExitKind.SHUTDOWN:
            self._stop = ExitReason.shutdown(term)
        else:
            raise ValueError(f"stop kind must be normal or shutdown (a term only with "
                             f"shutdown), got {kind!r} with term {term!r}")

    # ---------------------------------------------------------------- timers
    def start_timer(self, delay: float, message: Any, *,
                    interval: float | None = None) -> Timer | TaskTimer:
        """Post ``message`` to this actor's own mailbox after ``delay`` [s], then every
        ``interval`` [s] if given. Timers stop with the incarnation.

        Posting uses ``send_nowait``: a full mailbox drops the tick (counted).

        Raises:
            ValueError: ``delay`` < 0 or ``interval`` <= 0.
            RuntimeError: outside a running actor, or more than `MAX_TIMERS` running.
        """
        if not delay >= 0:
            raise ValueError(f"delay must be >= 0 [s], got {delay!r}")
        if interval is not None and not interval > 0:
            raise ValueError(f"interval must be > 0 [s], got {interval!r}")
        if self._timers is None:
            raise RuntimeError("start_timer needs a running actor (from on_start or handle)")
        if len(self._live_timers) >= MAX_TIMERS:
            raise RuntimeError(f"an actor may run at most {MAX_TIMERS} timers")
        service = self.system.timers
        timer: Timer | TaskTimer
        if service is not None:
            timer = service.start(self._cell.mailbox, message, delay, interval,
                                  self._timer_done)
        else:
            timer = TaskTimer(trio.CancelScope())
            self._timers.start_soon(self._tick, timer, delay, message, interval)
        self._live_timers[timer] = None
        return timer

    def _timer_done(self, timer: Timer | TaskTimer) -> None:
        self._live_timers.pop(timer, None)

    async def _tick(self, timer: TaskTimer, delay: float, message: Any,
                    interval: float | None) -> None:
        mailbox = self._cell.mailbox
        try:
            with timer._scope:
                await sleep(delay)
                mailbox.send_nowait(message)
                while interval is not None:
                    await sleep(interval)
                    mailbox.send_nowait(message)
        finally:
            self._timer_done(timer)

    def _cancel_timers(self) -> None:
        """Stop every timer of this incarnation (at its end)."""
        for timer in list(self._live_timers):
            timer.cancel()


# ---------------------------------------------------------------------- running one incarnation
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

    Returns:
        The exit reason (`IGNORE` when ignored).
    """
    trace = system.trace
    started = False
    reason: ExitReason | Ignore = KILLED
    ctx: ActorContext | None = None
    cell.state = ActorState.STARTING
    cell.stop_requested = False
    try:
        with trio.CancelScope() as scope:
            cell.scope = scope
            async with trio.open_nursery() as timers:
                try:
                    actor = factory()
                    if actor is IGNORE:
                        reason = IGNORE
                        return reason
                    if not isinstance(actor, Actor):
                        raise TypeError(f"the factory must return an Actor, got {actor!r}")
                    ctx = ActorContext(system, cell)
                    ctx._timers = timers
                    actor.ctx = ctx
                    cell.actor = actor
                    if init is not None:
                        hooked = init(actor)
                        if hasattr(hooked, "__await__"):
                            hooked = await hooked
                        if hooked is IGNORE:
                            reason = IGNORE
                    if reason is not IGNORE and await actor.on_start() is IGNORE:
                        reason = IGNORE
                    if reason is IGNORE:
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
                reason = await _serve_safely(cell, actor, ctx, trace, system.max_burst)
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
    finally:
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
            task_status.started(reason)
        else:
            trace.emit(EventKind.STOP, cell.name, cell.name, None, cell.mailbox.depth, str(reason))
            cell.notify_down(reason)


async def _serve_safely(cell: Cell, actor: Actor, ctx: ActorContext, trace: Trace,
                        max_burst: int) -> ExitReason:
    """The message loop; turns a crash into a reason and reports the poison message."""
    try:
        return await _serve(cell, actor, ctx, trace, max_burst)
    except Exception as exc:
        reason = ExitReason.crash(exc)
        trace.emit(EventKind.CRASH, cell.name, cell.name, None, cell.mailbox.depth, reason.detail)
        _drop_poison(cell, actor, trace, reason)
        return reason


def _fail_held(cell: Cell, reason: Any) -> None:
    """Fail the calls in the message (or burst) the incarnation held when it ended."""
    held, cell.current = cell.current, None
    for item in held if isinstance(held, list) else (held,):
        if type(item) is CallEnvelope:
            item.fail(CallFailed(cell.name, reason if type(reason) is ExitReason else KILLED))


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
    """Serve under one watchdog guard per incarnation (see `_Guard`); a guard that fired
    while no message was being handled (only possible on a real clock, at a checkpoint
    between bursts) was a false alarm: a new guard is opened and serving goes on."""
    while True:
        guard = _Guard(cell.watchdog)
        try:
            with guard.scope:
                return await _serve_loop(cell, actor, ctx, trace, max_burst, guard)
        finally:
            guard.disarm()  # out of Trio's heap with the scope, as the scope's deadline was
        if cell.current is not None:
            return _hung(cell, actor, trace)


class _Guard(HeapEntry):
    """The watchdog of one incarnation: one cancel scope, cancelled when the deadline
    of the message being handled passes.

    Why not a scope per message: entering and leaving a Trio cancel scope per
    handled message was the largest single cost of the runtime in a whole game
    (about 13 us each). Here the deadline is set to (start of the message being
    handled + watchdog) only when the clock has moved since it was last set (in
    virtual time a burst handled at one instant sets it once), and taken away
    before the actor parks on an empty mailbox, so an idle actor is never woken by
    it. A handler that blocks past its deadline is cancelled at exactly start +
    watchdog, as with a scope of its own.

    Why the guard itself sits in Trio's deadline heap (as `actors.clock.sleep_until`'s
    alarms do) instead of setting the scope's deadline: each deadline change of a
    scope goes through Trio's bookkeeping (a context manager, twice per message
    at a new instant, about 4 % of a game). When the deadline is due, Trio's expiry
    pass calls `_cancel` with its reason, which cancels the scope at that moment,
    as the scope's own deadline would have. Without the heap (another Trio) the
    scope's deadline is moved as before.
    """

    __slots__ = ("scope", "watchdog", "since")

    def __init__(self, watchdog: float | None) -> None:
        super().__init__(deadline_heap() if watchdog is not None else None)
        self.scope = trio.CancelScope()
        self.watchdog = watchdog
        self.since = math.inf  # when the deadline was last set [s]; inf: not armed

    def arm(self) -> None:
        """A message starts now: its handling must end within the watchdog deadline."""
        if self.watchdog is not None:
            now = trio.current_time()
            if now != self.since:
                self.since = now
                if self._deadlines is None:
                    self.scope.deadline = now + self.watchdog
                    return
                self._leave()
                self._enter(now + self.watchdog)

    def disarm(self) -> None:
        """Nothing is being handled from now on (before parking, or a fault's own scope)."""
        if self.since != math.inf:
            self.since = math.inf
            if self._deadlines is None:
                self.scope.deadline = math.inf
            else:
                self._leave()

    def _cancel(self, reason: Any) -> None:
        """The deadline is due (called by Trio's `Deadlines.expire`): fire the watchdog."""
        self._leave()
        self.scope._cancel(reason)  # noqa: SLF001 - what the scope's own deadline calls


async def _serve_loop(cell: Cell, actor: Actor, ctx: ActorContext, trace: Trace,
                      max_burst: int, guard: _Guard) -> ExitReason:
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
                 guard: _Guard) -> bool:
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
