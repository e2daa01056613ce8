"""Engines: where a campaign's jobs run (the local process pool, or Ray).

An engine has ``name``, ``workers`` (how many jobs run at once),
``map(jobs, lost=None)`` (yields each job's result as it finishes) and
``close()``; `open_engine` makes one by name. Every engine calls the same
module-level entry points (`play_campaign_game`, and
`supervisors.harness.shrink.shrink_campaign_game` for ``--shrink``), so a
game gives the same trace hash on either.
"""

from __future__ import annotations

from typing import Any

from supervisors.harness.campaign.cluster import RayEngine
from supervisors.harness.campaign.local import LocalEngine, default_workers
from supervisors.harness.campaign.refs import CampaignError

ENGINES = ("local", "ray")


def open_engine(name: str, *, workers: int | None = None, address: str | None = None,
                pool: Any = None) -> LocalEngine | RayEngine:
    """The engine called ``name``, started (close it, or use it in a ``with``).

    Args:
        name: ``local`` or ``ray``.
        workers: local worker processes, or the local Ray instance's CPUs
            (default one per core).
        address: the Ray cluster to join (``ray`` only).
        pool: a started ``multiprocessing`` pool (``local`` only; benchmarks).

    Raises:
        CampaignError: an unknown name, an address for the local engine, Ray
            missing or unreachable.
    """
    if name not in ENGINES:
        raise CampaignError(f"engine must be {' or '.join(ENGINES)}, got {name!r}")
    if name == "local":
        if address:
            raise CampaignError("--address needs --engine ray")
        return LocalEngine(workers or default_workers(), pool=pool)
    return RayEngine(address, workers)
