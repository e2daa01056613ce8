"""The actor system: registry by name, sending, calls, monitors, faults, and its lifetime.

::

    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(spec)      # a supervisors.SupervisorSpec
        await system.send("mapper/motor", msg)
    # leaving the block stops every tree (children in reverse start order)

The runtime knows nothing of supervisors (layering): `start_supervisor`
accepts any spec with a ``build(system, name)`` method returning an object
with ``async run(*, task_status)`` and ``stop()``, which
``supervisors.SupervisorSpec`` provides.

Sending by name (``mapper/motor``):

* ``await send(name, msg)`` waits for room in the mailbox (backpressure);
* ``send_nowait(name, msg) -> bool`` never blocks: a full mailbox drops the
  message, counts it and returns False (what ISRs use);
* ``await cast(name, msg) -> bool`` is fire-and-forget like OTP's cast: as
  ``send``, but a name that is not registered is not an error (returns False);
* ``await call(name, request, timeout=...)`` returns the actor's reply (the
  return value of its ``handle``), raises `CallTimeout`, `CallFailed` (the
  callee exited while holding or queueing the call, with its reason) or
  `NoProc` (no such name, or it went away while the call waited).

``send``, ``send_nowait`` and ``call`` to a name that is not registered raise
`NoProc` (an `UnknownActor`); ``cast`` returns False.

Names live as long as their actor is not gone for good. A send to an actor
that is restarting lands in its mailbox: mailboxes belong to the cell, which
outlives incarnations. A name stops being registered when its supervisor will
not start it again on its own: a temporary child that ended, a transient one
that ended normally, a child terminated or ignored, and every child of a
supervisor that stopped or gave up. Calls waiting in its mailbox then fail with
`NoProc`, and senders waiting for room raise `MailboxClosed`.

Two ways to unregister, for a bounded registry that still tells what died:
`retire` closes the cell but keeps it readable (``whereis``, ``names``,
``statistics``: its state, last exit and counters) while the supervisor keeps
the child's spec, a bounded set; `forget` removes it, for children whose spec
goes with them (temporary and dynamic ones, which come and go without bound).
A closed cell is not registered: every sender gets `NoProc`, and the next
start of the name makes a fresh cell.
"""

from __future__ import annotations

import hashlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any, Protocol

import numpy as np
import trio

from .call import CallEnvelope, CallTimeout, NoProc
from .cell import Cell, Monitor
from .clock import deadline_heap
from .exits import NOPROC
from .mailbox import Mailbox, MailboxClosed, MailboxStatistics
from .timers import TimerService
from .trace import EventKind, Trace

__all__ = ["ActorSystem", "open_actor_system", "SupervisorHandle", "StartFailed"]


class StartFailed(RuntimeError):
    """Raised by `ActorSystem.start_supervisor` when the tree could not start.

    Attributes:
        reason: the `ExitReason` of the failed start.
    """

    def __init__(self, name: str, reason: Any) -> None:
        super().__init__(f"supervisor {name or '<root>'!r} failed to start: {reason}")
        self.reason = reason


class SupervisorHandle(Protocol):
    """What `ActorSystem.start_supervisor` needs from a built supervisor."""

    name: str

    async def run(self, *, task_status: trio.TaskStatus[Any]) -> Any: ...

    def stop(self) -> None: ...

    async def wait_stopped(self) -> None: ...


class ActorSystem:
    """The registry and services of one run. Made by `open_actor_system`.

    Attributes:
        seed: the run's seed.
        rng: the run's generator (derive per-component ones with `rng_for`).
        trace: the run's trace hub.
        max_burst: the most messages an actor handles between two checkpoints.
    """

    def __init__(self, nursery: trio.Nursery, *, seed: int, trace: Trace, max_burst: int,
                 timer_service: bool = False) -> None:
        self._nursery = nursery
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.trace = trace
        self.max_burst = max_burst
        self._cells: dict[str, Cell] = {}
        self.timers: TimerService | None = TimerService() if timer_service else None
        """Posts every actor timer's ticks in one task (see `actors.timers`); None: a task
        per timer."""
        self.roots: list[Any] = []
        """Supervisors started with `start_supervisor`, in start order."""
        self._deadlines = deadline_heap()  # Trio's heap for call timeouts, None: a scope each

    # ---------------------------------------------------------------- registry
    def rng_for(self, name: str) -> np.random.Generator:
        """A generator for ``name`` derived from the seed alone (independent of scheduling)."""
        words = np.frombuffer(hashlib.blake2b(name.encode(), digest_size=16).digest(), np.uint32)
        return np.random.default_rng([self.seed, *(int(w) for w in words)])

    def ensure_cell(self, name: str, capacity: int) -> Cell:
        """The cell registered as ``name``, made with a mailbox of ``capacity`` if new
        (supervisor use: the supervisor owns its children's mailboxes)."""
        cell = self._cells.get(name)
        if cell is None or cell.mailbox._closed:  # new, or retired: a fresh cell
            if not isinstance(name, str) or not name:
                raise ValueError(f"name must be a non-empty string, got {name!r}")
            cell = Cell(name, Mailbox(name, capacity, self.trace), self.rng_for(name))
            self._cells[name] = cell
        return cell

    def forget(self, name: str) -> None:
        """Unregister ``name`` (its actor is gone for good; supervisor use): close its
        mailbox, fail the calls waiting in it with `NoProc`. Idempotent."""
        cell = self._cells.pop(name, None)
        if cell is not None:
            cell.mailbox.close()
            cell.fail_calls(NOPROC)

    def retire(self, name: str) -> None:
        """Unregister ``name`` but keep its closed cell readable (supervisor use, see the
        module): close its mailbox, fail the calls waiting in it with `NoProc`. Idempotent."""
        cell = self._cells.get(name)
        if cell is not None and not cell.mailbox._closed:
            cell.mailbox.close()
            cell.fail_calls(NOPROC)

    def whereis(self, name: str) -> Cell | None:
        """The cell of ``name``, or None; a retired one too (``cell.closed``: not
        registered, senders get `NoProc`), for post-mortems."""
        return self._cells.get(name)

    def names(self) -> list[str]:
        """Names with a cell (retired ones included), in registration order."""
        return list(self._cells)

    def _cell(self, name: str, *, live: bool = True) -> Cell:
        cell = self._cells.get(name)
        if cell is None or (live and cell.mailbox._closed):
            raise NoProc(name)
        return cell

    def statistics(self, name: str) -> MailboxStatistics:
        """Counters of ``name``'s mailbox.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
        """
        return self._cell(name, live=False).mailbox.statistics()

    # ---------------------------------------------------------------- messaging
    async def send(self, name: str, message: Any) -> None:
        """Put ``message`` in ``name``'s mailbox, waiting for room.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
            MailboxClosed: the actor was unregistered while waiting.
        """
        mailbox = self._cell(name).mailbox
        if len(mailbox._queue) < mailbox.capacity and not mailbox._closed:
            mailbox.send_nowait(message)  # room: no coroutine of the mailbox's to run
        else:
            await mailbox.send(message)

    def send_nowait(self, name: str, message: Any) -> bool:
        """Put ``message`` in ``name``'s mailbox if there is room; else drop, count, False.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
        """
        return self._cell(name).mailbox.send_nowait(message)

    async def cast(self, name: str, message: Any) -> bool:
        """Fire and forget: as `send`, but an unregistered name returns False, also when
        it is unregistered while waiting for room."""
        sent = self.cast_nowait(name, message)
        if sent is not None:
            return sent
        try:
            await self._cells[name].mailbox.send(message)
        except MailboxClosed:
            return False
        return True

    def cast_nowait(self, name: str, message: Any) -> bool | None:
        """`cast` as far as it needs no waiting: True when the message was queued, False
        when ``name`` is unregistered or its mailbox closed, None when the mailbox is full
        (nothing done; `cast` would wait for room).

        Why: a sender that bounds its wait with a timeout needs the timeout's cancel
        scope only when there is no room; entering and leaving one costs several times
        what queuing the message does.
        """
        cell = self._cells.get(name)
        if cell is None:
            return False
        mailbox = cell.mailbox
        if mailbox._closed:
            return False
        queue = mailbox._queue
        n = len(queue)
        if n >= mailbox.capacity:
            return None
        if self.trace.per_message:
            return mailbox.send_nowait(message)  # it traces the SEND event
        # Mailbox.send_nowait's success path inline. Why: cast is the hot path of
        # actor-to-actor traffic, and the call was a fifth of a cast's CPU.
        queue.append(message)
        mailbox._sent += 1
        if n >= mailbox._high:
            mailbox._high = n + 1
        if mailbox._receiver is not None:
            mailbox._wake()
        return True

    async def call(self, name: str, request: Any, *, timeout: float) -> Any:
        """Send ``request`` and wait for the reply (``handle``'s return value).

        The timeout [s] covers waiting for room and for the reply; a reply
        made after it never reaches the caller. The call is tied to the callee's
        life (`actors.call`): its exit fails the caller at once.

        Raises:
            NoProc: ``name`` is not registered, or was unregistered while the call waited.
            ValueError: ``timeout`` is not > 0.
            CallTimeout: no reply within ``timeout``.
            CallFailed: the actor exited while holding or queueing the request
                (``reason``: its exit reason).
        """
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 [s], got {timeout!r}")
        cell = self._cells.get(name)
        if cell is None or cell.mailbox._closed:
            raise NoProc(name)
        mailbox = cell.mailbox
        deadlines = self._deadlines
        if deadlines is not None and len(mailbox._queue) < mailbox.capacity \
                and not mailbox._closed:
            # the hot path: room in the mailbox, the timeout is an entry in Trio's heap
            envelope = CallEnvelope(request, name, timeout, deadlines)
            mailbox.send_nowait(envelope)
            return await envelope.wait(trio.current_time() + timeout)
        with trio.move_on_after(timeout):
            envelope = CallEnvelope(request, name, timeout)
            try:
                await mailbox.send(envelope)
            except MailboxClosed:
                raise NoProc(name) from None
            return await envelope.wait()
        raise CallTimeout(f"no reply from {name!r} within {timeout} s")

    def monitor(self, name: str, capacity: int = 16) -> Monitor:
        """Watch ``name``: the monitor receives a `Down` notice at every exit.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
        """
        cell = self._cell(name, live=False)
        monitor = Monitor(cell, capacity)
        cell.monitors.append(monitor)
        return monitor

    # ---------------------------------------------------------------- faults
    def inject_crash(self, name: str) -> None:
        """Make ``name`` crash: at its next message, or at once when idle.

        A crash injected while the actor is restarting hits its next incarnation.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
        """
        cell = self._cell(name, live=False)
        cell.crash_pending = True
        self.trace.emit(EventKind.FAULT, name, name, None, cell.mailbox.depth, "crash")
        cell.mailbox.poke()

    def inject_hang(self, name: str, seconds: float) -> None:
        """Make ``name`` block for ``seconds`` [s] at a checkpoint before its next handling
        (at once when idle); with a shorter watchdog deadline it is restarted as ``hung``.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
            ValueError: ``seconds`` is not > 0.
        """
        if not seconds > 0:
            raise ValueError(f"seconds must be > 0, got {seconds!r}")
        cell = self._cell(name, live=False)
        cell.hang_pending = float(seconds)
        self.trace.emit(EventKind.FAULT, name, name, None, cell.mailbox.depth, f"hang {seconds} s")
        cell.mailbox.poke()

    def flood(self, name: str, n: int, message: Any) -> int:
        """``send_nowait`` ``message`` to ``name`` ``n`` times; returns how many were accepted.

        Raises:
            NoProc: ``name`` is not registered (an `UnknownActor`).
            ValueError: ``n`` < 0.
        """
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n!r}")
        mailbox = self._cell(name, live=False).mailbox
        self.trace.emit(EventKind.FAULT, name, name, message, mailbox.depth, f"flood {n}")
        return sum(mailbox.send_nowait(message) for _ in range(n))

    # ---------------------------------------------------------------- trees
    async def start_supervisor(self, spec: Any, name: str = "") -> Any:
        """Build and start a supervision tree; returns when all its children started.

        Args:
            spec: anything with ``build(system, name)`` (``supervisors.SupervisorSpec``).
            name: the tree's name; its children register as ``name/child_id``
                (just ``child_id`` for the default empty name).

        Raises:
            StartFailed: a child failed to start (those already started were stopped).
        """
        handle = spec.build(self, name)
        failure = await self._nursery.start(handle.run)
        if failure is not None:
            raise StartFailed(name, failure)
        self.roots.append(handle)
        return handle

    async def aclose(self, timeout: float = 10.0) -> None:
        """Stop every tree (last started first), then cancel what is left after ``timeout`` [s]."""
        with trio.move_on_after(timeout):
            for root in reversed(self.roots):
                root.stop()
                await root.wait_stopped()
        self._nursery.cancel_scope.cancel()


@asynccontextmanager
async def open_actor_system(seed: int = 0, *, trace: Trace | None = None, max_burst: int = 256,
                            shutdown_timeout: float = 10.0,
                            timer_service: bool = False) -> AsyncIterator[ActorSystem]:
    """Open an actor system for the block; leaving it stops every tree cleanly.

    Args:
        seed: the run's seed (all randomness derives from it).
        trace: the trace hub (a new `Trace` by default).
        max_burst: the most messages handled between two checkpoints (>= 1).
        shutdown_timeout: [s] to stop the trees gracefully before cancelling.
        timer_service: post all actor timers from one task (`actors.timers`; faster
            when many timers tick together) instead of a task per timer.
    """
    if max_burst < 1:
        raise ValueError(f"max_burst must be >= 1, got {max_burst!r}")
    async with trio.open_nursery() as nursery:
        system = ActorSystem(nursery, seed=seed, trace=trace or Trace(), max_burst=max_burst,
                             timer_service=timer_service)
        if system.timers is not None:
            nursery.start_soon(system.timers.run)
        try:
            yield system
        finally:
            with trio.CancelScope(shield=True):
                await system.aclose(shutdown_timeout)
