"""Supervisor: Erlang/OTP ``supervisor`` semantics on Trio. This docstring is the contract.

A supervisor starts, watches and restarts an ordered list of children, each
described by a `ChildSpec`. Children are workers (an `actors.Actor` made by
``start()``) or supervisors (a `SupervisorSpec` returned by ``start()``).
Workers register as ``<supervisor name>/<child id>`` (or ``<child id>`` under
an unnamed root); the supervisor creates each worker's mailbox the first time
and keeps it across restarts, so messages sent meanwhile are not lost.

Start and stop
    Children start in spec order, each fully (its ``on_start`` done) before
    the next. A child that fails to start makes the supervisor stop the ones
    already started (reverse order) and fail its own start with the reason
    (``StartFailed`` for a root). Children stop in reverse start order.

Restart types (``ChildSpec.restart``)
    ``permanent``: always restarted. ``transient``: restarted only after an
    abnormal exit (anything but ``normal`` and ``shutdown``). ``temporary``:
    never restarted; forgotten (its name unregistered) when it exits.

Strategies (``SupervisorSpec.strategy``)
    ``one_for_one``: only the failed child is restarted. ``one_for_all``: the
    others are stopped (reverse order) and all are restarted in start order.
    ``rest_for_one``: the children started after the failed one are stopped
    (reverse order), then the failed one and those are restarted in order.
    A temporary child stopped this way is not restarted but forgotten.

Intensity (``intensity`` = MaxR, ``period`` = MaxT [s])
    Every restart decision is recorded; if more than MaxR happened within the
    last MaxT seconds, the supervisor stops all its children (reverse order)
    and exits with reason ``shutdown`` (detail ``reached max restart
    intensity``, OTP's ``{shutdown, reached_max_restart_intensity}``).
    MaxR = 0 gives up at the first failure; restarts spaced wider than MaxT
    never add up. The window is the pure function `intensity_exceeded`.

Escalation
    A supervisor's exit is seen by its parent as that child exiting, and is
    handled by the parent's strategy and the child's restart type.

Shutdown (``ChildSpec.shutdown`` [s], None = wait forever)
    Stopping a child asks it to stop (a worker finishes its current message,
    runs ``on_stop(shutdown)``; a supervisor stops its own children first) and
    waits up to the timeout; then the child is cancelled hard and its exit
    reason is ``killed``. Supervisor children default to waiting forever.

Backoff (``SupervisorSpec.backoff``, optional)
    Before restarting, wait ``min * 2**(k-1)`` seconds capped at ``max``, times
    ``1 + jitter * u`` with ``u`` uniform in [-1, 1) drawn from the run's seeded
    generator, ``k`` being the number of restarts since the supervisor was last
    quiet for ``reset_after`` seconds.

Introspection
    `Supervisor.which_children` lists (id, name, kind, state, restarts, last
    exit reason); `Supervisor.snapshot` gives the nested `TreeNode` records a
    console draws, with mailbox statistics for workers.

Child spec fields and defaults: ``id`` (required, unique among siblings, no
``/``), ``start`` (required, a zero-argument callable), ``restart=permanent``,
``shutdown=5.0`` for workers / None for supervisors, ``mailbox=64``,
``watchdog=None`` [s], ``type=worker``.
Supervisor options and defaults: ``strategy=one_for_one``, ``intensity=3``,
``period=5.0`` [s], ``backoff=None``.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import trio

from actors import (
    KILLED,
    MAX_INTENSITY,
    SHUTDOWN,
    ActorState,
    ActorSystem,
    Cell,
    EventKind,
    ExitReason,
    MailboxStatistics,
    run_actor,
)

__all__ = [
    "Restart",
    "Strategy",
    "ChildType",
    "ChildSpec",
    "Backoff",
    "SupervisorSpec",
    "Supervisor",
    "ChildInfo",
    "TreeNode",
    "intensity_exceeded",
    "backoff_delay",
    "ChildStartError",
]

# ============================================================================ data


class Restart(enum.StrEnum):
    """When a child is restarted."""

    PERMANENT = "permanent"
    TRANSIENT = "transient"
    TEMPORARY = "temporary"


class Strategy(enum.StrEnum):
    """Which children are restarted when one exits."""

    ONE_FOR_ONE = "one_for_one"
    ONE_FOR_ALL = "one_for_all"
    REST_FOR_ONE = "rest_for_one"


class ChildType(enum.StrEnum):
    """A child is an actor (worker) or a nested supervisor."""

    WORKER = "worker"
    SUPERVISOR = "supervisor"


def _enum(cls: type[enum.StrEnum], name: str, value: Any) -> Any:
    try:
        return cls(value)
    except ValueError:
        allowed = ", ".join(m.value for m in cls)
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}") from None


@dataclass(frozen=True, slots=True)
class ChildSpec:
    """How to start and supervise one child (see the module docstring for the rules).

    Raises:
        ValueError: a field out of its range (the message names it).
        TypeError: ``start`` is not callable.
    """

    id: str
    start: Callable[[], Any]  #: makes an Actor (worker) or a SupervisorSpec (supervisor)
    restart: Restart = Restart.PERMANENT
    shutdown: float | None = -1.0  #: [s]; None waits forever; -1 means the type's default
    mailbox: int = 64  #: mailbox depth [messages] (workers)
    watchdog: float | None = None  #: handling deadline per message [s] (workers)
    type: ChildType = ChildType.WORKER

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id or "/" in self.id:
            raise ValueError(f"id must be a non-empty string without '/', got {self.id!r}")
        if not callable(self.start):
            raise TypeError(f"start must be callable, got {self.start!r}")
        object.__setattr__(self, "restart", _enum(Restart, "restart", self.restart))
        object.__setattr__(self, "type", _enum(ChildType, "type", self.type))
        if self.shutdown == -1.0:
            default = 5.0 if self.type is ChildType.WORKER else None
            object.__setattr__(self, "shutdown", default)
        if self.shutdown is not None and not self.shutdown >= 0:
            raise ValueError(f"shutdown must be >= 0 [s] or None, got {self.shutdown!r}")
        if isinstance(self.mailbox, bool) or not isinstance(self.mailbox, int) or self.mailbox < 1:
            raise ValueError(f"mailbox must be an int >= 1, got {self.mailbox!r}")
        if self.watchdog is not None and not self.watchdog > 0:
            raise ValueError(f"watchdog must be > 0 [s] or None, got {self.watchdog!r}")


@dataclass(frozen=True, slots=True)
class Backoff:
    """Restart backoff: ``min``..``max`` [s], relative ``jitter``, reset after quiet [s]."""

    min: float = 0.01
    max: float = 1.0
    jitter: float = 0.1
    reset_after: float = 10.0

    def __post_init__(self) -> None:
        if not 0 <= self.min <= self.max:
            raise ValueError(
                f"backoff needs 0 <= min <= max, got min={self.min!r} max={self.max!r}")
        if not 0 <= self.jitter < 1:
            raise ValueError(f"jitter must be in [0, 1), got {self.jitter!r}")
        if not self.reset_after > 0:
            raise ValueError(f"reset_after must be > 0 [s], got {self.reset_after!r}")


@dataclass(frozen=True, slots=True)
class SupervisorSpec:
    """A supervisor's children (in start order) and options."""

    children: Sequence[ChildSpec]
    strategy: Strategy = Strategy.ONE_FOR_ONE
    intensity: int = 3  #: MaxR: restarts allowed within ``period``
    period: float = 5.0  #: MaxT [s]
    backoff: Backoff | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "children", tuple(self.children))
        object.__setattr__(self, "strategy", _enum(Strategy, "strategy", self.strategy))
        ids = [c.id for c in self.children]
        for c in self.children:
            if not isinstance(c, ChildSpec):
                raise TypeError(f"children must be ChildSpec, got {c!r}")
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"child ids must be unique, got duplicates {dup}")
        if isinstance(self.intensity, bool) or not isinstance(self.intensity, int) \
                or self.intensity < 0:
            raise ValueError(f"intensity must be an int >= 0, got {self.intensity!r}")
        if not self.period > 0:
            raise ValueError(f"period must be > 0 [s], got {self.period!r}")

    def build(self, system: ActorSystem, name: str) -> Supervisor:
        """A supervisor for this spec registered under ``name`` (runtime use)."""
        return Supervisor(self, system, name)


class ChildStartError(RuntimeError):
    """A child's ``start`` returned the wrong kind of object for its ``type``."""


@dataclass(frozen=True, slots=True)
class ChildInfo:
    """One row of `Supervisor.which_children`."""

    id: str
    name: str  #: registered name (workers) or the nested supervisor's name
    type: ChildType
    state: ActorState
    restarts: int
    last_exit: ExitReason | None


@dataclass(frozen=True, slots=True)
class TreeNode:
    """A supervision tree snapshot for a console (nested)."""

    name: str
    kind: ChildType
    state: ActorState
    restarts: int
    last_exit: ExitReason | None
    mailbox: MailboxStatistics | None = None  #: workers only
    children: tuple[TreeNode, ...] = ()


# ============================================================================ pure rules


def intensity_exceeded(restarts: Sequence[float], now: float, period: float,
                       max_restarts: int) -> tuple[bool, list[float]]:
    """Record a restart at ``now`` and say whether the intensity is exceeded.

    Args:
        restarts: times [s] of earlier restarts (any order).
        now: the time of this restart [s].
        period: MaxT [s]; restarts more than this long ago no longer count.
        max_restarts: MaxR.

    Returns:
        (exceeded, restart times still inside the window including ``now``).
    """
    window = [t for t in restarts if now - t <= period] + [now]  # inclusive, as OTP
    return len(window) > max_restarts, window


def backoff_delay(backoff: Backoff, consecutive: int, u: float) -> float:
    """The wait [s] before the ``consecutive``-th (1-based) restart; ``u`` in [-1, 1)."""
    base = min(backoff.max, backoff.min * 2.0 ** min(consecutive - 1, 60))
    return max(0.0, base * (1.0 + backoff.jitter * u))


def _should_restart(restart: Restart, reason: ExitReason) -> bool:
    """The restart decision, one case per restart type."""
    if restart is Restart.PERMANENT:
        return True
    if restart is Restart.TRANSIENT:
        return reason.abnormal
    return False  # temporary


# ============================================================================ state


class _Run:
    """One running incarnation of a child."""

    __slots__ = ("done", "reason", "stopping", "scope", "sup")

    def __init__(self) -> None:
        self.done = trio.Event()  # set when the incarnation's task ended
        self.reason: ExitReason | None = None  # its exit reason, once done
        self.stopping = False  # the supervisor asked it to stop: its exit is no failure
        self.scope: trio.CancelScope | None = None  # kill switch (supervisor children)
        self.sup: Supervisor | None = None  # the nested supervisor (supervisor children)


class _Child:
    """The supervisor's record of one child."""

    __slots__ = ("spec", "name", "run", "restarts", "last_exit", "cell", "sup", "restarting")

    def __init__(self, spec: ChildSpec, name: str) -> None:
        self.spec = spec
        self.name = name
        self.run: _Run | None = None  # None when not running
        self.restarts = 0
        self.last_exit: ExitReason | None = None
        self.cell: Cell | None = None  # workers: the registered cell (owns the mailbox)
        self.sup: Supervisor | None = None  # supervisors: the latest incarnation
        self.restarting = False  # between its exit and its restart (backoff included)

    @property
    def state(self) -> ActorState:
        if self.restarting:
            return ActorState.RESTARTING
        if self.run is not None and not self.run.done.is_set():
            if self.cell is not None:
                return self.cell.state
            return ActorState.RUNNING
        return ActorState.STOPPED


# ============================================================================ the supervisor


class Supervisor:
    """A running supervisor (made by `SupervisorSpec.build`; start it with
    ``ActorSystem.start_supervisor`` or as a child)."""

    def __init__(self, spec: SupervisorSpec, system: ActorSystem, name: str) -> None:
        self.spec = spec
        self.system = system
        self.name = name
        self._children: list[_Child] = [  # in start order; temporary ones removed on exit
            _Child(c, self._child_name(c.id)) for c in spec.children
        ]
        self._nursery: trio.Nursery | None = None
        self._wakeup = trio.Event()  # set when a child exits or a stop is requested
        self._stop_requested = False
        self._stop_event = trio.Event()  # set by stop(); ends a backoff wait early
        self._stopped = trio.Event()
        self._restart_times: list[float] = []  # inside the intensity window
        self._consecutive = 0  # restarts since the last quiet period (backoff)
        self._last_restart = -math.inf
        self._rng = system.rng_for(f"supervisor:{name}")
        self.exit_reason: ExitReason | None = None
        """Why it stopped, once stopped."""

    def _child_name(self, child_id: str) -> str:
        return f"{self.name}/{child_id}" if self.name else child_id

    # ------------------------------------------------------------------ public API
    def stop(self) -> None:
        """Ask the supervisor to stop its children (reverse order) and exit ``shutdown``."""
        self._stop_requested = True
        self._stop_event.set()
        self._wakeup.set()

    async def wait_stopped(self) -> None:
        """Wait until it has stopped."""
        await self._stopped.wait()

    def which_children(self) -> list[ChildInfo]:
        """Its children in start order: id, name, type, state, restarts, last exit."""
        return [ChildInfo(c.spec.id, c.name, c.spec.type, c.state, c.restarts, c.last_exit)
                for c in self._children]

    def snapshot(self) -> TreeNode:
        """The whole tree below this supervisor, for a console."""
        nodes = []
        for c in self._children:
            sub = c.sup.snapshot().children if c.sup is not None else ()
            stats = c.cell.mailbox.statistics() if c.cell is not None else None
            nodes.append(TreeNode(c.name, c.spec.type, c.state, c.restarts, c.last_exit,
                                  stats, sub))
        state = ActorState.STOPPED if self._stopped.is_set() else ActorState.RUNNING
        return TreeNode(self.name, ChildType.SUPERVISOR, state, 0, self.exit_reason, None,
                        tuple(nodes))

    # ------------------------------------------------------------------ start
    async def run(self, *, task_status: trio.TaskStatus[ExitReason | None]
                  = trio.TASK_STATUS_IGNORED) -> ExitReason:
        """Start the children, supervise them until stopped or giving up.

        Reports ``task_status.started(None)`` when every child started, or
        ``started(reason)`` after a failed start (the started ones stopped).

        Returns:
            ``shutdown`` when stopped, `MAX_INTENSITY` when it gave up, or the
            start failure.
        """
        trace = self.system.trace
        reason: ExitReason = SHUTDOWN
        reported = False
        try:
            async with trio.open_nursery() as nursery:
                self._nursery = nursery
                failure = await self._start_children(list(self._children))
                if failure is not None:
                    reason = failure
                    await self._stop_children(list(self._children))
                    return reason
                trace.emit(EventKind.START, self.name or "<root>", detail="supervisor")
                reported = True
                task_status.started(None)
                reason = await self._supervise()
                await self._stop_children(list(self._children))
                nursery.cancel_scope.cancel()
            return reason
        finally:
            self.exit_reason = reason
            if not reported:
                task_status.started(reason)
            trace.emit(EventKind.STOP, self.name or "<root>", detail=str(reason))
            self._stopped.set()

    async def _start_children(self, children: list[_Child]) -> ExitReason | None:
        """Start ``children`` in order; on a failure return its reason (others stay up)."""
        for child in children:
            failure = await self._start_child(child)
            if failure is not None:
                self.system.trace.emit(EventKind.STOP, child.name, detail=f"start: {failure}")
                return failure
        return None

    async def _start_child(self, child: _Child) -> ExitReason | None:
        assert self._nursery is not None
        run = _Run()
        spec = child.spec
        if spec.type is ChildType.WORKER:
            cell = self.system.ensure_cell(child.name, spec.mailbox)
            cell.watchdog = spec.watchdog
            cell.supervisor = self.name
            child.cell = cell
            failure = await self._nursery.start(self._worker_task, child, run)
        else:
            failure = await self._nursery.start(self._supervisor_task, child, run)
        if failure is None:
            child.run = run
        else:
            child.last_exit = failure
        return failure

    async def _worker_task(self, child: _Child, run: _Run, *,
                           task_status: trio.TaskStatus[ExitReason | None]) -> None:
        assert child.cell is not None
        try:
            run.reason = await run_actor(self.system, child.cell, child.spec.start,
                                         task_status=task_status)
        finally:
            run.done.set()
            self._wakeup.set()

    async def _supervisor_task(self, child: _Child, run: _Run, *,
                               task_status: trio.TaskStatus[ExitReason | None]) -> None:
        started = False
        try:
            with trio.CancelScope() as scope:
                run.scope = scope
                try:
                    spec = child.spec.start()
                    if not isinstance(spec, SupervisorSpec):
                        raise ChildStartError(
                            f"start of supervisor child {child.spec.id!r} must return a "
                            f"SupervisorSpec, got {spec!r}")
                except Exception as exc:
                    run.reason = ExitReason.start_failed(f"{type(exc).__name__}: {exc}")
                    return
                sup = Supervisor(spec, self.system, child.name)
                run.sup = child.sup = sup

                def started_cb(value: ExitReason | None = None) -> None:
                    nonlocal started
                    started = True
                    task_status.started(value)

                run.reason = await sup.run(task_status=_Relay(started_cb))
            if scope.cancelled_caught:
                run.reason = KILLED
        finally:
            if not started:
                task_status.started(run.reason or KILLED)
            run.done.set()
            self._wakeup.set()

    # ------------------------------------------------------------------ supervise and restart
    async def _supervise(self) -> ExitReason:
        """Wait for exits and apply the strategy; returns when stopped or giving up."""
        while True:
            await self._wakeup.wait()
            self._wakeup = trio.Event()
            if self._stop_requested:
                return SHUTDOWN
            for child in list(self._children):
                run = child.run
                if run is None or not run.done.is_set() or run.stopping:
                    continue
                child.run = None
                reason = run.reason or KILLED
                child.last_exit = reason
                if not await self._handle_exit(child, reason):
                    return MAX_INTENSITY
                if self._stop_requested:
                    return SHUTDOWN

    async def _handle_exit(self, child: _Child, reason: ExitReason) -> bool:
        """Apply restart type and strategy to one exit; False when intensity is exceeded."""
        trace = self.system.trace
        if not _should_restart(child.spec.restart, reason):
            if child.spec.restart is Restart.TEMPORARY:
                self._forget(child)
            return True
        now = trio.current_time()
        exceeded, self._restart_times = intensity_exceeded(
            self._restart_times, now, self.spec.period, self.spec.intensity)
        if exceeded:
            trace.emit(EventKind.ESCALATE, self.name or "<root>", detail=(
                f"{len(self._restart_times)} restarts in {self.spec.period} s "
                f"> intensity {self.spec.intensity}; last: {child.name} {reason}"))
            return False
        affected = self._affected(child)
        # stop the running ones among them, reverse start order
        await self._stop_children([c for c in affected if c is not child])
        for c in affected:
            if c is not child and c.spec.restart is Restart.TEMPORARY:
                self._forget(c)
        to_start = [c for c in affected if c in self._children]
        for c in to_start:
            c.restarting = True
            if c.cell is not None:
                c.cell.state = ActorState.RESTARTING
        await self._backoff(now)
        if self._stop_requested:  # stopped during the backoff: nothing to restart
            for c in to_start:
                c.restarting = False
            return True
        for c in to_start:
            c.restarting = False
            c.restarts += 1
            trace.emit(EventKind.RESTART, c.name, c.name, None,
                       c.cell.mailbox.depth if c.cell is not None else 0,
                       f"after {reason} of {child.name}" if c is not child else str(reason))
            failure = await self._start_child(c)
            if failure is not None:
                # a failed restart counts as another exit (bounded by the intensity)
                run = _Run()
                run.reason = failure
                run.done.set()
                c.run = run
                self._wakeup.set()
                for rest in to_start[to_start.index(c) + 1:]:
                    rest.restarting = False
                break
        return True

    def _affected(self, child: _Child) -> list[_Child]:
        """The children to restart for ``child``'s exit, one case per strategy."""
        strategy = self.spec.strategy
        if strategy is Strategy.ONE_FOR_ONE:
            return [child]
        if strategy is Strategy.ONE_FOR_ALL:
            return list(self._children)
        index = self._children.index(child)  # rest_for_one
        return self._children[index:]

    async def _backoff(self, now: float) -> None:
        backoff = self.spec.backoff
        if backoff is None:
            return
        if now - self._last_restart >= backoff.reset_after:
            self._consecutive = 0
        self._consecutive += 1
        self._last_restart = now
        delay = backoff_delay(backoff, self._consecutive, float(self._rng.uniform(-1.0, 1.0)))
        if delay > 0:
            with trio.move_on_after(delay):
                await self._stop_event.wait()

    def _forget(self, child: _Child) -> None:
        if child in self._children:
            self._children.remove(child)
        if child.cell is not None:
            self.system.forget(child.name)

    # ------------------------------------------------------------------ shutdown
    async def _stop_children(self, children: list[_Child]) -> None:
        """Stop the running ones of ``children`` in reverse order, each within its timeout."""
        for child in reversed(children):
            run = child.run
            if run is None:
                continue
            run.stopping = True
            if not run.done.is_set():
                await self._stop_one(child, run)
            child.run = None
            child.last_exit = run.reason or KILLED

    async def _stop_one(self, child: _Child, run: _Run) -> None:
        timeout = child.spec.shutdown
        if child.cell is not None and child.spec.type is ChildType.WORKER:
            child.cell.stop_requested = True
            child.cell.mailbox.poke()
        elif run.sup is not None:
            run.sup.stop()
        with trio.move_on_after(math.inf if timeout is None else timeout):
            await run.done.wait()
        if not run.done.is_set():
            scope = child.cell.scope if child.cell is not None else run.scope
            if scope is not None:
                scope.cancel()
            await run.done.wait()
            self.system.trace.emit(EventKind.KILLED, child.name,
                                   detail=f"missed shutdown timeout {timeout} s")


class _Relay:
    """Passes a nested supervisor's ``started`` to the parent's task status."""

    def __init__(self, callback: Callable[[Any], None]) -> None:
        self._callback = callback

    def started(self, value: Any = None) -> None:
        self._callback(value)

