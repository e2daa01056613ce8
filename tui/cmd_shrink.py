"""``hideseek shrink``: a failing game's fault schedule shrunk to what its failure needs.

The game is a campaign game (``--campaign S:I[,...]``, as ``hideseek
campaign`` printed it) or a scenario file with faults (``--scenario FILE
--seed N``). The shrunk game is written as a scenario file (``--out``) that
``hideseek run --scenario FILE --seed N`` plays with the same outcome; the
report gives the original schedule, the shrunk one, each step kept and the
runs spent (at most ``--max-runs`` games, each in virtual time).

Exit status: 0 shrunk, and the written file fails the same way; 1 the file
did not (a bug worth reporting: shrinking assumes deterministic games);
2 bad input (no such game reference or file, a game that does not fail,
an ``--out`` that cannot be written).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from supervisors.harness.campaign import CampaignError
from supervisors.harness.shrink import (
    DEFAULT_MAX_RUNS,
    DEFAULT_RESOLUTION_S,
    ShrinkError,
    shrink_campaign_game,
    shrink_game,
)
from tui.progress import progress_bar
from world.scenario import ScenarioError, load_scenario


def add_arguments(parser: argparse.ArgumentParser) -> None:
    game = parser.add_mutually_exclusive_group(required=True)
    game.add_argument("--campaign", metavar="S:I[,...]",
                      help="game I of fault campaign S, as `hideseek campaign` printed it")
    game.add_argument("--scenario", metavar="NAME|FILE",
                      help="a scenario with a [[faults]] schedule (a .toml file or built-in name)")
    parser.add_argument("--seed", type=int, default=1,
                        help="the run's seed with --scenario (default 1)")
    parser.add_argument("--budget", type=float, default=1200.0,
                        help="simulated seconds allowed for mapping with --scenario "
                             "(default 1200; a campaign game brings its own)")
    parser.add_argument("--out", required=True, metavar="FILE.toml",
                        help="where to write the shrunk scenario")
    parser.add_argument("--max-runs", type=int, default=DEFAULT_MAX_RUNS, metavar="N",
                        help=f"games to play at most (default {DEFAULT_MAX_RUNS})")
    parser.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION_S, metavar="S",
                        help="how closely starts and durations are bisected [simulated s] "
                             f"(default {DEFAULT_RESOLUTION_S:g})")
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="guard per game [s], as in `hideseek campaign` (default 600)")
    parser.add_argument("--json", action="store_true", help="print the report as one JSON object")


def _check(args: argparse.Namespace) -> None:
    """Raises ValueError naming the first bad option."""
    if not 1 <= args.max_runs <= 10_000:
        raise ValueError(f"--max-runs must be within 1..10000, got {args.max_runs}")
    if not 0 < args.resolution <= 1e4:
        raise ValueError(f"--resolution must be within (0, 1e4] s, got {args.resolution}")
    if not 0 < args.budget <= 1e6:
        raise ValueError(f"--budget must be within (0, 1e6] s, got {args.budget}")
    if not args.timeout > 0:
        raise ValueError(f"--timeout must be > 0, got {args.timeout}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    out = Path(args.out)
    if out.is_dir() or not out.parent.is_dir():
        raise ValueError(f"--out must be a file in an existing folder, got {args.out!r}")


def print_report(r: dict[str, Any], out: str) -> None:
    """The report as text: the failure, both schedules, the steps and the command."""
    print(f"{r['origin']} ({r['room']}, seed {r['seed']}) fails: {r['failure']}")
    print(f"  original schedule ({len(r['original'])} faults):")
    for line in r["original"] or ["(none)"]:
        print(f"    {line}")
    print(f"  shrunk schedule ({len(r['shrunk'])} faults), {r['runs']} runs (at most "
          f"{r['max_runs']} to search, one to check the file)"
          f"{' (ran out: not minimal)' if r['exhausted'] else ''}:")
    for line in r["shrunk"] or ["(none: the game fails without its faults)"]:
        print(f"    {line}")
    for step in r["steps"]:
        print(f"  - {step}")
    verdict = "fails the same way" if r["reproduces"] else "DOES NOT fail the same way"
    print(f"  written to {out}: {verdict}; reproduce: {r['reproduce'].replace('FILE', out)}")


def run(args: argparse.Namespace) -> int:
    try:
        _check(args)
        if not args.json:
            game = f"campaign game {args.campaign}" if args.campaign else args.scenario
            print(f"shrinking {game}: at most {args.max_runs} runs in virtual time ...",
                  flush=True)
        with progress_bar("runs", args.max_runs + 1) as bar:  # the search's, and the check
            def ran(_runs: int) -> None:
                bar.advance()

            if args.campaign:
                report = shrink_campaign_game(args.campaign, max_runs=args.max_runs,
                                              resolution_s=args.resolution,
                                              wall_timeout_s=args.timeout, on_run=ran)
            else:
                base = load_scenario(args.scenario)
                report = shrink_game(base, args.seed, budget_s=args.budget,
                                     origin=f"scenario {args.scenario}", max_runs=args.max_runs,
                                     resolution_s=args.resolution, wall_timeout_s=args.timeout,
                                     on_run=ran)
            bar.finish()
    except (CampaignError, ScenarioError, ShrinkError, ValueError) as exc:
        print(f"hideseek shrink: {exc}", file=sys.stderr)
        return 2
    try:
        Path(args.out).write_text(report["toml"], encoding="utf-8")
    except OSError as exc:
        print(f"hideseek shrink: cannot write {args.out}: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({k: v for k, v in report.items() if k != "toml"} | {"out": args.out}))
    else:
        print_report(report, args.out)
    return 0 if report["reproduces"] else 1
