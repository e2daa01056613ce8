"""`Kick`: the server timer's wake-up, re-armed each round instead of made anew.

The timer task (`Server._timer`) sleeps until its next deadline or until work is
queued for a link (`Kick.set`, on every flush). Why not a `trio.Event` waited on
in a `trio.move_on_at` scope: an Event cannot be cleared, so each round would make
one (an attrs object and a parking lot), and the scope is made, entered, has its
deadline registered and is left every round (the dearer part). A `Kick` is
cleared instead, and `wait_until` bounds the wait by an entry in Trio's deadline
heap (`actors.clock.HeapEntry`, as the actors' sleeps do), which wakes the timer
with a plain value when due.

The wake-ups are an Event's and a scope's: a kick already given makes the wait a
checkpoint; `set` reschedules the parked task at once; the deadline reschedules it
in Trio's expiry pass, where a scope's cancellation would. So the timer wakes in
the same scheduler batches as with an Event in a scope (the same game). Without
Trio's internals the deadline is a cancel scope's.
"""

from __future__ import annotations

import math
from typing import Any

import trio
from trio.lowlevel import Abort, checkpoint, current_task, reschedule, wait_task_rescheduled

from actors.clock import HeapEntry, deadline_heap

__all__ = ["Kick"]


class Kick(HeapEntry):
    """A flag one task waits on, until a deadline; cleared by the waiter, set by anyone."""

    __slots__ = ("_given", "_waiter")

    def __init__(self) -> None:
        super().__init__(None)
        self._given = False
        self._waiter: Any = None  # the parked task, or None

    def set(self) -> None:
        """Give the kick: wakes the waiting task, or makes its next wait return."""
        if not self._given:
            self._given = True
            if self._waiter is not None:
                self._wake()

    def is_set(self) -> bool:
        """Whether a kick was given since the last `clear`."""
        return self._given

    def clear(self) -> None:
        """Take the kick back (the waiter, before it looks for work again)."""
        self._given = False

    async def wait_until(self, deadline: float = math.inf) -> bool:
        """Return once the kick is given (a checkpoint if it already was) or ``deadline``
        [s, Trio time] has come. True when kicked.

        Raises:
            RuntimeError: another task is already waiting.
        """
        if self._given:
            await checkpoint()
            return True
        if self._waiter is not None:
            raise RuntimeError("Kick has a waiting task already")
        deadlines = deadline_heap()
        if deadlines is None or not trio.current_time() < deadline < math.inf:
            with trio.move_on_at(deadline):  # no heap (another Trio), due, or never
                self._waiter = current_task()
                await wait_task_rescheduled(self._abort)
            return self._given
        self._deadlines = deadlines
        self._waiter = current_task()
        self._enter(deadline)
        await wait_task_rescheduled(self._abort)
        return self._given

    async def wait(self) -> None:
        """Return once the kick is given (a checkpoint if it already was)."""
        await self.wait_until(math.inf)

    def _wake(self) -> None:
        task, self._waiter = self._waiter, None
        self._leave()
        reschedule(task)

    def _cancel(self, _reason: Any) -> None:
        """The deadline is due (called by Trio's `Deadlines.expire`): wake the waiter."""
        if self._waiter is not None:
            self._wake()
        else:  # pragma: no cover - the waiter left the heap when it stopped waiting
            self._leave()

    def _abort(self, _raise_cancel: Any) -> Abort:
        """Cancelled from outside while waiting: leave the heap, let Trio raise."""
        self._waiter = None
        self._leave()
        return Abort.SUCCEEDED
