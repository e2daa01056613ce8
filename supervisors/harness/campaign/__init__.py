"""Fault campaigns: many seeded games under random faults, invariants checked.

In the spirit of FoundationDB's simulation testing and TigerBeetle's VOPR:
game ``i`` of campaign ``S`` is a pure function of ``(S, i)`` and the
campaign's options, so every failure is reproducible from a short
reference, ``S:i[,key=value...]``, which ``hideseek run --campaign REF``
accepts and plays with the same trace hash.

The package, bottom up (each module imports only those above it):

- `refs`: the options (`CampaignConfig`) and game references;
- `plan`: the game a reference names (`plan_game`: run seed, room, faults);
- `dispatch`: which game to start first (longest expected first);
- `play`: one game with its probes and invariant checks
  (`play_campaign_game`, the worker entry point every engine calls);
- `local` and `cluster`: the engines, a local process pool and Ray
  (`engines.open_engine` makes one by name);
- `run`: `run_campaign`, which orders the games and hands them to an engine;
- `summary` and `store`: the JSON summary and the SQLite results.

The names below are the package's promise; everything else is importable
but may move.
"""

from supervisors.harness.campaign.dispatch import (
    ORDER_BLOCK,
    ROOM_CPU_S,
    dispatch_order,
    expected_cpu_s,
)
from supervisors.harness.campaign.engines import ENGINES, open_engine
from supervisors.harness.campaign.local import default_workers
from supervisors.harness.campaign.plan import (
    ACTORS_BY_ROLE,
    GameSpec,
    game_from_ref,
    plan_game,
)
from supervisors.harness.campaign.play import (
    WALL_GUARD_FACTOR,
    play_campaign_game,
    play_checked,
    seed_game_scheduler,
)
from supervisors.harness.campaign.refs import (
    FAULT_LABELS,
    MAX_GAMES,
    MODES,
    CampaignConfig,
    CampaignError,
    parse_game_ref,
    select_kinds,
)
from supervisors.harness.campaign.run import run_campaign
from supervisors.harness.campaign.store import CampaignStore
from supervisors.harness.campaign.summary import summarize

__all__ = [
    "FAULT_LABELS", "MODES", "CampaignError", "CampaignConfig", "GameSpec", "plan_game",
    "parse_game_ref", "game_from_ref", "select_kinds", "play_campaign_game", "play_checked",
    "run_campaign", "summarize", "CampaignStore", "ACTORS_BY_ROLE", "default_workers",
    "MAX_GAMES", "seed_game_scheduler", "ROOM_CPU_S", "ORDER_BLOCK", "expected_cpu_s",
    "dispatch_order", "WALL_GUARD_FACTOR", "ENGINES", "open_engine",
]
