"""The command half every console system shares: queue, run in Trio, publish the result.

`tui.snapshot.Controller` methods are called from Textual handlers and must
never block or raise. `QueuedController` implements them once: each call is
queued with ``send_nowait`` into a bounded Trio channel (a full queue is a
``refused`` result with reason ``"busy"``), and `_command_loop`, running in
Trio, calls the subclass's ``_do_<command>`` (plain or async) and publishes a
`CommandResult`: ``refused`` when it raised ValueError/TypeError, ``error`` for
OSError, ``ok`` otherwise. It also owns the clock, because pause and speed are
the clock's rate: a Trio `MockClock`'s rate and autojump, changed from inside
Trio, or a `tui.governor.GovernedClock`'s, changed at once on the console's
side (no Trio task runs for it, so the game cannot see a change of speed).

Subclasses supply ``_do_<command>`` for the commands they support and
``_event(kind, text)`` for the timeline.
"""

from __future__ import annotations

import inspect
import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import trio
import trio.testing

from tui.governor import GovernedClock
from tui.snapshot import CommandResult, Publish

__all__ = ["QueuedController"]


class QueuedController:
    """Controller methods, the command queue, and the clock of a console system.

    Args:
        speed: initial clock rate, None for "as fast as possible".
        paused: start with simulated time stopped.
        capacity: commands that may wait for Trio [commands].
        governed: run on a `GovernedClock` (the game's virtual clock paced to the
            wall clock) instead of a `MockClock` running at the speed.

    Attributes:
        clock: the Trio clock the system runs on.
        calls: every controller call received, ``(method, args)``, newest last
            (bounded), for tests and the benchmark.
    """

    def __init__(self, *, speed: float | None, paused: bool = False, capacity: int,
                 governed: bool = False) -> None:
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be > 0 or None, got {speed!r}")
        self.clock: trio.testing.MockClock | GovernedClock = (
            GovernedClock(speed, paused=paused) if governed else trio.testing.MockClock())
        self.calls: deque[tuple[str, tuple]] = deque(maxlen=1000)
        self._speed = speed
        self._paused = paused
        self._publish: Publish | None = None
        self._cmd_send, self._cmd_recv = trio.open_memory_channel[tuple[str, tuple]](capacity)
        self._apply_clock()

    # -- Controller (synchronous, called from the console) -----------------
    def start_mapping(self) -> None:
        self._submit("start_mapping")

    def stop_mapping(self) -> None:
        self._submit("stop_mapping")

    def hide_at(self, x_cm: float, y_cm: float, heading_deg: float) -> None:
        self._submit("hide_at", float(x_cm), float(y_cm), float(heading_deg))

    def seek_at(self, x_cm: float, y_cm: float, within_cm: float | None = None) -> None:
        wider = () if within_cm is None else (float(within_cm),)
        self._submit("seek_at", float(x_cm), float(y_cm), *wider)

    def new_game(self) -> None:
        self._submit("new_game")

    def pause(self) -> None:
        self._clock_command("pause")

    def resume(self) -> None:
        self._clock_command("resume")

    def set_speed(self, rate: float | None) -> None:
        self._clock_command("set_speed", rate)

    def inject_fault(self, target: str, kind: str, duration_s: float | None,
                     params: Mapping[str, Any]) -> None:
        self._submit("inject_fault", target, kind, duration_s, dict(params))

    def clear_fault(self, fault: str) -> None:
        self._submit("clear_fault", fault)

    def export_map(self, directory: str) -> None:
        self._submit("export_map", str(directory))

    def _clock_command(self, name: str, *args: Any) -> None:
        """Pause and speed: on a governed clock, done here and now (see `GovernedClock.set`)."""
        if not isinstance(self.clock, GovernedClock):
            self._submit(name, *args)
            return
        self.calls.append((name, args))
        try:
            reason = getattr(self, "_do_" + name)(*args)
        except (ValueError, TypeError) as exc:
            self._result(name, "refused", str(exc))
        else:
            self._result(name, "ok", reason or "")

    def _submit(self, name: str, *args: Any) -> None:
        self.calls.append((name, args))
        try:
            self._cmd_send.send_nowait((name, args))
        except trio.WouldBlock:
            self._result(name, "refused", "busy")

    # -- Trio side ----------------------------------------------------------
    async def _command_loop(self) -> None:
        """Run queued commands one at a time, publishing each outcome."""
        async for name, args in self._cmd_recv:
            self._before_command()
            try:
                reason = getattr(self, "_do_" + name)(*args)
                if inspect.isawaitable(reason):
                    reason = await reason
            except (ValueError, TypeError) as exc:
                self._result(name, "refused", str(exc))
            except OSError as exc:
                self._result(name, "error", f"{exc.strerror or exc}: {exc.filename or ''}")
            else:
                self._result(name, "ok", reason or "")

    def _before_command(self) -> None:
        """Hook run before each command (the fake system reads the clock here)."""

    def _result(self, name: str, status: str, reason: str) -> None:
        if self._publish is not None:
            self._publish(CommandResult(name, status, reason))  # type: ignore[arg-type]

    def _event(self, kind: str, text: str) -> None:
        raise NotImplementedError

    # -- clock commands -----------------------------------------------------
    def _do_pause(self) -> None:
        self._paused = True
        self._apply_clock()
        self._event("game", "paused")

    def _do_resume(self) -> None:
        self._paused = False
        self._apply_clock()
        self._event("game", "resumed")

    def _do_set_speed(self, rate: float | None) -> str:
        if rate is not None and not (isinstance(rate, int | float) and rate > 0):
            raise ValueError(f"speed must be > 0 or None, got {rate!r}")
        self._speed = rate
        self._apply_clock()
        text = "as fast as possible" if rate is None else f"x{rate:g}"
        self._event("game", f"speed {text}")
        return text

    def _apply_clock(self) -> None:
        """Pause and speed are the clock's rate and autojump (a `MockClock`: call inside
        Trio once running)."""
        if isinstance(self.clock, GovernedClock):
            self.clock.set(self._speed, self._paused)
        elif self._paused:
            self.clock.autojump_threshold = math.inf
            self.clock.rate = 0.0
        elif self._speed is None:
            self.clock.rate = 0.0
            self.clock.autojump_threshold = 0.0
        else:
            self.clock.autojump_threshold = math.inf
            self.clock.rate = float(self._speed)
