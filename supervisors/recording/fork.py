"""Fork a recorded game: play it again to time T, checking it, then differently.

A headless game is a function of its scenario, seed, budget and code, all of
which a recording names (`RunInfo`). `fork_game` rebuilds them, adds the
change (faults scheduled at T or later, another hide spot, other guesses) and
plays the game again in virtual time with a `ForkChecker` watching: at every
whole second before T it compares the run's checkpoint (runtime trace hash and
message count, `supervisors.recording.records.checkpoint`) with the one
recorded at that second. A mismatch means this is not the recorded game (other
code, other options, a changed scenario file): the run is cancelled and
`ForkDiverged` says where and what differed. A fork with no change plays the
recorded game to the end: the same trace hash.

Why the change goes into the scenario: a fault at T is one more entry of the
fault schedule, which the world and the actor-fault watcher apply when due, so
nothing is done before T that the recorded run did not do (the checker's tap
adds no task). A hide spot or guesses replace the scenario's; the headless
operator reads them only when it sends the hider or the seeker, so they must
come after T (checked against the recording's commands).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from typing import Any

import trio

from actors import EventKind, running, seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import Budget, GameReport, run_game
from supervisors.system import SimSystem
from world.faults import check_fault
from world.scenario import ScenarioError, ScheduledFault

from .reading import Recording, read_recording
from .recorder import Recorder
from .records import checkpoint
from .runinfo import RunInfo, code_version

__all__ = ["ForkChecker", "ForkDiverged", "ForkError", "fork_game", "plan_fork"]


class ForkError(ValueError):
    """A fork that cannot be made (bad time, a recording that cannot be re-played)."""


class ForkDiverged(RuntimeError):
    """Raised by `fork_game` when the re-simulated game left the recording before T."""


class ForkChecker:
    """A run observer comparing the run's checkpoints with recorded ones before ``at_s``.

    Args:
        recorded: whole second -> (trace hash, messages) of the recording.
        at_s: the fork time [s]; checkpoints at seconds < ``at_s`` are compared.
        recorded_code: the recording's code version (named in the error).
    """

    def __init__(self, recorded: dict[int, tuple[str, int]], at_s: float, *,
                 recorded_code: str = "unknown") -> None:
        self.recorded = recorded
        self.at_s = at_s
        self.recorded_code = recorded_code
        self.compared = 0
        """Checkpoints compared and found equal."""
        self.diverged: str | None = None
        """Why the run left the recording (None while it follows it)."""
        self.scope: trio.CancelScope | None = None
        """Cancelled when the run diverges (set by the caller)."""
        self._system: SimSystem | None = None
        self._next = 0.0
        self._sub: Any = None

    def started(self, system: SimSystem) -> None:
        self._system = system
        self._sub = system.actors.trace.tap_messages(self._on_message)
        now = trio.current_time()
        self._next = now
        self._check(now)

    def finished(self, system: SimSystem, report: GameReport) -> None:
        if self._sub is not None:
            self._sub.close()
            self._sub = None

    def _on_message(self, time: float, kind: EventKind, queue: str, message: Any,
                    depth: int) -> None:
        if time >= self._next:
            self._check(time)

    def _check(self, now: float) -> None:
        """The same instants as the recorder's checkpoints: the first message at or after
        each whole second."""
        self._next = math.floor(now) + 1.0
        index = int(math.floor(now))
        if self.diverged is not None or index >= self.at_s or self._system is None:
            if index >= self.at_s and self._sub is not None:
                self._sub.close()  # past T: nothing more to compare
                self._sub = None
            return
        want = self.recorded.get(index)
        if want is None:
            return
        got = checkpoint(self._system, now)
        if (got["trace_hash"], got["messages"]) == want:
            self.compared += 1
            return
        self.diverged = (
            f"the re-simulated game left the recording at t={now:.3f} s (before --fork-at "
            f"{self.at_s:g}): trace hash {got['trace_hash'][:12]} and {got['messages']} messages "
            f"here, {want[0][:12]} and {want[1]} in the recording. It was recorded by code "
            f"{self.recorded_code}, this is {code_version()}: other code or options play "
            "another game")
        if self.scope is not None:
            self.scope.cancel()


def plan_fork(rec: Recording, at_s: float, *,
              faults: Sequence[tuple[str, str, float]] = (),
              hide: tuple[float, float, float] | None = None,
              seek: Sequence[tuple[float, float]] | None = None) -> RunInfo:
    """The `RunInfo` of a fork of ``rec`` at ``at_s`` with these changes.

    Args:
        faults: (target, kind, duration [s]) injected at ``at_s``.
        hide: hide spot (room frame x, y [cm], heading [deg]) instead of the scenario's.
        seek: guesses (room frame [cm]) instead of the scenario's.

    Raises:
        ForkError: ``at_s`` outside the recording, a console recording, a fault that does
            not fit its target, or a hide spot or guesses given after the recorded game
            already sent the hider or the seeker.
    """
    if rec.run.operator != "headless":
        raise ForkError(f"{rec.path}: recorded from the console: a person's choices cannot be "
                        "played again headless; fork a `hideseek run` recording")
    began = _began(rec)
    if not math.isfinite(at_s) or not began <= at_s <= rec.end_s:
        raise ForkError(f"--fork-at must be within the recording, {began:.1f}..{rec.end_s:.1f} "
                        f"s, got {at_s!r}" + (" (it was started mid-game: the game before "
                                              "it is not checked)" if began > 0 else ""))
    for name, given in (("hide", hide is not None), ("seek", seek is not None)):
        sent = _first_command(rec, name)
        if given and sent is not None and sent < at_s:
            raise ForkError(f"--{name}: the recorded game sent the "
                            f"{'hider' if name == 'hide' else 'seeker'} at t={sent:.1f} s, "
                            f"before --fork-at {at_s:g}: fork earlier")
    extra = []
    for target, kind, duration in faults:
        try:
            params = check_fault(target, kind, float(duration), {})
        except ValueError as exc:
            raise ForkError(f"--fault: {exc}") from None
        extra.append(ScheduledFault(at_s, target, kind, float(duration), params))
    return dataclasses.replace(
        rec.run, code=code_version(), extra_faults=rec.run.extra_faults + tuple(extra),
        hide_at=hide if hide is not None else rec.run.hide_at,
        seek_at=tuple(seek) if seek is not None else rec.run.seek_at)


def _began(rec: Recording) -> float:
    """When the recording began [s]: 0, or the time of the game state it starts with."""
    states = rec.topic("/game/state")
    return states[0][0] if states else 0.0


def _first_command(rec: Recording, name: str) -> float | None:
    """When the recorded game first sent ``hide`` or ``seek`` (the recording's start when
    it was sent before the recording began), None when never."""
    states = rec.topic("/game/state")
    if states and states[0][1].get("hide_spot" if name == "hide" else "guesses"):
        return states[0][0]
    for t, log in rec.topic("/game/events"):
        if log.get("name") == "command" and f"command={name} " in log.get("message", "") + " ":
            return t
    return None


def fork_game(path: str | os.PathLike[str], at_s: float, *,
              faults: Sequence[tuple[str, str, float]] = (),
              hide: tuple[float, float, float] | None = None,
              seek: Sequence[tuple[float, float]] | None = None,
              record: str | os.PathLike[str] | None = None) -> tuple[GameReport, ForkChecker]:
    """Re-simulate the recording at ``path`` to ``at_s``, checking it, and play on changed.

    Runs its own Trio run in virtual time (like ``hideseek run``).

    Returns:
        The game's report and the checker (``compared``: checkpoints found equal).

    Raises:
        RecordingReadError: the file cannot be read.
        ForkError: a fork that cannot be made (see `plan_fork`), or a scenario that
            cannot be rebuilt.
        ForkDiverged: the game left the recording before ``at_s``.
    """
    rec = read_recording(path, topics=("/checkpoints", "/game/events", "/game/state"))
    info = plan_fork(rec, at_s, faults=faults, hide=hide, seek=seek)
    try:
        scenario = info.scenario()
    except ScenarioError as exc:
        raise ForkError(str(exc)) from None
    recorded = {int(c["index"]): (c["trace_hash"], int(c["messages"]))
                for _, c in rec.topic("/checkpoints")}
    checker = ForkChecker(recorded, at_s, recorded_code=rec.run.code)
    observers: list[Any] = [checker]
    if record is not None:
        observers.append(Recorder(record, info, scenario_toml=rec.scenario_toml))
    seed_trio_scheduler(info.seed)

    async def main() -> GameReport | None:
        with trio.CancelScope() as scope:
            checker.scope = scope
            return await run_game(scenario, info.seed, budget=Budget(mapping=info.budget_s),
                                  observers=observers)
        return None

    report = running.run(main, clock=virtual_clock())
    if checker.diverged is not None or report is None:
        raise ForkDiverged(checker.diverged or "the fork was cancelled")
    return report, checker

