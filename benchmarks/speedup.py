"""Whole-game speed of this tree against an earlier commit, side by side in one run.

Run as ``python -m benchmarks.speedup [--base REV | --base-tree DIR] [--rooms a,b]
[--seeds 1-2] [--rounds N]``.

Why side by side: on a shared machine a CPU second does more or less work with
the load (shared cores and caches), so figures taken at different times do not
compare. Here the earlier commit ``--base`` is checked out into a temporary
``git worktree`` and the games of the two trees alternate: for every room and
seed, one game of each tree, the tree that goes first swapping from one game
pair to the next. Each game is its own ``python -m tui.cli run ... --json``
process started in its tree's directory (so that tree's code is imported), run
one at a time; its CPU time is the ``resource.getrusage(RUSAGE_CHILDREN)``
delta (user + system, interpreter start included; both trees are byte-compiled
first), its simulated time the game's ``sim_seconds``.

Per room the rate is the simulated seconds per CPU second summed over its
games; the ratio is this tree's rate over the base's (above 1: faster). The
table also says whether the two trees played the same game (equal trace
hashes): when they differ the mapping phase may be longer or shorter, and the
ratio then also measures that. The last line is the figures as JSON. The
worktree is removed afterwards, also when the run is interrupted. ``--base-tree``
names an earlier tree already on disk instead (a machine without the repository's
history, such as a copy of the working tree): no worktree is made, and the base is
named by its directory.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass

from benchmarks.game import parse_seeds
from benchmarks.trace_hashes import run_json
from world.scenario import builtin_scenarios

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

DEFAULT_BASE = "45ea061"
"""The tree the whole-game speed target is measured against (``--base`` overrides)."""


@dataclass(frozen=True, slots=True)
class Game:
    """One game's figures."""

    sim_s: float
    """Simulated seconds the game ran."""
    cpu_s: float
    """CPU seconds of its process (user + system)."""
    outcome: str
    trace_hash: str


def is_tree(path: str) -> bool:
    """Whether ``path`` holds a hideseek tree (its ``tui/cli.py``)."""
    return os.path.isfile(os.path.join(path, "tui", "cli.py"))


def byte_compile(tree: str) -> None:
    """Byte-compile ``tree``, so that no timed process pays for compiling it."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", "-x", r"/\.", tree],
                   capture_output=True, check=False)


def children_cpu_s() -> float:
    """CPU seconds (user + system) of this process's finished children so far: the
    difference around a child is that child's."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def play(tree: str, room: str, seed: int, timeout_s: float) -> Game:
    """Play one headless game in ``tree``'s directory and measure its child's CPU time."""
    before = children_cpu_s()
    try:
        out = run_json(["--scenario", room, "--seed", str(seed)], cwd=tree,
                       timeout_s=timeout_s)
    except RuntimeError as exc:
        raise RuntimeError(f"{room} seed {seed} in {tree}: {exc}") from exc
    cpu = children_cpu_s() - before
    return Game(float(out["sim_seconds"]), cpu, str(out["outcome"]), str(out["trace_hash"]))


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", _ROOT, *args], check=True, capture_output=True,
                          text=True).stdout.strip()


def rate(games: list[Game]) -> float:
    """Simulated seconds per CPU second over ``games``."""
    return sum(g.sim_s for g in games) / max(sum(g.cpu_s for g in games), 1e-9)


def _describe_head() -> tuple[str, str]:
    """This tree's short commit and a note on uncommitted changes ("", "" without git)."""
    try:
        head = _git("rev-parse", "--short", "HEAD")
    except (OSError, subprocess.CalledProcessError):
        return "(no git)", ""
    return head, " (with uncommitted changes)" if _git("status", "--porcelain", "-uno") else ""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speedup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", default=DEFAULT_BASE,
                    help=f"the earlier commit to compare with (default {DEFAULT_BASE})")
    ap.add_argument("--base-tree", default="",
                    help="an earlier tree already on disk, instead of --base")
    ap.add_argument("--rooms", default="", help="comma-separated rooms (default: every built-in)")
    ap.add_argument("--seeds", default="1", help="seeds per room, e.g. 1-3 (default 1)")
    ap.add_argument("--rounds", type=int, default=1, help="game pairs per room and seed")
    ap.add_argument("--timeout", type=float, default=900.0, help="per game [s]")
    args = ap.parse_args(argv)
    known = builtin_scenarios()
    rooms = [r for r in args.rooms.split(",") if r] or known
    try:
        seeds = parse_seeds(args.seeds)
        unknown = [r for r in rooms if r not in known]
        if unknown or args.rounds < 1:
            raise ValueError(f"unknown rooms {unknown} (known: {', '.join(known)})"
                             if unknown else "--rounds must be >= 1")
        if args.base_tree and not is_tree(args.base_tree):
            raise ValueError(f"--base-tree {args.base_tree!r} holds no tree (no tui/cli.py)")
        base_rev = (os.path.abspath(args.base_tree) if args.base_tree
                    else _git("rev-parse", "--verify", f"{args.base}^{{commit}}"))
    except (ValueError, subprocess.CalledProcessError) as exc:
        msg = exc.stderr.strip() if isinstance(exc, subprocess.CalledProcessError) else exc
        print(f"speedup: {msg}", file=sys.stderr)
        return 2

    head, dirty = _describe_head()
    with tempfile.TemporaryDirectory(prefix="speedup-") as tmp:
        base_tree = args.base_tree or os.path.join(tmp, "base")
        if not args.base_tree:
            _git("worktree", "add", "--detach", base_tree, base_rev)
        try:
            load0 = os.getloadavg()[0]
            base_name = base_rev if args.base_tree else base_rev[:9]
            print(f"this tree {head}{dirty} against {base_name}; load {load0:.1f} "
                  f"on {os.cpu_count()} cores", flush=True)
            trees = {"new": _ROOT, "base": base_tree}
            for tree in trees.values():
                byte_compile(tree)
            games: dict[str, dict[str, list[Game]]] = {k: {r: [] for r in rooms} for k in trees}
            pair = 0
            for _ in range(args.rounds):
                for room in rooms:
                    for seed in seeds:
                        order = ("base", "new") if pair % 2 == 0 else ("new", "base")
                        pair += 1
                        for name in order:
                            g = play(trees[name], room, seed, args.timeout)
                            games[name][room].append(g)
                            print(f"  {room:10s} seed {seed} {name:4s}: {g.sim_s:7.1f} sim s "
                                  f"{g.cpu_s:6.1f} CPU s  {g.sim_s / g.cpu_s:6.1f}x  "
                                  f"{g.outcome}  {g.trace_hash[:8]}", flush=True)
        finally:
            if not args.base_tree:
                subprocess.run(["git", "-C", _ROOT, "worktree", "remove", "--force", base_tree],
                               capture_output=True)
                subprocess.run(["git", "-C", _ROOT, "worktree", "prune"], capture_output=True)

    load1 = os.getloadavg()[0]
    print(f"\n{'room':10s} {'base x':>7s} {'new x':>7s} {'ratio':>6s}  same games")
    ratios: dict[str, float] = {}
    for room in rooms:
        b, n = rate(games["base"][room]), rate(games["new"][room])
        ratios[room] = n / b
        same = sum(x.trace_hash == y.trace_hash
                   for x, y in zip(games["base"][room], games["new"][room], strict=True))
        print(f"{room:10s} {b:7.1f} {n:7.1f} {ratios[room]:6.2f}  "
              f"{same}/{len(games['new'][room])}")
    median = statistics.median(ratios.values())
    print(f"median ratio {median:.2f}, lowest {min(ratios.values()):.2f}; "
          f"load {load0:.1f} -> {load1:.1f}")
    print(json.dumps({"base": base_rev, "head": head, "seeds": seeds, "rounds": args.rounds,
                      "ratios": ratios, "median": median, "load": [load0, load1]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
