"""Virtual time released to the wall clock: the console's clock.

The headless game (`hideseek run`) runs on a virtual clock: time stands still
while any task can run and jumps to the next deadline when every task is
blocked, so a game is a function of its scenario and seed alone. The console
plays that same game. `GovernedClock` is a virtual clock with a governor: a
jump is allowed only as far as the wall clock has released virtual time,
``rate`` simulated seconds per wall second since the last change of rate.
While the next deadline is not yet released, Trio sleeps for the wall time
until it is (at most `POLL_S` at a time, so a new rate or a resume is noticed
without waking any task). The speed changes only *when* each jump happens,
never *which* jumps happen or in what order: x1, x4, x16 and "as fast as
possible" (``rate=None``: every jump at once) play the same game, event for
event, with the same trace hash.

When the machine cannot keep up, the next deadline is always released before
the tasks are idle again; time then runs as fast as the machine allows, and
`GovernedClock.reached` says how fast that was. Released time that the
machine could not use is not kept beyond `MAX_DEBT_S` of wall time, so a slow
stretch is not followed by a burst "catching up".

This is the one place of the console that reads the wall clock; the game
never sees it. Trio asks `deadline_to_sleep_time` only when no task is
runnable, which is exactly when a virtual clock jumps.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

import trio

__all__ = ["GovernedClock", "POLL_S", "MAX_DEBT_S"]

#: Longest wall sleep before the clock looks at its rate again [s, wall].
POLL_S = 0.05
#: Released virtual time the machine could not use is kept for this long at most [s, wall].
MAX_DEBT_S = 0.25
#: The reached speed is measured over this much wall time [s, wall].
REACHED_WINDOW_S = 2.0


class GovernedClock(trio.abc.Clock):
    """A virtual clock paced to the wall clock at ``rate`` (None: as fast as possible).

    Args:
        rate: simulated seconds released per wall second, > 0; None releases every
            deadline at once (a plain virtual clock).
        paused: start with no time released.
        wall: the wall clock [s] (a test hook).

    Raises:
        ValueError: ``rate`` is not None and not a finite number > 0.
    """

    def __init__(self, rate: float | None = 1.0, *, paused: bool = False,
                 wall: Callable[[], float] = time.perf_counter) -> None:
        self._wall = wall
        self._vt = 0.0  # the virtual time [s]
        self._rate = _check(rate)
        self._paused = paused
        self._anchor_wall = wall()  # released time = _anchor_vt + (wall - _anchor_wall) * rate
        self._anchor_vt = 0.0
        self._samples: deque[tuple[float, float]] = deque(maxlen=64)  # (wall, vt)

    def __repr__(self) -> str:
        rate = "max" if self._rate is None else f"x{self._rate:g}"
        return f"<GovernedClock t={self._vt:.3f} {rate}{' paused' if self._paused else ''}>"

    # -- trio.abc.Clock -----------------------------------------------------------
    def start_clock(self) -> None:
        self._reanchor()

    def current_time(self) -> float:
        return self._vt

    def deadline_to_sleep_time(self, deadline: float) -> float:
        """Called by Trio when no task is runnable: jump to ``deadline`` if it is
        released, else say how long to sleep [s, wall] until it is."""
        if deadline <= self._vt:
            return 0.0
        if self._paused or deadline == math.inf:
            return POLL_S
        if self._rate is None:
            self._vt = deadline
            return 0.0
        now = self._wall()
        released = self._anchor_vt + (now - self._anchor_wall) * self._rate
        if deadline <= released:
            if released - deadline > MAX_DEBT_S * self._rate:  # the machine fell behind:
                self._anchor_vt, self._anchor_wall = deadline, now - MAX_DEBT_S  # forget it
            self._vt = deadline
            return 0.0
        return min((deadline - released) / self._rate, POLL_S)

    # -- the governor -------------------------------------------------------------
    @property
    def rate(self) -> float | None:
        """Simulated seconds released per wall second; None: as fast as possible."""
        return self._rate

    @property
    def paused(self) -> bool:
        """No virtual time is released."""
        return self._paused

    def set(self, rate: float | None, paused: bool) -> None:
        """Change the rate and pause; from any code of the thread that runs Trio.

        Trio notices within `POLL_S` (a sleeping run is not woken: waking it
        would run a task, and the game must not see the console).

        Raises:
            ValueError: ``rate`` is not None and not a finite number > 0.
        """
        self._rate = _check(rate)
        self._paused = paused
        self._reanchor()
        self._samples.clear()

    def reached(self) -> float | None:
        """Simulated seconds per wall second over the last `REACHED_WINDOW_S` (None until
        two samples, or while paused); sampled at each call, so call it at the UI's rate."""
        if self._paused:
            return None
        now = self._wall()
        samples = self._samples
        samples.append((now, self._vt))
        while len(samples) > 2 and now - samples[1][0] >= REACHED_WINDOW_S:
            samples.popleft()
        w0, v0 = samples[0]
        if now - w0 < 0.2:
            return None
        return (self._vt - v0) / (now - w0)

    def _reanchor(self) -> None:
        self._anchor_vt, self._anchor_wall = self._vt, self._wall()


def _check(rate: float | None) -> float | None:
    if rate is None:
        return None
    if isinstance(rate, bool) or not isinstance(rate, int | float):
        raise TypeError(f"rate must be a number or None, got {rate!r}")
    if not 0 < rate < math.inf:
        raise ValueError(f"rate must be a finite number > 0 or None, got {rate!r}")
    return float(rate)
