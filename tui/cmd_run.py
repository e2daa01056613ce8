"""``hideseek run``: one whole game, headless, in virtual time.

Exit status: 0 the hider was found, 1 it was not (or the game failed), 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import trio

from actors import JsonLinesRecorder, Trace, seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import Budget, GameReport, run_game
from tui import args as args_
from world.scenario import ScenarioError, builtin_scenarios, generate_scenario, load_scenario


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help=f"built-in name ({', '.join(builtin_scenarios())}) or a .toml file "
                             "(default: furniture)")
    parser.add_argument("--generated", metavar="SEED:INDEX",
                        help="a procedurally generated room instead of --scenario")
    parser.add_argument("--seed", type=args_.seed, default=1, help="the run's seed (default 1)")
    parser.add_argument("--campaign", metavar="S:I[,...]",
                        help="game I of fault campaign S, as `hideseek campaign` printed it "
                             "(room, faults, seed and budget all come from it)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--db", type=args_.sqlite_file, default=":memory:",
                        help="SQLite file for the server's store")
    parser.add_argument("--trace", metavar="FILE", help="record the trace as JSON lines")
    parser.add_argument("--budget", type=args_.positive_seconds, default=1200.0,
                        help="simulated seconds allowed for mapping (default 1200)")


def _scenario(args: argparse.Namespace):
    if args.generated:
        try:
            seed, index = (int(v) for v in args.generated.split(":"))
        except ValueError:
            raise ScenarioError(f"--generated must be SEED:INDEX, got {args.generated!r}") from None
        return generate_scenario(seed, index)
    return load_scenario(args.scenario)


def print_summary(r: GameReport) -> None:
    """The human-readable summary of a game (also `hideseek play --auto`'s)."""
    def pct(v: float | None) -> str:
        return "-" if v is None else f"{100 * v:.1f} %"

    def sec(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f} s"

    print(f"\n{r.scenario} seed {r.seed}: {r.outcome.upper()}"
          + (f" ({r.reason})" if r.reason else ""))
    print(f"  simulated {r.sim_seconds:.1f} s in {r.wall_seconds:.1f} s wall "
          f"({r.real_time_factor:.0f}x real time)")
    print(f"  map: coverage {pct(r.coverage)}, accuracy {pct(r.accuracy)}, "
          f"T90 {sec(r.t90_s)}, T99 {sec(r.t99_s)}, mapper path {r.path_cm / 100:.1f} m")
    print("  phases: " + ", ".join(f"{k} {v:.1f} s" for k, v in r.phases.items()))
    print(f"  guesses {r.guesses}, restarts {r.restarts}, faults {r.faults}, "
          f"dropped {r.dropped}, resent {r.resent}, messages {r.messages}")
    print(f"  trace hash {r.trace_hash}")


def run(args: argparse.Namespace) -> int:
    try:
        if args.campaign:
            from supervisors.harness.campaign import (  # noqa: PLC0415 - only when asked
                game_from_ref,
                seed_game_scheduler,
            )
            scenario, args.seed, args.budget = game_from_ref(args.campaign)
            seed_game_scheduler(args.seed)  # the campaign's scheduling, so the same trace hash
        else:
            scenario = _scenario(args)
    except (ScenarioError, OSError) as exc:
        print(f"hideseek run: {exc}", file=sys.stderr)
        return 2
    trace = Trace()
    trace_file = None
    if args.trace:
        try:
            trace_file = open(args.trace, "w")  # noqa: SIM115 (closed below)
        except OSError as exc:
            print(f"hideseek run: cannot write trace: {exc}", file=sys.stderr)
            return 2
        trace.subscribe(JsonLinesRecorder(trace_file))
    budget = Budget(mapping=args.budget)
    if not args.json:
        print(f"running {scenario.name} (seed {args.seed}) in virtual time ...", flush=True)
    seed_trio_scheduler(args.seed)
    wall0 = time.perf_counter()  # wall time is measured for the report only
    report = trio.run(lambda: run_game(scenario, args.seed, db=args.db, budget=budget,
                                       trace=trace), clock=virtual_clock())
    report.wall_seconds = time.perf_counter() - wall0
    report.real_time_factor = report.sim_seconds / max(report.wall_seconds, 1e-9)
    if trace_file is not None:
        trace_file.close()
    return print_report(report, as_json=args.json)


def print_report(report: GameReport, *, as_json: bool) -> int:
    """Print a finished game as ``hideseek run`` does (one JSON object, or its events and
    a summary); returns the exit status: 0 the hider was found, else 1."""
    if as_json:
        print(json.dumps(report.to_json()))
    else:
        for line in report.events:
            print("  " + line)
        print_summary(report)
    return 0 if report.outcome == "found" else 1
