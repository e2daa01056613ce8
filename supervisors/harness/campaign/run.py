"""Running a campaign: which games, in which order, on which engine.

`run_campaign` checks the options, orders the games (`dispatch_order`:
longest expected first, in blocks) and hands them to an engine
(`supervisors.harness.campaign.engines`: the local process pool, or Ray), or
plays them in this process in index order. Results arrive in completion
order, keyed by index; `summarize` and `CampaignStore` take them from there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from supervisors.harness.campaign.dispatch import dispatch_order, is_replayed
from supervisors.harness.campaign.engines import open_engine
from supervisors.harness.campaign.local import Job, call, default_workers
from supervisors.harness.campaign.play import lost_result, play_campaign_game
from supervisors.harness.campaign.refs import MAX_GAMES, CampaignConfig, CampaignError


def run_campaign(config: CampaignConfig, games: int, *, workers: int | None = None,
                 worker: Callable[..., dict[str, Any]] = play_campaign_game,
                 determinism_every: int = 10, wall_timeout_s: float | None = 600.0,
                 start: int = 0, pool: Any = None, engine: Any = None
                 ) -> Iterator[dict[str, Any]]:
    """Play games ``start .. start+games-1`` of a campaign; yield results as they finish.

    An engine gets the games in `dispatch_order` (longest expected first, in
    blocks); in this process they are played in index order. Either way each
    game is played once and its result carries its ``index``.

    Args:
        config: the campaign.
        games: how many games (1..`MAX_GAMES`).
        workers: worker processes (default: one per core); 0 plays in this
            process (debugging, tests). Ignored when ``engine`` is given.
        worker: the entry point (`play_campaign_game`; tests pass stand-ins,
            which must be module-level functions for the ``spawn`` pool).
        determinism_every: replay every n-th game to compare trace hashes
            (0: never).
        wall_timeout_s: guard per play [s] (see `play_campaign_game`).
        start: index of the first game.
        pool: an already started ``multiprocessing`` pool to use (``workers``
            is then ignored); benchmarks pass a warmed-up one.
        engine: an engine from `open_engine` (the caller closes it); default
            the local pool.

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
        return (worker, (config.game_ref(i),),
                {"determinism": is_replayed(i, determinism_every),
                 "wall_timeout_s": wall_timeout_s})

    if engine is None and pool is None and n == 0:  # in this process: index order
        for i in range(start, start + games):
            yield call(job(i))
        return
    jobs = (job(i) for i in dispatch_order(config, start, games, determinism_every))
    if engine is None:
        engine = open_engine("local", workers=min(n, games) or 1, pool=pool)
    yield from engine.map(jobs, lost=_lost)


def _lost(job: Job, exc: BaseException) -> dict[str, Any]:
    """A game whose task the engine gave up on, as a failed result."""
    return lost_result(job[1][0], f"{type(exc).__name__}: {str(exc)[:200]}")
