"""Campaign engines compared: games per wall minute on the local pool and on Ray.

Run as ``python -m benchmarks.engines [--games N] [--budget S] [--rooms A,B]``.
The same games (campaign seed 1, single faults, default: the empty room and
the corridor with a 30 s mapping budget, so games are short and the
engines' own costs show) are played four times: by the local ``spawn`` pool
with 1 and with 2 workers, and by a local Ray instance with 1 and with 2
CPUs. Each engine is started and warmed up (imports done, workers up) before
its clock starts; start-up is reported apart.

Ray's overhead per game is reported two ways: with one worker, each
engine's cost per game is the run's wall time per game less the game's own
wall time (submission, scheduling, argument and result transfer), and
Ray's overhead is its cost less the pool's; and a no-op task's round trip
(``ray.get(f.remote())`` of a function doing nothing, one at a time). The
runs are interleaved (pool 1, Ray 1, pool 2, Ray 2) so a drifting load
weighs on both engines alike. The table reports the load average before and
after each run (a load near or above the CPU count means other work shared
the cores). The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from typing import Any

from supervisors.harness.campaign import CampaignConfig, default_workers, run_campaign
from supervisors.harness.campaign.cluster import RayEngine
from supervisors.harness.campaign.local import LocalEngine

_NOOPS = 200  # no-op tasks timed for the round trip


def _warm(_: int) -> int:
    """Import what a game needs, so process start-up stays out of the timing."""
    import supervisors.harness.campaign  # noqa: F401, PLC0415

    time.sleep(0.2)  # keep this worker busy so the next warm-up goes to another
    return os.getpid()


def _noop() -> int:
    return 0


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return -1.0


def _play(config: CampaignConfig, games: int, engine: Any) -> dict[str, Any]:
    load0, wall0 = _load(), time.perf_counter()
    results = list(run_campaign(config, games, engine=engine, determinism_every=0,
                                wall_timeout_s=None))
    wall = time.perf_counter() - wall0
    return {"wall_s": wall, "games_per_min": 60.0 * len(results) / wall,
            "game_wall_s": sum(r["wall_s"] for r in results) / len(results),
            "load": [round(load0, 2), round(_load(), 2)],
            "hashes": {r["index"]: r["trace_hash"] for r in results}}


def _local(config: CampaignConfig, games: int, workers: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        pool.map(_warm, range(workers), chunksize=1)
        start = time.perf_counter() - t0
        out = _play(config, games, LocalEngine(workers, pool=pool))
    return out | {"start_s": start}


def _ray(config: CampaignConfig, games: int, workers: int) -> dict[str, Any]:
    import ray  # noqa: PLC0415

    t0 = time.perf_counter()
    with RayEngine(workers=workers) as engine:
        warm = ray.remote(num_cpus=1)(_warm)
        ray.get([warm.remote(i) for i in range(workers)])
        start = time.perf_counter() - t0
        out = _play(config, games, engine)
        noop = ray.remote(num_cpus=1)(_noop)
        ray.get(noop.remote())
        t1 = time.perf_counter()
        for _ in range(_NOOPS):
            ray.get(noop.remote())
        round_trip = (time.perf_counter() - t1) / _NOOPS
    return out | {"start_s": start, "noop_round_trip_s": round_trip}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.engines")
    parser.add_argument("--games", type=int, default=12, help="games per run (default 12)")
    parser.add_argument("--budget", type=float, default=30.0,
                        help="mapping budget [simulated s] (default 30: short games)")
    parser.add_argument("--rooms", default="empty,corridor", help="built-in rooms, round-robin")
    args = parser.parse_args(argv)
    if not 1 <= args.games <= 10_000:
        parser.error(f"--games must be within 1..10000, got {args.games}")
    config = CampaignConfig(1, mode="single", mapping_budget_s=args.budget,
                            rooms=tuple(args.rooms.split(",")))
    runs = {f"{name}_{n}": run(config, args.games, n)  # interleaved: load drifts
            for n in (1, 2) for name, run in (("local", _local), ("ray", _ray))}
    base = runs["local_1"]["hashes"]
    same = all(r["hashes"] == base for r in runs.values())
    print(f"campaign engines, {args.games} games per run ({args.rooms}, mapping budget "
          f"{args.budget:g} s), {default_workers()} CPUs usable")
    print(f"{'engine':>8}{'workers':>8}{'start [s]':>11}{'wall [s]':>10}{'games/min':>11}"
          f"{'game wall [s]':>15}{'load before/after':>19}")
    for key, r in runs.items():
        name, n = key.split("_")
        print(f"{name:>8}{n:>8}{r['start_s']:>11.1f}{r['wall_s']:>10.1f}"
              f"{r['games_per_min']:>11.1f}{r['game_wall_s']:>15.2f}"
              f"{r['load'][0]:>10.2f}/{r['load'][1]:.2f}")
    # with one worker, run wall time not spent inside games is the engine's own cost
    cost = {k: runs[f"{k}_1"]["wall_s"] / args.games - runs[f"{k}_1"]["game_wall_s"]
            for k in ("local", "ray")}
    overhead = cost["ray"] - cost["local"]
    noop = runs["ray_1"]["noop_round_trip_s"]
    print(f"engine cost per game, 1 worker (run wall / games - game wall): local "
          f"{1000 * cost['local']:.0f} ms, ray {1000 * cost['ray']:.0f} ms; Ray's overhead "
          f"per game {1000 * overhead:.0f} ms; no-op task round trip {1000 * noop:.2f} ms")
    print(f"same games on every engine (trace hashes by index): {'yes' if same else 'NO'}")
    print(json.dumps({"games": args.games, "budget_s": args.budget, "rooms": args.rooms,
                      "cpus": default_workers(),
                      **{f"games_per_min_{k}": round(r["games_per_min"], 2)
                         for k, r in runs.items()},
                      **{f"start_s_{k}": round(r["start_s"], 2) for k, r in runs.items()},
                      **{f"load_{k}": r["load"] for k, r in runs.items()},
                      "engine_cost_per_game_s": {k: round(v, 4) for k, v in cost.items()},
                      "ray_overhead_per_game_s": round(overhead, 4),
                      "ray_noop_round_trip_s": round(noop, 5), "same_games": same}))


if __name__ == "__main__":
    main()
