"""Running a campaign: which games, in which order, on which engine.

`run_campaign` checks the options, orders the games (`dispatch_order`:
longest expected first, in blocks) and hands them to an engine: in this
process (index order), or the local pool of `supervisors.harness.campaign.local`.
Results arrive in completion order, keyed by index; `summarize` and
`CampaignStore` take them from there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from supervisors.harness.campaign.dispatch import dispatch_order, is_replayed
from supervisors.harness.campaign.local import Job, call, default_workers, play_in_pool
from supervisors.harness.campaign.play import play_campaign_game
from supervisors.harness.campaign.refs import MAX_GAMES, CampaignConfig, CampaignError


def run_campaign(config: CampaignConfig, games: int, *, workers: int | None = None,
                 worker: Callable[..., dict[str, Any]] = play_campaign_game,
                 determinism_every: int = 10, wall_timeout_s: float | None = 600.0,
                 start: int = 0, pool: Any = None) -> Iterator[dict[str, Any]]:
    """Play games ``start .. start+games-1`` of a campaign; yield results as they finish.

    A pool gets the games in `dispatch_order` (longest expected first, in
    blocks); in this process they are played in index order. Either way each
    game is played once and its result carries its ``index``.

    Args:
        config: the campaign.
        games: how many games (1..`MAX_GAMES`).
        workers: worker processes (default: one per core); 0 plays in this
            process (debugging, tests).
        worker: the entry point (`play_campaign_game`; tests pass stand-ins,
            which must be module-level functions for the ``spawn`` pool).
        determinism_every: replay every n-th game to compare trace hashes
            (0: never).
        wall_timeout_s: guard per play [s] (see `play_campaign_game`).
        start: index of the first game.
        pool: an already started ``multiprocessing`` pool to use (``workers``
            is then ignored); benchmarks pass a warmed-up one.

    Raises:
        CampaignError: a bad count.
    """
    if isinstance(games, bool) or not isinstance(games, int) or not 1 <= games <= MAX_GAMES:
        raise CampaignError(f"games must be within 1..{MAX_GAMES}, got {games!r}")
    if workers is not None and (not isinstance(workers, int) or not 0 <= workers <= 256):
        raise CampaignError(f"workers must be within 0..256, got {workers!r}")
    if not isinstance(determinism_every, int) or determinism_every < 0:
        raise CampaignError(f"determinism_every must be >= 0, got {determinism_every!r}")
    n = default_workers() if workers is None else workers

    def job(i: int) -> Job:
        return (worker, config.game_ref(i), is_replayed(i, determinism_every), wall_timeout_s)

    if pool is None and n == 0:  # in this process: index order, easiest to follow
        for i in range(start, start + games):
            yield call(job(i))
        return
    jobs = (job(i) for i in dispatch_order(config, start, games, determinism_every))
    yield from play_in_pool(jobs, min(n, games), pool=pool)
