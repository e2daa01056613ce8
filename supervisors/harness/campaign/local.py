"""The local engine: a pool of ``spawn`` worker processes on this machine.

Each worker process plays games one at a time, each in a fresh Trio run
(`play_campaign_game`), so nothing a game leaves behind steers the next;
workers are recycled now and then all the same, since a game stopped by its
guard may leave garbage.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

#: one job: (entry point, game reference, replay for determinism, guard [s])
Job = tuple[Callable[..., dict[str, Any]], str, bool, float | None]
_RECYCLE_EVERY = 100        # games a worker process plays before it is replaced


def call(job: Job) -> dict[str, Any]:
    """Play one job (the pool's task; module-level, so ``spawn`` workers can unpickle it)."""
    worker, ref, determinism, wall_timeout_s = job
    return worker(ref, determinism=determinism, wall_timeout_s=wall_timeout_s)


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def play_in_pool(jobs: Iterable[Job], workers: int, *, pool: Any = None
                 ) -> Iterator[dict[str, Any]]:
    """Play ``jobs`` on ``workers`` processes (or on ``pool``); yield results as they finish.

    Closing the generator stops the pool it started: games in flight are
    abandoned.
    """
    if pool is not None:
        yield from pool.imap_unordered(call, jobs, chunksize=1)
        return
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(workers, maxtasksperchild=_RECYCLE_EVERY) as started:
        yield from started.imap_unordered(call, jobs, chunksize=1)
