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
    ``IGNORE`` returned by a child's ``start``, its spec's ``init`` hook or the
    actor's ``on_start`` (OTP's ``ignore``) is no failure: the child is kept
    (a temporary one is dropped) but not running, and its name unregistered.

Restart types (``ChildSpec.restart``)
    ``permanent``: always restarted. ``transient``: restarted only after an
    abnormal exit (anything but ``normal`` and ``shutdown``). ``temporary``:
    never restarted; forgotten (its name unregistered) when it exits.
    The exit may be the actor's own choice: ``ctx.stop()`` (``normal``),
    ``ctx.stop("shutdown")`` or ``ctx.stop("shutdown", term)`` (OTP's
    ``{shutdown, Term}``); the rules are the same.

Strategies (``SupervisorSpec.strategy``)
    ``one_for_one``: only the failed child is restarted. ``one_for_all``: the
    others are stopped (reverse order) and all are restarted in start order.
    ``rest_for_one``: the children started after the failed one are stopped
    (reverse order), then the failed one and those are restarted in order.
    A temporary child stopped this way is not restarted but forgotten. As in
    OTP, a non-temporary child that was not running is started with the others.

Intensity (``intensity`` = MaxR, ``period`` = MaxT [s])
    Every restart decision is recorded; if more than MaxR happened within the
    last MaxT seconds, the supervisor stops all its children (reverse order)
    and exits with reason ``shutdown`` (detail ``reached max restart
    intensity``, OTP's ``{shutdown, reached_max_restart_intensity}``).
    MaxR = 0 gives up at the first failure; restarts spaced wider than MaxT
    never add up. The window is the pure function `intensity_exceeded`.
    A restart whose start fails counts as another exit of that child.

Escalation
    A supervisor's exit is seen by its parent as that child exiting, and is
    handled by the parent's strategy and the child's restart type.

Auto-shutdown (``SupervisorSpec.auto_shutdown``, ``ChildSpec.significant``; OTP 24)
    ``never`` (default; significant children are refused), ``any_significant``:
    the supervisor stops its other children and exits ``shutdown`` (detail
    ``auto shutdown``) when a significant child ends by itself and is not
    restarted; ``all_significant``: when the last running significant child
    does. A significant child is transient or temporary, never permanent.
    Ending by the supervisor's hand (``terminate_child``, a sibling's
    restart, the supervisor's stop) never triggers it.

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

Names and calls
    A worker's name and mailbox live across its restarts. Every exit of an
    incarnation fails the calls it held or that wait in its mailbox, with its
    exit reason (`actors.CallFailed`), in the same scheduler pass. The name is
    unregistered when the supervisor will not start the child again on its
    own: a temporary child ended, a transient one ended normally, a child was
    terminated, deleted or ignored, or the supervisor itself stopped or gave up
    (then every one of its workers). From then on ``call``, ``send`` and
    ``send_nowait`` raise `actors.NoProc` and ``cast`` returns False. The closed
    cell stays readable (``whereis``, ``names``, ``statistics``) while the
    supervisor keeps the child's spec; a dropped spec (temporary, dynamic)
    takes the name out of the registry (`actors.ActorSystem.retire`, ``forget``).

Dynamic children (serialised with restarts: one runs at a time)
    ``await start_child(spec)`` adds a child at the end and starts it (its name,
    or None when ignored; a failed start adds nothing); ``await
    terminate_child(id)`` stops it and keeps its spec (a temporary one is
    dropped); ``await restart_child(id)`` starts a kept child that is not
    running; ``await delete_child(id)`` drops the spec of a child that is not
    running; ``count_children()`` counts specs, running children, supervisors
    and workers. Errors raise `ChildError` with OTP's reason (``already_started``,
    ``already_present``, ``not_found``, ``running``, ``restarting``, a start
    failure). `supervisors.dynamic.DynamicSupervisor` runs many children of one
    spec started on demand, bounded by ``max_children``.

Introspection
    `Supervisor.which_children` lists (id, name, kind, state, restarts, last
    exit reason); a child's state is ``restarting`` from its exit until its
    restart's ``on_start`` returned (backoff included). `Supervisor.snapshot`
    gives the nested `TreeNode` records a console draws, with mailbox
    statistics for workers.

Child spec fields and defaults: ``id`` (required, unique among siblings, no
``/``), ``start`` (required, a zero-argument callable), ``restart=permanent``,
``shutdown=5.0`` for workers / None for supervisors, ``mailbox=64``,
``watchdog=None`` [s], ``type=worker``, ``significant=False``, ``init=None``
(per-incarnation hook ``init(actor)`` before ``on_start``).
Supervisor options and defaults: ``strategy=one_for_one``, ``intensity=3``,
``period=5.0`` [s], ``backoff=None``, ``auto_shutdown=never``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

import trio

from actors import (
    AUTO_SHUTDOWN,
    IGNORE,
    KILLED,
    MAX_INTENSITY,
    SHUTDOWN,
    ActorState,
    ActorSystem,
    EventKind,
    ExitKind,
    ExitReason,
    Ignore,
    run_actor,
)

from .spec import (
    AutoShutdown,
    Backoff,
    ChildCounts,
    ChildError,
    ChildInfo,
    ChildSpec,
    ChildStartError,
    ChildType,
    Restart,
    Strategy,
    SupervisorSpec,
    TreeNode,
    backoff_delay,
    check_significant,
    intensity_exceeded,
    should_restart,
)
from .state import ChildRecord, Run, Serial, Started

__all__ = [
    "AutoShutdown", "Backoff", "ChildCounts", "ChildError", "ChildInfo", "ChildSpec",
    "ChildStartError", "ChildType", "Restart", "Strategy", "Supervisor", "SupervisorSpec",
    "TreeNode", "backoff_delay", "intensity_exceeded",
]


# ============================================================================ the supervisor


class Supervisor:
    """A running supervisor (made by `SupervisorSpec.build`; start it with
    ``ActorSystem.start_supervisor`` or as a child)."""

    _keeps_ended = True  # a child that ended and is not restarted keeps its spec

    def __init__(self, spec: Any, system: ActorSystem, name: str) -> None:
        self.spec = spec
        self.system = system
        self.name = name
        # by id, in start order; a child whose spec goes (temporary, dynamic) is removed
        self._children: dict[str, ChildRecord] = {
            c.id: ChildRecord(c, self._child_name(c.id)) for c in spec.children}
        self._exited: deque[Run] = deque()  # runs that ended, not yet handled
        self._nursery: trio.Nursery | None = None
        self._open = False  # accepting dynamic-children calls (between start and stop)
        self._serial = Serial()
        self._wakeup = trio.Event()  # set when a child exits or a stop is requested
        self._stop_requested = False
        self._stop_event = trio.Event()  # set by stop(); ends a backoff wait early
        self._stopped = trio.Event()
        self._restart_times: deque[float] = deque()  # inside the intensity window, in order
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
                for c in self._children.values()]

    def count_children(self) -> ChildCounts:
        """Specs known, children running, supervisors and workers (OTP's count_children)."""
        children = self._children.values()
        sups = sum(c.spec.type is ChildType.SUPERVISOR for c in children)
        active = sum(c.run is not None and not c.run.done.is_set() for c in children)
        return ChildCounts(len(self._children), active, sups, len(self._children) - sups)

    def snapshot(self) -> TreeNode:
        """The whole tree below this supervisor, for a console."""
        nodes = []
        for c in self._children.values():
            sub = c.sup.snapshot().children if c.sup is not None else ()
            stats = c.cell.mailbox.statistics() if c.cell is not None else None
            nodes.append(TreeNode(c.name, c.spec.type, c.state, c.restarts, c.last_exit,
                                  stats, sub))
        state = ActorState.STOPPED if self._stopped.is_set() else ActorState.RUNNING
        return TreeNode(self.name, ChildType.SUPERVISOR, state, 0, self.exit_reason, None,
                        tuple(nodes))

    async def start_child(self, spec: ChildSpec) -> str | None:
        """Add ``spec`` as the last child and start it (OTP's ``start_child``).

        Returns:
            The child's registered name, or None when its start returned `IGNORE`.

        Raises:
            ChildError: ``already_started`` / ``already_present`` (the id is taken,
                running or not), ``stopped`` (the supervisor is not running), or the
                start failure's `ExitReason` (nothing is added).
            ValueError: a significant child under ``auto_shutdown=never``.
        """
        if not isinstance(spec, ChildSpec):
            raise TypeError(f"spec must be a ChildSpec, got {spec!r}")
        check_significant([spec], self.spec.auto_shutdown)
        async with self._serial:
            self._check_open(spec.id)
            self._admit(spec)
            return await self._add(spec)

    async def terminate_child(self, child_id: str) -> None:
        """Stop a child (within its shutdown timeout); its spec is kept unless temporary.

        Not a failure: no restart, no intensity, no auto-shutdown.

        Raises:
            ChildError: ``not_found``, or ``stopped``.
        """
        async with self._serial:
            self._check_open(child_id)
            child = self._find(child_id)
            await self._stop_children([child])
            child.restarting = False
            self._ended(child)

    async def restart_child(self, child_id: str) -> str | None:
        """Start a kept child that is not running (OTP's ``restart_child``).

        Returns:
            Its registered name, or None when its start returned `IGNORE`.

        Raises:
            ChildError: ``not_found``, ``running``, ``restarting``, ``stopped``, or the
                start failure's `ExitReason` (the spec is kept).
        """
        async with self._serial:
            self._check_open(child_id)
            child = self._find_idle(child_id)
            started = await self._start_child(child)
            if started is IGNORE:
                self._ended(child)
                return None
            if started is not None:
                self._forget_name(child)
                raise ChildError(self.name, started, child_id)
            return child.name

    async def delete_child(self, child_id: str) -> None:
        """Drop the spec of a child that is not running (OTP's ``delete_child``).

        Raises:
            ChildError: ``not_found``, ``running``, ``restarting``, or ``stopped``.
        """
        async with self._serial:
            self._check_open(child_id)
            self._remove(self._find_idle(child_id))

    def _check_open(self, child_id: str) -> None:
        if not self._open:
            raise ChildError(self.name, "stopped", child_id)

    def _admit(self, spec: ChildSpec) -> None:
        """Refuse a new child whose id is taken."""
        existing = self._children.get(spec.id)
        if existing is not None:
            running = existing.run is not None or existing.restarting
            raise ChildError(self.name, "already_started" if running else "already_present",
                             spec.id)

    async def _add(self, spec: ChildSpec) -> str | None:
        child = ChildRecord(spec, self._child_name(spec.id))
        self._children[spec.id] = child
        started = await self._start_child(child)
        if started is IGNORE:
            self._ended(child)
            return None
        if started is not None:
            self._remove(child)
            raise ChildError(self.name, started, spec.id)
        return child.name

    def _find(self, child_id: str) -> ChildRecord:
        child = self._children.get(child_id)
        if child is None:
            raise ChildError(self.name, "not_found", child_id)
        return child

    def _find_idle(self, child_id: str) -> ChildRecord:
        child = self._find(child_id)
        if child.restarting:
            raise ChildError(self.name, "restarting", child_id)
        if child.run is not None:
            raise ChildError(self.name, "running", child_id)
        return child

    # ------------------------------------------------------------------ start
    async def run(self, *, task_status: trio.TaskStatus[Started]
                  = trio.TASK_STATUS_IGNORED) -> ExitReason:
        """Start the children, supervise them until stopped, giving up or auto-shutdown.

        Reports ``task_status.started(None)`` when every child started, or
        ``started(reason)`` after a failed start (the started ones stopped).

        Returns:
            ``shutdown`` when stopped, `MAX_INTENSITY` when it gave up,
            ``AUTO_SHUTDOWN`` after its significant children ended, or the start failure.
        """
        trace = self.system.trace
        reason: ExitReason = SHUTDOWN
        reported = False
        try:
            async with trio.open_nursery() as nursery:
                self._nursery = nursery
                failure = await self._start_children(list(self._children.values()))
                if failure is not None:
                    reason = failure
                    await self._stop_children(list(self._children.values()))
                    return reason
                trace.emit(EventKind.START, self.name or "<root>", detail="supervisor")
                reported = True
                self._open = True
                task_status.started(None)
                reason = await self._supervise()
                async with self._serial:
                    self._open = False
                    await self._stop_children(list(self._children.values()))
                nursery.cancel_scope.cancel()
            return reason
        finally:
            self._open = False
            self.exit_reason = reason
            for child in self._children.values():  # gone with this incarnation, for good
                self._forget_name(child, keep=self._keeps_ended)
            if not reported:
                task_status.started(reason)
            trace.emit(EventKind.STOP, self.name or "<root>", detail=str(reason))
            self._stopped.set()

    async def _start_children(self, children: list[ChildRecord]) -> ExitReason | None:
        """Start ``children`` in order; on a failure return its reason (others stay up)."""
        for child in children:
            started = await self._start_child(child)
            if started is IGNORE:
                self._ended(child)
            elif started is not None:
                self.system.trace.emit(EventKind.STOP, child.name, detail=f"start: {started}")
                return started
        return None

    async def _start_child(self, child: ChildRecord) -> Started:
        assert self._nursery is not None
        run = Run(child)
        spec = child.spec
        if spec.type is ChildType.WORKER:
            cell = self.system.ensure_cell(child.name, spec.mailbox)
            cell.watchdog = spec.watchdog
            cell.supervisor = self.name
            child.cell = cell
            started = await self._nursery.start(self._worker_task, run)
        else:
            started = await self._nursery.start(self._supervisor_task, run)
        if started is None:
            child.run = run
        elif started is not IGNORE:
            child.last_exit = started
        return started

    async def _worker_task(self, run: Run, *, task_status: trio.TaskStatus[Started]) -> None:
        """Run a worker's incarnations: the first, then those restarted in place."""
        child = run.child
        status: Any = task_status
        try:
            while True:
                assert child.cell is not None
                reason = await run_actor(self.system, child.cell, child.spec.start,
                                         init=child.spec.init, task_status=status)
                run.reason = reason
                if not self._restart_in_place(run, reason):
                    return
                status = _InPlace(self, child)
        finally:
            self._ended_run(run)

    def _restart_in_place(self, run: Run, reason: ExitReason | Ignore) -> bool:
        """Decide a worker's restart in its own task, when nothing else is involved.

        Why: a restart through the supervisor's task costs a task switch, a nursery
        ``start`` and a new task; for the common case (``one_for_one``, no backoff,
        a restart within the intensity, the supervisor idle) the decision and its
        record are the same as `_handle_exit`'s, so the exited task starts the next
        incarnation itself. The supervisor's serial lock is held until that start
        returned, as for a restart made by the supervisor. Anything else (a stop in
        progress, another strategy, backoff, the intensity reached, a start that
        failed) takes the supervisor's path, which decides it again from scratch.

        Returns:
            True when the caller is to run the next incarnation now.
        """
        child = run.child
        if (child.run is not run or run.stopping or not self._open or self._stop_requested
                or type(reason) is not ExitReason or reason.kind is ExitKind.START_FAILED
                or self.spec.strategy is not Strategy.ONE_FOR_ONE
                or self.spec.backoff is not None
                or not should_restart(child.spec.restart, reason)):
            return False
        now = trio.current_time()
        times = self._restart_times
        while times and now - times[0] > self.spec.period:
            times.popleft()
        if len(times) + 1 > self.spec.intensity or not self._serial.try_acquire():
            return False
        times.append(now)
        child.last_exit = reason
        child.restarting = True
        child.restarts += 1
        cell = child.cell
        assert cell is not None
        cell.state = ActorState.RESTARTING
        self.system.trace.emit(EventKind.RESTART, child.name, child.name, None,
                               cell.mailbox.depth, str(reason))
        return True

    def _ended_run(self, run: Run) -> None:
        run.done.set()
        self._exited.append(run)
        self._wakeup.set()

    async def _supervisor_task(self, run: Run, *,
                               task_status: trio.TaskStatus[Started]) -> None:
        child = run.child
        started = False
        try:
            with trio.CancelScope() as scope:
                run.scope = scope
                try:
                    spec = child.spec.start()
                    if spec is IGNORE:
                        run.reason = IGNORE
                        return
                    if not hasattr(spec, "build") or not hasattr(spec, "children"):
                        raise ChildStartError(
                            f"start of supervisor child {child.spec.id!r} must return a "
                            f"SupervisorSpec, got {spec!r}")
                except Exception as exc:
                    run.reason = ExitReason.start_failed(f"{type(exc).__name__}: {exc}")
                    return
                sup = spec.build(self.system, child.name)
                run.sup = child.sup = sup

                def started_cb(value: Started = None) -> None:
                    nonlocal started
                    started = True
                    task_status.started(value)

                run.reason = await sup.run(task_status=_Relay(started_cb))
            if scope.cancelled_caught:
                run.reason = KILLED
        finally:
            if not started:
                task_status.started(run.reason or KILLED)
            self._ended_run(run)

    # ------------------------------------------------------------------ supervise and restart
    async def _supervise(self) -> ExitReason:
        """Wait for exits and apply the strategy; returns when stopped or ending."""
        while True:
            await self._wakeup.wait()
            self._wakeup = trio.Event()
            if self._stop_requested:
                return SHUTDOWN
            async with self._serial:
                while self._exited:
                    ended = self._take_exits()
                    for run in ended:
                        child = run.child
                        if child.run is not run or run.stopping:
                            continue  # stopped by this supervisor, or a start that failed
                        child.run = None
                        reason = run.reason if isinstance(run.reason, ExitReason) else KILLED
                        child.last_exit = reason
                        verdict = await self._handle_exit(child, reason)
                        if verdict is not None:
                            return verdict
                        if self._stop_requested:
                            return SHUTDOWN

    def _take_exits(self) -> list[Run]:
        """The runs ended so far, in their children's start order (as a scan would)."""
        ended = list(self._exited)
        self._exited.clear()
        if len(ended) > 1:
            order = {c: i for i, c in enumerate(self._children.values())}
            ended.sort(key=lambda r: order.get(r.child, -1))
        return ended

    async def _handle_exit(self, child: ChildRecord, reason: ExitReason) -> ExitReason | None:
        """Apply restart type and strategy to one exit.

        Returns:
            None to go on, or the supervisor's own exit reason (intensity exceeded,
            auto-shutdown).
        """
        trace = self.system.trace
        if not should_restart(child.spec.restart, reason):
            self._ended(child)
            if child.spec.significant and self._auto_shutdown_due():
                trace.emit(EventKind.STOP, self.name or "<root>",
                           detail=f"auto shutdown: {child.name} {reason}")
                return AUTO_SHUTDOWN
            return None
        now = trio.current_time()
        exceeded, window = intensity_exceeded(
            self._restart_times, now, self.spec.period, self.spec.intensity)
        self._restart_times = deque(window)
        if exceeded:
            trace.emit(EventKind.ESCALATE, self.name or "<root>", detail=(
                f"{len(self._restart_times)} restarts in {self.spec.period} s "
                f"> intensity {self.spec.intensity}; last: {child.name} {reason}"))
            return MAX_INTENSITY
        affected = self._affected(child)
        for c in affected:
            c.restarting = c is child or c.spec.restart is not Restart.TEMPORARY
        # stop the running ones among them, reverse start order
        await self._stop_children([c for c in affected if c is not child])
        for c in affected:
            if c is not child and c.spec.restart is Restart.TEMPORARY:
                self._remove(c)
        to_start = [c for c in affected if c.restarting]
        for c in to_start:
            if c.cell is not None:
                c.cell.state = ActorState.RESTARTING
        await self._backoff(now)
        if self._stop_requested:  # stopped during the backoff: nothing to restart
            for c in to_start:
                c.restarting = False
            return None
        for i, c in enumerate(to_start):
            c.restarts += 1
            trace.emit(EventKind.RESTART, c.name, c.name, None,
                       c.cell.mailbox.depth if c.cell is not None else 0,
                       f"after {reason} of {child.name}" if c is not child else str(reason))
            started = await self._start_child(c)
            c.restarting = False
            if started is IGNORE:
                self._ended(c)
            elif started is not None:
                # a failed restart counts as another exit (bounded by the intensity)
                run = Run(c)
                run.reason = started
                c.run = run
                self._ended_run(run)
                for rest in to_start[i + 1:]:
                    rest.restarting = False
                break
        return None

    def _affected(self, child: ChildRecord) -> list[ChildRecord]:
        """The children to restart for ``child``'s exit, one case per strategy."""
        strategy = self.spec.strategy
        if strategy is Strategy.ONE_FOR_ONE:
            return [child]
        children = list(self._children.values())
        if strategy is Strategy.ONE_FOR_ALL:
            return children
        return children[children.index(child):]  # rest_for_one

    def _auto_shutdown_due(self) -> bool:
        """A significant child just ended by itself: does the supervisor end too?"""
        mode = self.spec.auto_shutdown
        if mode is AutoShutdown.ANY_SIGNIFICANT:
            return True
        if mode is AutoShutdown.ALL_SIGNIFICANT:
            return not any(c.spec.significant and (c.run is not None or c.restarting)
                           for c in self._children.values())
        return False

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

    def _ended(self, child: ChildRecord) -> None:
        """A child ended and will not be restarted: drop a temporary one (every one in a
        dynamic supervisor), unregister its name."""
        if child.spec.restart is Restart.TEMPORARY or not self._keeps_ended:
            self._remove(child)
        else:
            self._forget_name(child)

    def _remove(self, child: ChildRecord) -> None:
        if self._children.get(child.spec.id) is child:
            del self._children[child.spec.id]
        self._forget_name(child, keep=False)

    def _forget_name(self, child: ChildRecord, *, keep: bool = True) -> None:
        """Unregister a worker's name: retired (readable) while its spec is kept,
        forgotten with its spec (see `actors.system`)."""
        if child.cell is not None and self.system.whereis(child.name) is child.cell:
            if keep:
                self.system.retire(child.name)
            else:
                self.system.forget(child.name)

    # ------------------------------------------------------------------ shutdown
    async def _stop_children(self, children: list[ChildRecord]) -> None:
        """Stop the running ones of ``children`` in reverse order, each within its timeout."""
        for child in reversed(children):
            run = child.run
            if run is None:
                continue
            run.stopping = True
            if not run.done.is_set():
                await self._stop_one(child, run)
            child.run = None
            child.last_exit = run.reason if isinstance(run.reason, ExitReason) else KILLED

    async def _stop_one(self, child: ChildRecord, run: Run) -> None:
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


class _InPlace:
    """The task status of an incarnation started in place (see
    `Supervisor._restart_in_place`): ends the restart when its start returned."""

    __slots__ = ("_sup", "_child")

    def __init__(self, sup: Supervisor, child: ChildRecord) -> None:
        self._sup = sup
        self._child = child

    def started(self, value: Started = None) -> None:
        child = self._child
        child.restarting = False
        if value is IGNORE:
            child.run = None
            self._sup._ended(child)  # noqa: SLF001 - the supervisor's own helper
        elif value is not None:
            child.last_exit = value
        self._sup._serial.release()  # noqa: SLF001


class _Relay:
    """Passes a nested supervisor's ``started`` to the parent's task status."""

    def __init__(self, callback: Callable[[Any], None]) -> None:
        self._callback = callback

    def started(self, value: Any = None) -> None:
        self._callback(value)
