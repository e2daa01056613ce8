"""A recording as the console's `System`: the same panels, read from a file.

`ReplaySystem` implements `tui.snapshot.System` over a `ReplayIndex`. Its
replay time runs on the console's clock (pause and speed are the clock's, as
for a live system); `seek`, `step` and `next_event` move it. Commands that
would change the game (mapping, hide, seek, faults) are refused: nothing is
simulated. ``Fork`` is the way to change a recorded game
(`supervisors.recording.fork`).
"""

from __future__ import annotations

import math
from typing import Any

import trio

from server.protocol import Pose, compose, inverse
from supervisors.recording.reading import Recording, read_recording
from tui.controller import QueuedController
from tui.snapshot import Publish, Snapshot, TimelineEvent

from .index import EVENT_KINDS, ReplayIndex

__all__ = ["ReplaySystem", "MAX_SPEED", "map_from_room"]

MAX_SPEED = 64.0
"""What "as fast as possible" means in a replay (there is nothing to compute) [x]."""
_NOTHING_SIMULATED = "a replay reads the recording: nothing is simulated (fork it to change it)"


def map_from_room(rec: Recording) -> Any:
    """Room frame -> map frame from the recording's scenario (None when it cannot be rebuilt)."""
    try:
        start = rec.run.scenario().starts["mapper"]
    except Exception:  # noqa: BLE001 - any rebuild failure: points shown as given
        return None
    to_map = inverse(Pose(start.x, start.y, start.heading_deg))

    def convert(x: float, y: float, heading: float = 0.0) -> tuple[float, float, float]:
        p = compose(to_map, Pose(x, y, heading))
        return p.x, p.y, p.heading_deg
    return convert


class ReplaySystem(QueuedController):
    """Replays a recording in the console (see the module docstring).

    Args:
        recording: a `Recording` read whole, or the path of one.
        speed: initial rate, None for `MAX_SPEED`.
        paused: start paused.
        at: start at this simulated time [s] (default: the recording's start).

    Raises:
        supervisors.recording.reading.RecordingReadError: the file cannot be read.
    """

    def __init__(self, recording: Recording | str, *, speed: float | None = 1.0,
                 paused: bool = False, at: float | None = None) -> None:
        rec = read_recording(recording) if isinstance(recording, str) else recording
        self.rec = rec
        self.index = ReplayIndex(rec, map_from_room(rec))
        self._t = self.index.start_s  # replay time at the anchor [s]
        if at is not None:
            self._t = min(max(float(at), self.index.start_s), self.index.end_s)
        self._anchor: float | None = None  # clock time when `_t` was set (None: not running)
        self._timeline_extra: list[TimelineEvent] = []
        self._last_kind: str | None = None
        super().__init__(speed=speed, paused=paused, capacity=32)

    # -- time -------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """The replay's simulated time now [s], within the recording."""
        if self._anchor is None:
            return self._t
        # the clock runs at the replay's speed and stands still while paused
        t = self._t + (trio.current_time() - self._anchor)
        return min(max(t, self.index.start_s), self.index.end_s)

    def _set_time(self, t: float) -> None:
        self._t = min(max(t, self.index.start_s), self.index.end_s)
        self._anchor = trio.current_time() if self._anchor is not None else None

    def _apply_clock(self) -> None:
        """Speed is the clock's rate; "as fast as possible" is `MAX_SPEED` (nothing waits on
        the clock in a replay, so autojump would stop time instead)."""
        if self._anchor is not None:
            self._t, self._anchor = self.time_s, trio.current_time()
        self.clock.autojump_threshold = math.inf
        self.clock.rate = 0.0 if self._paused else float(self._speed or MAX_SPEED)

    # -- Trio side ----------------------------------------------------------------------
    async def run(self, publish: Publish, requests: trio.abc.ReceiveChannel[None]) -> None:
        """Answer the console's snapshot requests until cancelled."""
        self._publish = publish
        self._anchor = trio.current_time()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._command_loop)
            async for _ in requests:
                if not self._paused and self.time_s >= self.index.end_s:
                    self._do_pause()  # the end of the recording
                publish(self.snapshot())

    def snapshot(self) -> Snapshot:
        """What the recording shows at the replay's time."""
        t = self.time_s
        ix = self.index
        hide, guesses = ix.commands(t)
        run = self.rec.run
        return Snapshot(
            time_s=t, speed=self._speed, paused=self._paused,
            scenario=f"{run.scenario_ref} (replay)", seed=run.seed, phase=ix.phase(t),
            guesses=len(guesses), map=ix.map(t), rovers=ix.rovers(t),
            lidar_points=ix.lidar_points(t), hide_spot=hide, seek_guesses=guesses,
            queues=ix.queues(t), log=ix.log(t), tree=ix.tree(t), links=ix.links(t),
            timeline=ix.timeline(t), faults=ix.faults(t))

    def _event(self, kind: str, text: str) -> None:
        """Pause/speed notes are command results only: the timeline is the recording's."""

    # -- replay commands (called from the console; queued like every command) ------------
    def seek(self, t: float) -> None:
        """Go to simulated time ``t`` [s] (clamped to the recording)."""
        self._submit("seek", float(t))

    def step(self, dt: float) -> None:
        """Pause and move ``dt`` [s] (negative: back)."""
        self._submit("step", float(dt))

    def next_event(self, kind: str | None = None) -> None:
        """Go to the next timeline event (of ``kind``: phase, fault, crash, restart, link,
        game), after the current time."""
        self._submit("next_event", kind)

    def _do_seek(self, t: float) -> str:
        if not math.isfinite(t):
            raise ValueError(f"time must be a number of seconds, got {t!r}")
        self._set_time(t)
        return f"at {self.time_s:.1f} s"

    def _do_step(self, dt: float) -> str:
        if not self._paused:
            self._do_pause()
        self._set_time(self.time_s + dt)
        return f"at {self.time_s:.1f} s"

    def _do_next_event(self, kind: str | None) -> str:
        if kind is not None and kind not in EVENT_KINDS:
            raise ValueError(f"event kind must be one of {', '.join(EVENT_KINDS)}, got {kind!r}")
        t = self.index.next_event(self.time_s, kind)
        if t is None:
            raise ValueError(f"no {kind or ''} event after {self.time_s:.1f} s".replace("  ", " "))
        self._set_time(t)
        return f"{kind or 'event'} at {t:.1f} s"

    # -- what a replay cannot do -----------------------------------------------------------
    def _refuse(self, *args: Any) -> None:
        raise ValueError(_NOTHING_SIMULATED)

    _do_start_mapping = _do_stop_mapping = _do_hide_at = _do_seek_at = _refuse
    _do_new_game = _do_inject_fault = _do_clear_fault = _do_export_map = _refuse
