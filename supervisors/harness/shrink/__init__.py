"""Shrinking failing games: the smallest fault schedule that still fails the same way.

The package, bottom up:

- `ddmin`: delta debugging over a list (Zeller's ddmin);
- `schedule`: `shrink_schedule`, which faults, how late, how short, how mild,
  pure of the game (it is handed a ``play`` function);
- `toml`: a scenario written back as TOML;
- `game`: real games: `shrink_game` (a room with its schedule and a seed) and
  `shrink_campaign_game` (the worker entry point engines call).

Every failing campaign game comes with a reproduce command; a shrunk one
comes with a scenario file that holds only the faults its failure needs.
"""

from supervisors.harness.shrink.ddmin import ddmin
from supervisors.harness.shrink.game import (
    play_scenario,
    shrink_campaign_game,
    shrink_failure,
    shrink_failures,
    shrink_game,
    shrinkable,
    with_faults,
)
from supervisors.harness.shrink.schedule import (
    DEFAULT_MAX_RUNS,
    DEFAULT_RESOLUTION_S,
    MILDER,
    Failure,
    Played,
    ShrinkError,
    ShrinkOutcome,
    describe,
    shrink_schedule,
)
from supervisors.harness.shrink.toml import scenario_toml

__all__ = [
    "ddmin", "shrink_schedule", "shrink_game", "shrink_campaign_game", "play_scenario",
    "with_faults", "shrink_failure", "shrink_failures", "shrinkable", "scenario_toml", "describe",
    "Failure", "Played", "ShrinkError", "ShrinkOutcome", "MILDER", "DEFAULT_MAX_RUNS",
    "DEFAULT_RESOLUTION_S",
]
