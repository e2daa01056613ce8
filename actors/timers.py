"""Actor timers: one service task per actor system posts every timer's ticks.

Why one task and not a task per timer: a Trio sleep is a cancel scope whose
deadline expires, i.e. a scope entered, a ``Cancelled`` raised and caught,
and a task switch, for every tick of every timer. In a whole game the
timers of the three rovers (motor control, WiFly, navigation) tick
together at the same instants; one service task sleeping until the earliest
due time posts all the ticks due then in one wake-up. Its sleep is one
scope whose deadline is moved earlier when a sooner timer is added.

The service is opt-in for now (``open_actor_system(timer_service=True)``);
without it every timer is a task of its own (`TaskTimer`), as before. Why
opt-in: it changes the order of same-instant events, and one end-to-end game
test (the gap room on the truth map, seed 1) happens to fall on a navigation
failure that another seed shows without it; the default flips once that is
fixed.

Semantics are those of the per-task timers: the first tick
``delay`` [s] after the start, then every ``interval`` [s] counted from
when the previous tick was posted (so a late service does not post a
catch-up burst); ticks go to the owner's mailbox with ``send_nowait`` (a
full mailbox drops and counts the tick); ticks due at the same instant are
posted in the order their timers were scheduled (deterministic).
"""

from __future__ import annotations

import heapq
import math
from typing import TYPE_CHECKING, Any

import trio

if TYPE_CHECKING:
    from .mailbox import Mailbox

__all__ = ["TaskTimer", "Timer", "TimerService"]

#: cancelled entries tolerated in the heap before it is compacted
_COMPACT_AT = 64


class Timer:
    """A running timer (made by `ActorContext.start_timer`); `cancel` stops it."""

    __slots__ = ("_service", "_mailbox", "_message", "_interval", "_done", "_on_done")

    def __init__(self, service: TimerService, mailbox: Mailbox, message: Any,
                 interval: float | None, on_done: Any) -> None:
        self._service = service
        self._mailbox = mailbox
        self._message = message
        self._interval = interval
        self._done = False
        self._on_done = on_done  # called once when the timer ends (owner's bookkeeping)

    def cancel(self) -> None:
        """Stop the timer (idempotent)."""
        if not self._done:
            self._finish()
            self._service._cancelled_in_heap += 1

    def _finish(self) -> None:
        self._done = True
        self._on_done(self)

    @property
    def cancelled(self) -> bool:
        """True once cancelled (or its actor stopped, or a one-shot timer fired)."""
        return self._done


class TaskTimer:
    """A timer run by a task of its own (without a `TimerService`); `cancel` stops it."""

    __slots__ = ("_scope",)

    def __init__(self, scope: trio.CancelScope) -> None:
        self._scope = scope

    def cancel(self) -> None:
        """Stop the timer (idempotent)."""
        self._scope.cancel()

    @property
    def cancelled(self) -> bool:
        """True once cancelled (or its actor stopped)."""
        return self._scope.cancel_called


class TimerService:
    """The timers of one actor system (made and run by `open_actor_system`)."""

    __slots__ = ("_heap", "_seq", "_scope", "_cancelled_in_heap")

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Timer]] = []  # (due [s], order, timer)
        self._seq = 0
        self._scope: trio.CancelScope | None = None  # the service's sleep, while it sleeps
        self._cancelled_in_heap = 0

    def start(self, mailbox: Mailbox, message: Any, delay: float, interval: float | None,
              on_done: Any) -> Timer:
        """Post ``message`` to ``mailbox`` after ``delay`` [s], then every ``interval`` [s]."""
        timer = Timer(self, mailbox, message, interval, on_done)
        self._push(trio.current_time() + delay, timer)
        return timer

    def _push(self, due: float, timer: Timer) -> None:
        heapq.heappush(self._heap, (due, self._seq, timer))
        self._seq += 1
        scope = self._scope
        if scope is not None and due < scope.deadline:
            scope.deadline = due

    def _compact(self) -> None:
        self._heap = [e for e in self._heap if not e[2]._done]
        heapq.heapify(self._heap)
        self._cancelled_in_heap = 0

    async def run(self) -> None:
        """Post ticks as they fall due, forever (cancelled with the system)."""
        while True:
            if self._cancelled_in_heap > _COMPACT_AT and self._cancelled_in_heap * 2 > len(
                    self._heap):
                self._compact()
            with trio.CancelScope() as scope:
                scope.deadline = self._heap[0][0] if self._heap else math.inf
                self._scope = scope
                try:
                    await trio.sleep_forever()
                finally:
                    self._scope = None
            heap = self._heap
            now = trio.current_time()
            while heap and heap[0][0] <= now:
                _, _, timer = heapq.heappop(heap)
                if timer._done:
                    self._cancelled_in_heap = max(0, self._cancelled_in_heap - 1)
                    continue
                timer._mailbox.send_nowait(timer._message)
                if timer._interval is None:
                    timer._finish()
                else:
                    self._push(now + timer._interval, timer)
