"""Campaign throughput: games per wall minute with 1 and with 2 worker processes.

Run as ``python -m benchmarks.campaign [--quick] [--games N] [--budget S]``.
The same games (campaign seed 1, single faults, built-in rooms round-robin)
are played once by a pool of one ``spawn`` worker (the baseline) and once by
a pool of two; the figure is the ratio of games per wall minute (target
>= 1.8 on two otherwise idle cores). The ratio
measures how well games spread over workers: each pool is started and
warmed up (imports done) before its clock starts.

``--quick`` plays 4 short games per run with a small mapping budget (games
then end early as failed: the figure is still throughput, not outcome).
``--budget S`` alone gives the same short games at any count.

Both runs play the same games (the same references): the benchmark checks
it by comparing each game's trace hash across the two runs. Because the
ratio means nothing on a busy machine, the table reports the CPUs this
process may use and the load average before and after each run (a load
near or above the CPU count means other work shared the cores).

The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from typing import Any

from supervisors.campaign import CampaignConfig, default_workers, run_campaign


def _warm(_: int) -> int:
    """Import what a game needs, so process start-up stays out of the timing."""
    import supervisors.campaign  # noqa: F401, PLC0415

    time.sleep(0.2)  # keep this worker busy so the pool hands the next warm-up to another
    return os.getpid()


def _load() -> float:
    """The 1-minute load average (-1 where the OS does not tell)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return -1.0


def _measure(config: CampaignConfig, games: int, workers: int) -> dict[str, Any]:
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        pids = set(pool.map(_warm, range(workers), chunksize=1))
        load0 = _load()
        wall0 = time.perf_counter()
        results = list(run_campaign(config, games, determinism_every=0, wall_timeout_s=None,
                                    pool=pool))
        wall = time.perf_counter() - wall0
        load1 = _load()
    if len(pids) != workers:
        print(f"note: warm-up reached {len(pids)} of {workers} workers")
    return {"games": len(results), "wall_s": wall, "games_per_min": 60.0 * len(results) / wall,
            "sim_s": sum(r["sim_s"] for r in results),
            "game_wall_s": sum(r["wall_s"] for r in results),
            "cpu_s": sum(r.get("cpu_s", 0.0) for r in results),
            "found": sum(r["outcome"] == "found" for r in results),
            "load_before": load0, "load_after": load1,
            "hashes": {r["index"]: r["trace_hash"] for r in results}}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.campaign")
    parser.add_argument("--quick", action="store_true", help="4 short games per run")
    parser.add_argument("--games", type=int, default=None, help="games per run (default 8)")
    parser.add_argument("--budget", type=float, default=None,
                        help="mapping budget [simulated s] (default 1200, 30 with --quick)")
    args = parser.parse_args(argv)
    if args.games is not None and not 1 <= args.games <= 10_000:
        parser.error(f"--games must be within 1..10000, got {args.games}")
    if args.budget is not None and not 0 < args.budget <= 1e6:
        parser.error(f"--budget must be within (0, 1e6] s, got {args.budget}")
    games = args.games or (4 if args.quick else 8)
    budget = args.budget or (30.0 if args.quick else 1200.0)
    config = CampaignConfig(1, mode="single", mapping_budget_s=budget)
    cpus = default_workers()
    one = _measure(config, games, 1)
    two = _measure(config, games, 2)
    ratio = two["games_per_min"] / one["games_per_min"]
    same = one["hashes"] == two["hashes"]
    print(f"campaign throughput, {games} games per run, mapping budget {budget:g} s, "
          f"{cpus} CPUs usable")
    print(f"{'workers':>8}{'wall [s]':>10}{'games/min':>11}{'sim s/wall s':>14}"
          f"{'game s/wall s':>15}{'CPU s/game':>12}{'CPU s/wall s':>14}{'found':>7}"
          f"{'load before':>13}{'load after':>12}")
    for n, m in ((1, one), (2, two)):
        print(f"{n:>8}{m['wall_s']:>10.1f}{m['games_per_min']:>11.2f}"
              f"{m['sim_s'] / m['wall_s']:>14.1f}{m['game_wall_s'] / m['wall_s']:>15.2f}"
              f"{m['cpu_s'] / m['games']:>12.2f}{m['cpu_s'] / m['wall_s']:>14.2f}"
              f"{m['found']:>7}{m['load_before']:>13.2f}{m['load_after']:>12.2f}")
    print("game s/wall s: the games' own wall time summed over the run's wall time (workers "
          "kept busy); CPU s/wall s: the CPU the games got (2 on two idle cores); CPU s/game "
          "equal in both runs means the pool adds no work")
    print(f"same games in both runs (trace hashes by index): {'yes' if same else 'NO'}")
    print(f"ratio 2 workers / 1 worker: {ratio:.2f} (target >= 1.8 on {cpus} otherwise idle "
          f"cores; load before/after the 2-worker run {two['load_before']:.2f}/"
          f"{two['load_after']:.2f})")
    print(json.dumps({"games": games, "budget_s": budget, "cpus": cpus,
                      "games_per_min_1": round(one["games_per_min"], 3),
                      "games_per_min_2": round(two["games_per_min"], 3),
                      "ratio_2_over_1": round(ratio, 3),
                      "wall_s_1": round(one["wall_s"], 2), "wall_s_2": round(two["wall_s"], 2),
                      "load_1": [round(one["load_before"], 2), round(one["load_after"], 2)],
                      "load_2": [round(two["load_before"], 2), round(two["load_after"], 2)],
                      "cpu_s_per_game_1": round(one["cpu_s"] / one["games"], 3),
                      "cpu_s_per_game_2": round(two["cpu_s"] / two["games"], 3),
                      "cpu_per_wall_2": round(two["cpu_s"] / two["wall_s"], 3),
                      "same_games": same}))


if __name__ == "__main__":
    main()
