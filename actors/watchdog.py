"""The watchdog of one incarnation: a message handled past its deadline is cancelled.

`Guard` is one cancel scope per incarnation, cancelled when the deadline of the
message being handled passes; `actors.serving` arms it as a message starts and
disarms it before parking. Trio cancels only at checkpoints: a handler stuck
in a loop that never awaits cannot be cancelled.
"""

from __future__ import annotations

import math
from typing import Any

import trio

from .clock import HeapEntry, deadline_heap, time_reader

__all__ = ["Guard"]


class Guard(HeapEntry):
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

    __slots__ = ("scope", "watchdog", "since", "_now")

    def __init__(self, watchdog: float | None) -> None:
        super().__init__(deadline_heap() if watchdog is not None else None)
        self.scope = trio.CancelScope()
        self.watchdog = watchdog
        self.since = math.inf  # when the deadline was last set [s]; inf: not armed
        self._now = time_reader()  # read per handled message

    def arm(self) -> None:
        """A message starts now: its handling must end within the watchdog deadline."""
        if self.watchdog is not None:
            now = self._now()
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
