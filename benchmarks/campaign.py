"""Campaign throughput: games per wall minute with 1 and with 2 worker processes.

Run as ``python -m benchmarks.campaign [--quick] [--games N] [--budget S]
[--no-probe | --probe-only]``, or ``python -m benchmarks.campaign --base DIR
[--games N] [--workers W] [--rounds R]`` for games per CPU minute of one
``hideseek campaign`` in this tree and in a base tree on disk, alternated, with
each game's trace hash compared (`benchmarks.side_by_side.compare_campaign`).
The same games (campaign seed 1, single faults, built-in rooms round-robin)
are played once by a pool of one ``spawn`` worker (the baseline) and once by
a pool of two; the figure is the ratio of games per wall minute (target
>= 1.8 on two otherwise idle cores). Each pool is started and warmed up
(imports done) before its clock starts. The pools get the games longest
expected first (`supervisors.harness.campaign.dispatch_order`), as ``hideseek
campaign`` does, so the two workers finish together.

The default is 24 games (three of each of the eight rooms): games differ
tenfold in length (empty ~3, furniture ~25 CPU s), and with few games the
end, when one worker has nothing left to play, weighs on the ratio.
``--quick`` plays 4 short games per run with a small mapping budget (games
then end early as failed: the figure is still throughput, not outcome).
``--budget S`` alone gives the same short games at any count.

Both runs play the same games (the same references): the benchmark checks
it by comparing each game's trace hash across the two runs.

Where the ratio falls short of 2 is split into three factors, exactly
(``ratio = 2 x busy x share x cpu``, each a 2-worker / 1-worker quotient):

- *busy*: the fraction of worker time spent in games (the rest is the
  end of the run, when a worker idles, and hand-over between games);
- *share*: CPU time a game got per wall second of it (below 1 when other
  processes took the cores);
- *cpu*: CPU seconds per game, paired by game (1 worker's / 2 workers'),
  below 1 when a game costs more CPU with two running.

The contention probe (skip with ``--no-probe``) says why a game can cost
more CPU with two running on two cores: it times the same fixed work alone
and as two processes at once, for pure Python arithmetic that stays in
the core's own caches (slower in pairs only if the cores themselves slow
down: a lower shared clock, or two virtual CPUs on one physical core) and
for a numpy stream over arrays larger than the core's L2 cache (slower in
pairs when shared cache or memory bandwidth is the limit), and for a walk
over a million Python objects in random order (a heap the size of a game's,
latency-bound: slower in pairs when the shared cache is what keeps it fast).
It reports CPU seconds per unit of work, pair / alone.

The table reports the CPUs this process may use and the load average
before and after each run (a load near or above the CPU count means other
work shared the cores). The last line printed is one JSON object with
every figure.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from typing import Any

from supervisors.harness.campaign import CampaignConfig, default_workers, run_campaign

_PROBE_KINDS = ("python", "memory", "objects")
_STREAM_MB = 64          # probe array size per process [MB] (L2 is a few MB per core)
_OBJECTS = 1_000_000     # probe: Python objects visited in random order (~100 MB, like a game)


def _warm(_: int) -> int:
    """Import what a game needs, so process start-up stays out of the timing."""
    import supervisors.harness.campaign  # noqa: F401, PLC0415

    time.sleep(0.2)  # keep this worker busy so the pool hands the next warm-up to another
    return os.getpid()


def _load() -> float:
    """The 1-minute load average (-1 where the OS does not tell)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return -1.0


def _measure(config: CampaignConfig, games: int, workers: int) -> dict[str, Any]:
    arrivals: list[float] = []
    results = []
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        pids = set(pool.map(_warm, range(workers), chunksize=1))
        load0 = _load()
        wall0 = time.perf_counter()
        for r in run_campaign(config, games, determinism_every=0, wall_timeout_s=None,
                              pool=pool):
            results.append(r)
            arrivals.append(time.perf_counter() - wall0)
        wall = time.perf_counter() - wall0
        load1 = _load()
    if len(pids) != workers:
        print(f"note: warm-up reached {len(pids)} of {workers} workers")
    # after the (n-W+k)-th result, k workers have nothing left to play
    n = len(results)
    idle = sum(wall - t for t in arrivals[max(n - workers, 0):n - 1])
    game_wall = sum(r["wall_s"] for r in results)
    cpu = sum(r.get("cpu_s", 0.0) for r in results)
    return {"games": n, "wall_s": wall, "games_per_min": 60.0 * n / wall,
            "sim_s": sum(r["sim_s"] for r in results),
            "game_wall_s": game_wall, "cpu_s": cpu,
            "busy": game_wall / (workers * wall), "share": cpu / game_wall,
            "tail_idle_s": idle,
            "found": sum(r["outcome"] == "found" for r in results),
            "load_before": load0, "load_after": load1,
            "cpu_by_index": {r["index"]: r.get("cpu_s", 0.0) for r in results},
            "hashes": {r["index"]: r["trace_hash"] for r in results}}


# ---------------------------------------------------------------------------- contention probe

def _work(job: tuple[str, int]) -> float:
    """CPU seconds this process spent on ``units`` of ``kind`` work."""
    kind, units = job
    cpu0 = time.process_time()
    if kind == "python":
        acc = 0
        for i in range(units * 1_000_000):
            acc = (acc + i * 7) & 0xFFFF
    elif kind == "objects":
        import numpy as np  # noqa: PLC0415

        order = np.random.default_rng(1).permutation(_OBJECTS).tolist()
        items = [{"x": float(i), "y": [i, i + 1]} for i in range(_OBJECTS)]
        cpu0 = time.process_time()  # building them is not the walk
        acc = 0.0
        step = _OBJECTS // 10  # a unit visits a tenth of them, about as long as the others
        for u in range(units):
            for i in order[(u % 10) * step:(u % 10 + 1) * step]:
                item = items[i]
                acc += item["x"] + item["y"][1]
    else:
        import numpy as np  # noqa: PLC0415

        a = np.ones(_STREAM_MB * 2**20 // 8)
        b = np.empty_like(a)
        cpu0 = time.process_time()  # the allocation is not the stream
        for _ in range(4 * units):  # about as long per unit as the python loop
            np.multiply(a, 1.0001, out=b)
            np.add(b, a, out=a)
    return time.process_time() - cpu0


def _probe(units: int) -> dict[str, dict[str, float]]:
    """CPU seconds per unit of work alone and as two processes at once, per kind."""
    out = {}
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        pool.map(_warm, range(2), chunksize=1)
        for kind in _PROBE_KINDS:
            alone = min(pool.apply(_work, ((kind, units),)) for _ in range(2))
            pair = min(min(pool.map(_work, [(kind, units)] * 2, chunksize=1))
                       for _ in range(2))
            out[kind] = {"alone_s": alone / units, "pair_s": pair / units,
                         "pair_over_alone": pair / alone}
    return out


# ---------------------------------------------------------------------------- report

def _print_probe(probe: dict[str, dict[str, float]], *, json_line: bool = True) -> None:
    print(f"\ncontention probe: CPU s per unit of work, alone and two processes at once "
          f"(load now {_load():.2f})")
    print(f"{'work':>8}{'alone [s]':>11}{'pair [s]':>10}{'pair/alone':>12}")
    for kind, p in probe.items():
        print(f"{kind:>8}{p['alone_s']:>11.4f}{p['pair_s']:>10.4f}"
              f"{p['pair_over_alone']:>12.3f}")
    print(f"python: arithmetic in the core's caches; memory: numpy stream over "
          f"{_STREAM_MB} MB arrays per process; objects: {_OBJECTS:,} Python objects "
          f"visited in random order (latency-bound, like a game's heap)")
    if json_line:
        print(json.dumps({"probe": {k: round(v["pair_over_alone"], 3)
                                    for k, v in probe.items()}, "load": round(_load(), 2)}))


def _parse_args(argv: list[str] | None) -> tuple[argparse.ArgumentParser, argparse.Namespace]:
    """The parser (for its errors) and the checked options."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.campaign")
    parser.add_argument("--quick", action="store_true", help="4 short games per run")
    parser.add_argument("--games", type=int, default=None, help="games per run (default 24)")
    parser.add_argument("--budget", type=float, default=None,
                        help="mapping budget [simulated s] (default 1200, 30 with --quick)")
    parser.add_argument("--base", default="",
                        help="a base tree on disk: games per CPU minute of the same campaign "
                             "there and here, alternated (default 200 games, 2 workers)")
    parser.add_argument("--workers", type=int, default=2, help="with --base: pool size")
    parser.add_argument("--rounds", type=int, default=1, help="with --base: runs per tree")
    probing = parser.add_mutually_exclusive_group()
    probing.add_argument("--no-probe", action="store_true",
                         help="skip the CPU contention probe")
    probing.add_argument("--probe-only", action="store_true",
                         help="only the CPU contention probe (a few seconds)")
    args = parser.parse_args(argv)
    if args.games is not None and not 1 <= args.games <= 10_000:
        parser.error(f"--games must be within 1..10000, got {args.games}")
    if args.budget is not None and not 0 < args.budget <= 1e6:
        parser.error(f"--budget must be within (0, 1e6] s, got {args.budget}")
    return parser, args


def main(argv: list[str] | None = None) -> None:
    parser, args = _parse_args(argv)
    if args.base:
        from benchmarks.side_by_side import compare_campaign  # noqa: PLC0415

        try:
            compare_campaign(args.base, args.games or 200, workers=args.workers,
                             rounds=args.rounds)
        except (ValueError, RuntimeError) as exc:
            parser.error(str(exc))
        return
    games = args.games or (4 if args.quick else 24)
    budget = args.budget or (30.0 if args.quick else 1200.0)
    config = CampaignConfig(1, mode="single", mapping_budget_s=budget)
    if args.probe_only:
        _print_probe(_probe(2 if args.quick else 8))
        return
    one = _measure(config, games, 1)
    two = _measure(config, games, 2)
    probe = None if args.no_probe else _probe(2 if args.quick else 8)
    _print_report(games, budget, default_workers(), one, two, probe)


def _print_report(games: int, budget: float, cpus: int, one: dict[str, Any],
                  two: dict[str, Any], probe: dict[str, Any] | None) -> None:
    """The table of the two runs (``one``: 1 worker, ``two``: 2), the ratio split into its
    factors, the probe's figures, and all of it as one JSON line."""
    ratio = two["games_per_min"] / one["games_per_min"]
    same = one["hashes"] == two["hashes"]
    paired = [one["cpu_by_index"][i] / two["cpu_by_index"][i] for i in one["cpu_by_index"]
              if two["cpu_by_index"].get(i, 0.0) > 0]
    cpu_factor = one["cpu_s"] / two["cpu_s"] if two["cpu_s"] > 0 else 0.0
    busy_factor = two["busy"] / one["busy"]
    share_factor = two["share"] / one["share"]
    print(f"campaign throughput, {games} games per run, mapping budget {budget:g} s, "
          f"{cpus} CPUs usable")
    print(f"{'workers':>8}{'wall [s]':>10}{'games/min':>11}{'sim s/wall s':>14}"
          f"{'busy':>7}{'tail idle [s]':>15}{'CPU s/game':>12}{'share':>7}{'found':>7}"
          f"{'load before':>13}{'load after':>12}")
    for n, m in ((1, one), (2, two)):
        print(f"{n:>8}{m['wall_s']:>10.1f}{m['games_per_min']:>11.2f}"
              f"{m['sim_s'] / m['wall_s']:>14.1f}{m['busy']:>7.3f}{m['tail_idle_s']:>15.1f}"
              f"{m['cpu_s'] / m['games']:>12.2f}{m['share']:>7.3f}"
              f"{m['found']:>7}{m['load_before']:>13.2f}{m['load_after']:>12.2f}")
    print("busy: game wall time / (workers x run wall time); tail idle: worker seconds "
          "with no game left to play; share: CPU s a game got per wall s of it (1 on idle "
          "cores)")
    print(f"same games in both runs (trace hashes by index): {'yes' if same else 'NO'}")
    print(f"ratio 2 workers / 1 worker: {ratio:.3f} = 2 x busy {busy_factor:.3f} x share "
          f"{share_factor:.3f} x CPU per game {cpu_factor:.3f} (target >= 1.8 on {cpus} "
          f"otherwise idle cores; load before/after the 2-worker run "
          f"{two['load_before']:.2f}/{two['load_after']:.2f})")
    if paired:
        paired.sort()
        print(f"CPU per game, 1 worker / 2 workers, paired by game: median "
              f"{paired[len(paired) // 2]:.3f}, range {paired[0]:.3f}..{paired[-1]:.3f}")
    if probe:
        _print_probe(probe, json_line=False)
    print(json.dumps({"games": games, "budget_s": budget, "cpus": cpus,
                      "games_per_min_1": round(one["games_per_min"], 3),
                      "games_per_min_2": round(two["games_per_min"], 3),
                      "ratio_2_over_1": round(ratio, 3),
                      "busy_factor": round(busy_factor, 4),
                      "share_factor": round(share_factor, 4),
                      "cpu_factor": round(cpu_factor, 4),
                      "busy_1": round(one["busy"], 4), "busy_2": round(two["busy"], 4),
                      "tail_idle_s_2": round(two["tail_idle_s"], 2),
                      "wall_s_1": round(one["wall_s"], 2), "wall_s_2": round(two["wall_s"], 2),
                      "load_1": [round(one["load_before"], 2), round(one["load_after"], 2)],
                      "load_2": [round(two["load_before"], 2), round(two["load_after"], 2)],
                      "cpu_s_per_game_1": round(one["cpu_s"] / one["games"], 3),
                      "cpu_s_per_game_2": round(two["cpu_s"] / two["games"], 3),
                      "cpu_per_wall_2": round(two["cpu_s"] / two["wall_s"], 3),
                      "probe": {k: round(v["pair_over_alone"], 3) for k, v in probe.items()}
                      if probe else None,
                      "same_games": same}))


if __name__ == "__main__":
    main()
