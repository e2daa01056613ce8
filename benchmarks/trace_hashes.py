"""Trace hashes of a fixed set of games: proof that a change kept behaviour.

Run as ``python -m benchmarks.trace_hashes [--out FILE] [--check FILE]
[--workers W] [--games SPEC,...]``.

A game's trace hash (``hideseek run --json``, field ``trace_hash``) covers
every event of the run, so two trees that give the same hash for a game play
it event for event alike. The default set is every built-in room with seeds 1
and 2 plus a few campaign games with faults (``--campaign S:I``) and generated
rooms: a refactoring that must not change behaviour records the set before
(``--out before.json``) and checks it after (``--check before.json``; exit 1
on any difference, each difference printed). Each game runs as its own
``python -m tui.cli run`` process in the current directory, so the tree under
test is the one the command is run from.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

from world.scenario import builtin_scenarios

CAMPAIGN_REFS = ("1:0", "1:1", "1:2", "2:3", "3:4", "7:5")
"""Campaign games (``S:I``: campaign seed S, game I) with their faults."""

GENERATED = ("11:0", "12:1")
"""Generated rooms (``SEED:INDEX``), seed 1."""


def default_games() -> list[str]:
    """Each game as the ``hideseek run`` arguments that play it, joined by spaces."""
    games = [f"--scenario {name} --seed {seed}" for name in builtin_scenarios() for seed in (1, 2)]
    games += [f"--campaign {ref}" for ref in CAMPAIGN_REFS]
    games += [f"--generated {ref} --seed 1" for ref in GENERATED]
    return games


def run_json(args: list[str], *, cwd: str | None = None, timeout_s: float = 900) -> dict:
    """Play one game as ``python -m tui.cli run ARGS --json`` in a child process (in
    ``cwd``'s tree) and return its JSON report.

    Raises:
        RuntimeError: the child printed no report (its exit status and last error line).
    """
    cmd = [sys.executable, "-m", "tui.cli", "run", *args, "--json"]
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    try:
        report = json.loads(proc.stdout.strip().splitlines()[-1])
        if "trace_hash" not in report:
            raise KeyError("trace_hash")
        return report
    except (IndexError, KeyError, ValueError) as exc:
        raise RuntimeError(f"no result (exit {proc.returncode}): "
                           f"{proc.stderr.strip().splitlines()[-1:]}") from exc


def trace_hash(game: str) -> str:
    """Play one game headless in a child process and return its trace hash (or the error)."""
    try:
        return run_json(game.split())["trace_hash"]
    except RuntimeError as exc:
        return f"error: {exc}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.trace_hashes", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="write {game: hash} as JSON to FILE")
    ap.add_argument("--check", help="compare with a JSON file written by --out; exit 1 on change")
    ap.add_argument("--workers", type=int, default=2, help="games played at once (default 2)")
    ap.add_argument("--games", help="';'-separated run arguments instead of the default set")
    args = ap.parse_args(argv)
    games = args.games.split(";") if args.games else default_games()
    if args.check:
        with open(args.check, encoding="utf-8") as fh:
            expected = json.load(fh)
        games = list(expected)
    with ThreadPoolExecutor(max_workers=max(1, args.workers)) as pool:
        hashes = dict(zip(games, pool.map(trace_hash, games), strict=True))
    for game, h in hashes.items():
        print(f"{h}  {game}")
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(hashes, fh, indent=1)
    if args.check:
        changed = [g for g in games if hashes[g] != expected[g]]
        for g in changed:
            print(f"CHANGED {g}: {expected[g]} -> {hashes[g]}")
        print(f"{len(games) - len(changed)}/{len(games)} games keep their trace hash")
        return 1 if changed else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
