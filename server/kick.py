"""`Kick`: the server timer's wake-up, re-armed each round instead of made anew.

The timer task (`Server._timer`) sleeps until its next deadline or until work is
queued for a link (`Kick.set`, on every flush). A `trio.Event` cannot be cleared,
so the timer used to make one per round (an attrs object and a parking lot);
this one is cleared instead. Its wait and its wake-up are the ones an Event's
are: a kick already given makes `wait` a checkpoint, and `set` reschedules the
one parked task at once, so the timer wakes in the same scheduler batch.
"""

from __future__ import annotations

from typing import Any

from trio.lowlevel import Abort, checkpoint, current_task, reschedule, wait_task_rescheduled

__all__ = ["Kick"]


class Kick:
    """A flag one task waits on; cleared by the waiter, set by anyone."""

    __slots__ = ("_given", "_waiter")

    def __init__(self) -> None:
        self._given = False
        self._waiter: Any = None  # the parked task, or None

    def set(self) -> None:
        """Give the kick: wakes the waiting task, or makes its next `wait` return."""
        if not self._given:
            self._given = True
            if self._waiter is not None:
                task, self._waiter = self._waiter, None
                reschedule(task)

    def is_set(self) -> bool:
        """Whether a kick was given since the last `clear`."""
        return self._given

    def clear(self) -> None:
        """Take the kick back (the waiter, before it looks for work again)."""
        self._given = False

    async def wait(self) -> None:
        """Return once the kick is given (a checkpoint if it already was).

        Raises:
            RuntimeError: another task is already waiting.
        """
        if self._given:
            await checkpoint()
            return
        if self._waiter is not None:
            raise RuntimeError("Kick has a waiting task already")
        self._waiter = current_task()
        await wait_task_rescheduled(self._abort)

    def _abort(self, _raise_cancel: Any) -> Abort:
        self._waiter = None
        return Abort.SUCCEEDED
