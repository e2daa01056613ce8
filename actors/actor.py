"""Actors: the class users subclass, its context, and the loop that runs one incarnation.

An actor handles one message at a time from its bounded mailbox::

    class Echo(Actor):
        async def handle(self, message):
            return message          # the reply when the message came by call()

Life of one incarnation (run by its supervisor through `run_actor`, in
`actors.incarnation`; the message loop and its watchdog are `actors.serving`
and `actors.watchdog`):

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

from typing import TYPE_CHECKING, Any

import numpy as np
import trio

from .cell import Cell, Monitor
from .clock import sleep
from .exits import ExitKind, ExitReason
from .timers import TaskTimer, Timer
from .trace import Trace

if TYPE_CHECKING:
    from .system import ActorSystem

__all__ = ["Actor", "ActorContext", "Timer", "InjectedCrash"]

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

    def cast_nowait(self, name: str, message: Any) -> bool | None:
        """`ActorSystem.cast_nowait`."""
        return self.system.cast_nowait(name, message)

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
