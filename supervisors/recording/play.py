"""Play one headless game with a recorder on: what ``--record-failures`` runs per game."""

from __future__ import annotations

import os

from actors import running, seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import Budget, GameReport, run_game
from world.scenario import Scenario

from .recorder import Recorder

__all__ = ["record_game"]


def record_game(scenario: Scenario, seed: int, path: str | os.PathLike[str], *,
                budget_s: float = 1200.0, campaign: str | None = None) -> GameReport:
    """Play ``scenario`` with ``seed`` in virtual time, recorded into ``path``.

    ``campaign`` names the game's campaign reference (``S:I``) so the recording
    rebuilds it; its scheduling is seeded as ``hideseek run --campaign`` seeds it,
    so the recorded game has the campaign's trace hash.

    Raises:
        RecordingError: the file cannot be created.
    """
    recorder = Recorder.for_scenario(path, scenario, seed, budget_s=budget_s, campaign=campaign)
    seed_trio_scheduler(seed)
    return running.run(lambda: run_game(scenario, seed, budget=Budget(mapping=budget_s),
                                        observers=[recorder]), clock=virtual_clock())
