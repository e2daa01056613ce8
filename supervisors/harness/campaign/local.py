"""The local engine: a pool of ``spawn`` worker processes on this machine.

Each worker process plays games one at a time, each in a fresh Trio run
(`play_campaign_game`), so nothing a game leaves behind steers the next;
workers are recycled now and then all the same, since a game stopped by its
guard may leave garbage. A worker imports a game's modules once, when it
starts (`start_worker`), and freezes them out of the cyclic collector, as the
command line does for its one game.
"""

from __future__ import annotations

import gc
import importlib
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

#: one job: (module-level entry point, positional arguments, keyword arguments)
Job = tuple[Callable[..., dict[str, Any]], tuple[Any, ...], dict[str, Any]]
#: games a worker process plays before it is replaced (the Ray engine's ``max_calls`` too)
RECYCLE_EVERY = 100


def call(job: Job) -> dict[str, Any]:
    """Run one job (an engine's task; module-level, so workers can unpickle it by name)."""
    fn, args, kwargs = job
    return fn(*args, **kwargs)


def start_worker() -> None:
    """A pool worker's start: import what a game runs with the cyclic collector paused,
    then freeze those objects (`gc.freeze`).

    Why: the modules of a game (the firmware, the world, the runtime, numpy and
    Trio) are some hundred thousand objects that live as long as the worker; left in
    the collector's generations, every full collection of every game walks them again
    and frees none. Importing them here, not in the first game, also keeps the first
    game's CPU time its own. Nothing a game computes depends on the collector, so the
    games are the same.
    """
    gc.disable()
    try:
        importlib.import_module("supervisors.harness.campaign.play")
        rover = importlib.import_module("supervisors.rover")
        rover._default_nav_factory()  # noqa: SLF001 - imports navigation, as a game's start does
        importlib.import_module("world.scenario").builtin_scenarios()
    finally:
        gc.freeze()
        gc.enable()


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class LocalEngine:
    """Jobs on a pool of local ``spawn`` processes, results as they finish.

    Args:
        workers: worker processes (>= 1).
        pool: an already started ``multiprocessing`` pool to use instead
            (``workers`` then only reports its size); benchmarks pass a
            warmed-up one.
    """

    name = "local"

    def __init__(self, workers: int, *, pool: Any = None) -> None:
        self.workers, self._pool = workers, pool

    def map(self, jobs: Iterable[Job], *,
            lost: Callable[[Job, BaseException], dict[str, Any]] | None = None
            ) -> Iterator[dict[str, Any]]:
        """Run ``jobs``; yield each result as it finishes.

        ``lost`` is the Ray engine's (a pool whose worker dies fails the
        ``multiprocessing`` way). Closing the generator stops the pool it
        started: jobs in flight are abandoned.
        """
        if self._pool is not None:
            yield from self._pool.imap_unordered(call, jobs, chunksize=1)
            return
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(self.workers, initializer=start_worker,
                      maxtasksperchild=RECYCLE_EVERY) as started:
            yield from started.imap_unordered(call, jobs, chunksize=1)

    def close(self) -> None:
        """Nothing to release: each `map` owns its pool."""

    def __enter__(self) -> LocalEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
