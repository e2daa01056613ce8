"""Fork a recording into the live console: the recorded game to T, then a person's.

`ForkLiveSystem` is the console's `LiveSystem` on the recording's scenario and
seed; before any of the console's tasks start (`LiveSystem._prelude`) it plays
the recorded game exactly as ``hideseek run`` did, the scenario's choices
standing in for the operator, as fast as the machine allows, with a
`ForkChecker` comparing each second with the recording. At T the headless
operator stops, time stands still (x1, paused) and the console takes over:
`ForkConsoleApp` opens the fault dialog.

Why this is the recorded game: the console's clock and Trio's guest mode play a
seed's game with the same trace hash as ``trio.run`` does, as long as nothing of
the console runs beside it, which is why the console's tasks start only at T.
If the game leaves the recording before T (other code, another scenario file),
the system stops with `ForkDiverged` and the console says why.
"""

from __future__ import annotations

from typing import Any

import trio

from supervisors.harness.headless import Budget, GameReport, play_game
from supervisors.recording.fork import ForkChecker, ForkDiverged, plan_fork
from supervisors.recording.reading import Recording
from supervisors.system import SimSystem
from tui.app import ConsoleApp
from tui.live import LiveSystem
from tui.snapshot import Publish, Snapshot
from tui.widgets import FaultDialog

__all__ = ["ForkLiveSystem", "ForkConsoleApp"]


class ForkLiveSystem(LiveSystem):
    """The live system, re-simulated from a recording to ``at_s`` first.

    Args:
        rec: the recording (read with its ``/checkpoints`` and ``/game/events``).
        at_s: the fork time [s].
        kwargs: `LiveSystem` options (``db``, ``log_messages``, ``record``).

    Raises:
        supervisors.recording.fork.ForkError: a fork that cannot be made.
        world.scenario.ScenarioError: the scenario cannot be rebuilt.
    """

    def __init__(self, rec: Recording, at_s: float, **kwargs: Any) -> None:
        info = plan_fork(rec, at_s)
        super().__init__(info.scenario(), seed=info.seed, speed=None, **kwargs)
        self.at_s = at_s
        self.budget = Budget(mapping=info.budget_s)
        self.checker = ForkChecker(
            {int(c["index"]): (c["trace_hash"], int(c["messages"]))
             for _, c in rec.topic("/checkpoints")}, at_s, recorded_code=rec.run.code)
        self.source = rec.path
        self.reached = False  # the fork has played the recorded game to its time

    async def run(self, publish: Publish, requests: trio.abc.ReceiveChannel[None]) -> None:
        """`LiveSystem.run`; a divergence ends it with `ForkDiverged` itself (not inside
        the nurseries' exception groups), so the console can say what happened."""
        try:
            await super().run(publish, requests)
        except BaseExceptionGroup:
            if self.checker.diverged is not None:
                raise ForkDiverged(self.checker.diverged) from None
            raise

    async def _prelude(self, system: SimSystem) -> None:
        """Play the recorded game to ``at_s`` (see the module docstring)."""
        checker = self.checker
        report = GameReport(self.scenario.name, self.seed)
        checker.started(system)
        with trio.CancelScope(deadline=self.at_s) as scope:
            checker.scope = scope
            await play_game(system, report, self.budget)
        checker.finished(system, report)
        if checker.diverged is not None:
            raise ForkDiverged(checker.diverged)
        self._speed, self._paused = 1.0, True
        self._apply_clock()
        self.reached = True
        self._event("game", f"forked {self.source} at {trio.current_time():.1f} s "
                            f"({checker.compared} seconds checked): yours from here, paused")


class ForkConsoleApp(ConsoleApp):
    """The console on a `ForkLiveSystem`: says what it is doing, then opens the fault
    dialog once the fork has reached its time."""

    def __init__(self, system: ForkLiveSystem, **kwargs: Any) -> None:
        super().__init__(system, **kwargs)
        self.fork = system
        self._dialog_shown = False

    def on_mount(self) -> None:
        # (ConsoleApp's own on_mount runs too: Textual calls each class's handler)
        self.notify(f"playing the recorded game to {self.fork.at_s:g} s, checked against "
                    "the recording ...", timeout=5)

    def show(self, snap: Snapshot) -> None:
        super().show(snap)
        if (not self._dialog_shown and self.fork.reached and snap.paused and snap.catalogue
                and len(self.screen_stack) == 1):
            self._dialog_shown = True
            self.push_screen(FaultDialog(snap.catalogue, snap.faults), self._fault_chosen)
