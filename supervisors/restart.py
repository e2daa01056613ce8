"""Restart decisions: a supervisor's exits, its strategy, intensity, backoff and auto-shutdown.

The rules are the contract in `supervisors.supervisor`; the pure parts
(`should_restart`, `intensity_exceeded`, `backoff_delay`) are in
`supervisors.spec`. `Restarts` applies them to the exits its children's tasks
queue, one at a time under the supervisor's serial lock, and keeps the
bookkeeping they need: the restart times inside the intensity window and the
restarts since the last quiet period.
"""

from __future__ import annotations

import math
from collections import deque
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
)

from .children import ChildLifecycle
from .spec import AutoShutdown, Restart, Strategy, backoff_delay, intensity_exceeded, should_restart
from .state import ChildRecord, Run

__all__ = ["Restarts"]


class Restarts(ChildLifecycle):
    """A supervisor's restart logic, over the children `ChildLifecycle` starts and stops."""

    def __init__(self, spec: Any, system: ActorSystem, name: str) -> None:
        super().__init__(spec, system, name)
        self._restart_times: deque[float] = deque()  # inside the intensity window, in order
        self._consecutive = 0  # restarts since the last quiet period (backoff)
        self._last_restart = -math.inf
        self._rng = system.rng_for(f"supervisor:{name}")

    # ------------------------------------------------------------------ restart in place
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
