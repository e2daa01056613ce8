"""Starting and stopping a supervisor's children (see `supervisors.supervisor`).

`ChildLifecycle` holds a supervisor's state and starts each child in its own
task: a worker's task runs its incarnations (`actors.run_actor`), the first
and those restarted in place; a supervisor child's task builds and runs the
nested supervisor. Each incarnation's end is queued for the restart logic
(`supervisors.restart`). Stopping is two-step: ask, wait the child's shutdown
timeout, then cancel hard (exit reason ``killed``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

import trio

from actors import IGNORE, KILLED, ActorSystem, EventKind, ExitReason, Ignore, run_actor

from .spec import ChildStartError, ChildType, Restart
from .state import ChildRecord, Run, Serial, Started

__all__ = ["ChildLifecycle"]


class ChildLifecycle:
    """A supervisor's state, and the start and stop of its children."""

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
        self.exit_reason: ExitReason | None = None
        """Why it stopped, once stopped."""

    def _child_name(self, child_id: str) -> str:
        return f"{self.name}/{child_id}" if self.name else child_id

    # ------------------------------------------------------------------ start
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
            if isinstance(status, _InPlace):
                status.settle()  # a start cut short by Ctrl-C or a cancel still ends its restart
            self._ended_run(run)

    def _restart_in_place(self, run: Run, reason: ExitReason | Ignore) -> bool:
        """Whether a worker's own task starts its next incarnation now
        (decided by `supervisors.restart.Restarts`)."""
        raise NotImplementedError

    def _ended_run(self, run: Run) -> None:
        run.done.set()
        self._exited.append(run)
        self._wakeup.set()

    async def _supervisor_task(self, run: Run, *,
                               task_status: trio.TaskStatus[Started]) -> None:
        child = run.child
        reported = False  # the start's outcome reached the task status, or leaves as an exception
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
                    nonlocal reported
                    reported = True
                    task_status.started(value)

                run.reason = await sup.run(task_status=_Relay(started_cb))
            if scope.cancelled_caught:
                run.reason = KILLED
        except BaseException:  # Ctrl-C or an outer cancel: it leaves `nursery.start` itself
            reported = True
            raise
        finally:
            if not reported:
                task_status.started(run.reason or KILLED)
            self._ended_run(run)

    # ------------------------------------------------------------------ ended for good
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
    `supervisors.restart.Restarts._restart_in_place`): ends the restart when its
    start returned."""

    __slots__ = ("_sup", "_child", "_reported")

    def __init__(self, sup: ChildLifecycle, child: ChildRecord) -> None:
        self._sup = sup
        self._child = child
        self._reported = False

    def settle(self) -> None:
        """End the restart as ``killed`` unless its start reported: an incarnation that a
        ``KeyboardInterrupt`` or a cancel stops while it starts reports nothing (the
        exception carries the news), and the restart must still end (its lock freed)."""
        if not self._reported:
            self.started(KILLED)

    def started(self, value: Started = None) -> None:
        self._reported = True
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
