"""How often the console draws: a frame rate, and fewer frames at "as fast as possible".

At a set speed the console asks for `REFRESH_HZ` snapshots per wall second. At
"as fast as possible" every frame drawn is simulation not run, so `FramePacer`
lets through at most `REFRESH_HZ_MAX_SPEED` frames per second, and none while
the console's share of the thread's time since the last frame is above
`UI_SHARE_MAX_SPEED` (Trio's batches are the rest), but at least one per
`MAX_FRAME_GAP_S`. Wall time here paces drawing only, never the game.
"""

from __future__ import annotations

import time

__all__ = ["REFRESH_HZ", "REFRESH_HZ_MAX_SPEED", "UI_SHARE_MAX_SPEED", "MAX_FRAME_GAP_S",
           "FramePacer"]

#: Snapshots asked for per wall second.
REFRESH_HZ = 15.0
#: ... and at "as fast as possible", where every frame drawn is simulation not run.
REFRESH_HZ_MAX_SPEED = 10.0
#: At "as fast as possible", frames are drawn only while the console's share of the
#: thread's time stays below this (the simulation keeps the rest, however loaded the
#: machine), and at least once per `MAX_FRAME_GAP_S`.
UI_SHARE_MAX_SPEED = 0.06
MAX_FRAME_GAP_S = 1.0


class FramePacer:
    """Decides, tick by tick, whether a frame at "as fast as possible" is skipped.

    Args:
        refresh_hz: the console's ticks per wall second.
    """

    def __init__(self, refresh_hz: float) -> None:
        self.refresh_hz = refresh_hz
        self._credit = 0.0  # frames owed at a reduced refresh rate
        self._last_frame = (0.0, 0.0)  # (wall [s], guest's busy_s) at the last frame drawn

    def skip(self, busy_s: float) -> bool:
        """One tick: True to skip its frame; ``busy_s`` is the time the Trio guest has
        been busy so far [s]."""
        self._credit = min(1.0, self._credit + REFRESH_HZ_MAX_SPEED / self.refresh_hz)
        if self._credit < 1.0:
            return True
        now = time.perf_counter()
        t0, busy0 = self._last_frame
        elapsed = now - t0
        if elapsed < MAX_FRAME_GAP_S and elapsed - (busy_s - busy0) > UI_SHARE_MAX_SPEED * elapsed:
            return True
        self._credit -= 1.0
        self._last_frame = (now, busy_s)
        return False
