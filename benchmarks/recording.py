"""What recording costs a game, in speed and file size, against unrecorded plays.

Run as ``python -m benchmarks.recording [--scenario furniture] [--seed 1] [--rounds 2]``.

Each round plays the same game twice in this process, unrecorded then
recorded (`supervisors.recording.Recorder` as a run observer), in virtual time
as ``hideseek run`` plays it, and measures each play's CPU time
(``time.process_time``: on a shared machine wall time measures the load as
much as the game) and wall time. The cost is the recorded play's CPU time over
the unrecorded one's, minus one, taken as the median over the rounds; the
limit is 15 %. The file size of the recorded game is compared with its limit
of 20 MB for a furniture game. The trace hashes of the two plays must be equal
(recording does not change the game). The last line printed is one JSON
object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from typing import Any

import trio

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import run_game
from supervisors.recording import Recorder, RunInfo
from supervisors.recording.runinfo import scenario_text
from world.scenario import load_scenario

LIMITS = {"cost": 0.15, "size_mb": 20.0}
"""Recording costs at most 15 % of a game's speed; a furniture game's file is at most 20 MB."""


def play(scenario: Any, seed: int, path: str | None) -> dict[str, Any]:
    """One game, recorded into ``path`` (None: not recorded); its times and hash."""
    observers = []
    if path is not None:
        observers.append(Recorder(path, RunInfo.for_scenario(scenario, seed),
                                  scenario_toml=scenario_text(scenario)))
    seed_trio_scheduler(seed)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    report = trio.run(lambda: run_game(scenario, seed, observers=observers),
                      clock=virtual_clock())
    return {"cpu_s": time.process_time() - cpu0, "wall_s": time.perf_counter() - wall0,
            "sim_s": report.sim_seconds, "hash": report.trace_hash,
            "outcome": report.outcome, "messages": report.messages}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="furniture")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rounds", type=int, default=2, help="plays of each kind (default 2)")
    args = parser.parse_args(argv)
    if not 1 <= args.rounds <= 20:
        print("--rounds must be within 1..20", file=sys.stderr)
        return 2
    scenario = load_scenario(args.scenario)
    costs, wall_costs, size = [], [], 0
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "game.mcap")
        for i in range(args.rounds):
            plain = play(scenario, args.seed, None)
            recorded = play(scenario, args.seed, path)
            size = os.path.getsize(path)
            if recorded["hash"] != plain["hash"]:
                print(f"recording changed the game: {recorded['hash']} != {plain['hash']}",
                      file=sys.stderr)
                return 1
            costs.append(recorded["cpu_s"] / plain["cpu_s"] - 1.0)
            wall_costs.append(recorded["wall_s"] / plain["wall_s"] - 1.0)
            print(f"round {i + 1}: unrecorded {plain['cpu_s']:.2f} CPU s "
                  f"({plain['wall_s']:.2f} wall), recorded {recorded['cpu_s']:.2f} CPU s "
                  f"({recorded['wall_s']:.2f} wall): cost {100 * costs[-1]:+.1f} % CPU, "
                  f"{100 * wall_costs[-1]:+.1f} % wall; file {size / 1e6:.2f} MB", flush=True)
    cost = statistics.median(costs)
    result = {"scenario": args.scenario, "seed": args.seed, "rounds": args.rounds,
              "sim_s": plain["sim_s"], "messages": plain["messages"], "outcome": plain["outcome"],
              "cost_cpu": round(cost, 4), "cost_wall": round(statistics.median(wall_costs), 4),
              "file_mb": round(size / 1e6, 3), "load": os.getloadavg()[0],
              "limits": LIMITS, "within": cost <= LIMITS["cost"] and
              size / 1e6 <= LIMITS["size_mb"]}
    print(f"{args.scenario} seed {args.seed}: recording costs {100 * cost:+.1f} % CPU "
          f"(limit {100 * LIMITS['cost']:.0f} %), file {size / 1e6:.2f} MB "
          f"(limit {LIMITS['size_mb']:.0f} MB)")
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
