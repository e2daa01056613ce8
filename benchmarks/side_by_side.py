"""Whole games and the world alone in this tree and a base tree, alternated in one run.

Used by ``python -m benchmarks.game --base DIR [--scenarios a,b] [--seeds 1-3]
[--rounds N] [--world-runs N]``. For every room and seed, one game of each tree,
the tree that goes first swapping from pair to pair; each game is a child
process started in its tree's directory (so that tree's code is imported) that
plays it with that tree's ``benchmarks.game.play_one``, exactly as ``hideseek
run`` plays it. Two CPU figures per game:

- ``cpu_s``: the game's own ``time.process_time`` around ``trio.run`` (what
  ``benchmarks.game`` reports as ``RTFc``; the imports are not in it);
- ``process_cpu_s``: the child's whole CPU time (``getrusage`` of the finished
  child: the interpreter's start and the imports too), what one ``hideseek run``
  costs.

Then the world alone (``benchmarks.world.run_world``: furniture at a 50 ms tick,
three rovers driving, the LIDAR and IR on), again alternated, each tree's best
of ``--world-runs`` runs: simulated seconds per CPU second. On a shared machine a
CPU second does more or less work with the load, so only the ratio of two trees
measured side by side is a comparison; the load average before and after is
printed with it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from dataclasses import dataclass
from typing import Any

from benchmarks.speedup import byte_compile, children_cpu_s, is_tree

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TARGET_RTF_CPU = 100.0
"""Simulated seconds per CPU second every room's games should reach."""
TARGET_RATIO = 1.6
"""How much faster than the base tree every room should play."""
WORLD_ROOM, WORLD_TICK_S, WORLD_SECONDS = "furniture", 0.05, 60.0
"""The world-alone run: room, tick [s] and simulated seconds per run."""

_GAME = ("import json, sys\n"
         "from benchmarks.game import play_one\n"
         "r = play_one((sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), False))\n"
         "print(json.dumps({k: r[k] for k in ('sim_seconds', 'cpu_seconds', 'outcome',"
         " 'trace_hash')}))\n")
_WORLD = ("import json, sys\n"
          "from benchmarks.world import run_world\n"
          "print(json.dumps(run_world(sys.argv[1], float(sys.argv[2]), float(sys.argv[3]),"
          " True)))\n")


@dataclass(frozen=True, slots=True)
class Played:
    """One game of one tree."""

    sim_s: float
    cpu_s: float
    """CPU seconds of ``trio.run`` alone."""
    process_cpu_s: float
    """CPU seconds of the whole child process (start and imports included)."""
    outcome: str
    trace_hash: str


def _child(tree: str, code: str, args: list[str], timeout_s: float) -> tuple[Any, float]:
    """Run ``code`` with ``args`` in ``tree``'s directory; its last stdout line as JSON and
    the child's CPU seconds.

    Raises:
        RuntimeError: the child printed no JSON (its exit status and last error line).
    """
    before = children_cpu_s()
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=tree, capture_output=True,
                          text=True, timeout=timeout_s, check=False)
    cpu = children_cpu_s() - before
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1]), cpu
    except (IndexError, ValueError) as exc:
        raise RuntimeError(f"{tree}: no result (exit {proc.returncode}): "
                           f"{proc.stderr.strip().splitlines()[-1:]}") from exc


def play(tree: str, room: str, seed: int, budget_s: float, timeout_s: float) -> Played:
    """Play one game in ``tree`` (a child process) and return its figures."""
    out, cpu = _child(tree, _GAME, [room, str(seed), repr(budget_s)], timeout_s)
    return Played(float(out["sim_seconds"]), float(out["cpu_seconds"]), cpu,
                  str(out["outcome"]), str(out["trace_hash"]))


def world_rtf_cpu(tree: str, timeout_s: float) -> float:
    """The world alone in ``tree``: simulated seconds per CPU second (see the module doc)."""
    out, _ = _child(tree, _WORLD, [WORLD_ROOM, repr(WORLD_TICK_S), repr(WORLD_SECONDS)],
                    timeout_s)
    return float(out[1])


def rate(games: list[Played], process: bool = False) -> float:
    """Simulated seconds per CPU second over ``games`` (``process``: whole processes)."""
    cpu = sum(g.process_cpu_s if process else g.cpu_s for g in games)
    return sum(g.sim_s for g in games) / max(cpu, 1e-9)


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return -1.0


def _trees(base: str) -> dict[str, str]:
    """This tree and ``base`` by name ("new", "base"), both byte-compiled, so that no timed
    process pays for compiling them.

    Raises:
        ValueError: ``base`` holds no tree.
    """
    if not is_tree(base):
        raise ValueError(f"--base {base!r} holds no tree (no tui/cli.py)")
    trees = {"new": _ROOT, "base": os.path.abspath(base)}
    for tree in trees.values():
        byte_compile(tree)
    return trees


def compare(base: str, rooms: list[str], seeds: list[int], *, budget_s: float = 1200.0,
            rounds: int = 1, world_runs: int = 3, timeout_s: float = 900.0) -> dict[str, Any]:
    """Play every room and seed in both trees, alternating, print a table and return the
    figures (also printed as the last line, JSON).

    Raises:
        ValueError: ``base`` holds no tree, or ``rounds`` / ``world_runs`` below 1.
    """
    if rounds < 1 or world_runs < 1:
        raise ValueError(f"--rounds and --world-runs must be >= 1, got {rounds}, {world_runs}")
    trees = _trees(base)
    load0 = _load()
    print(f"this tree {_ROOT} against {trees['base']}; load {load0:.2f} on "
          f"{os.cpu_count()} cores", flush=True)
    games: dict[str, dict[str, list[Played]]] = {k: {r: [] for r in rooms} for k in trees}
    pair = 0
    for _ in range(rounds):
        for room in rooms:
            for seed in seeds:
                order = ("base", "new") if pair % 2 == 0 else ("new", "base")
                pair += 1
                for name in order:
                    g = play(trees[name], room, seed, budget_s, timeout_s)
                    games[name][room].append(g)
                    print(f"  {room:10s} seed {seed} {name:4s}: {g.sim_s:7.1f} sim s "
                          f"{g.cpu_s:6.2f} CPU s {g.sim_s / max(g.cpu_s, 1e-9):6.1f}x "
                          f"(process {g.process_cpu_s:5.2f} s)  {g.outcome}  "
                          f"{g.trace_hash[:8]}", flush=True)
    world: dict[str, list[float]] = {k: [] for k in trees}
    for i in range(world_runs):
        for name in (("base", "new") if i % 2 == 0 else ("new", "base")):
            world[name].append(world_rtf_cpu(trees[name], timeout_s))
    load1 = _load()
    rows: dict[str, Any] = {}
    print(f"\n{'room':10s} {'base x':>7s} {'new x':>7s} {'ratio':>6s} {'process ratio':>13s}"
          f"  same games")
    for room in rooms:
        b, n = games["base"][room], games["new"][room]
        row = {"base_rtf_cpu": rate(b), "new_rtf_cpu": rate(n),
               "ratio": rate(n) / max(rate(b), 1e-9),
               "process_ratio": rate(n, True) / max(rate(b, True), 1e-9),
               "new_min_game_rtf_cpu": min(g.sim_s / max(g.cpu_s, 1e-9) for g in n),
               "same_games": sum(x.trace_hash == y.trace_hash for x, y in zip(b, n, strict=True)),
               "games": len(n)}
        rows[room] = row
        ok = row["new_rtf_cpu"] >= TARGET_RTF_CPU and row["ratio"] >= TARGET_RATIO
        print(f"{room:10s} {row['base_rtf_cpu']:7.1f} {row['new_rtf_cpu']:7.1f} "
              f"{row['ratio']:6.2f} {row['process_ratio']:13.2f}  "
              f"{row['same_games']}/{row['games']}{'' if ok else '  !'}")
    all_b = [g for r in rooms for g in games["base"][r]]
    all_n = [g for r in rooms for g in games["new"][r]]
    wb, wn = max(world["base"]), max(world["new"])
    figures = {
        "benchmark": "game_side_by_side", "base": trees["base"], "seeds": seeds,
        "rounds": rounds, "load": [load0, load1], "rooms": rows,
        "all": {"base_rtf_cpu": rate(all_b), "new_rtf_cpu": rate(all_n),
                "ratio": rate(all_n) / max(rate(all_b), 1e-9),
                "process_ratio": rate(all_n, True) / max(rate(all_b, True), 1e-9)},
        "median_ratio": statistics.median(r["ratio"] for r in rows.values()),
        "world": {"room": WORLD_ROOM, "tick_s": WORLD_TICK_S, "base_rtf_cpu": wb,
                  "new_rtf_cpu": wn, "ratio": wn / max(wb, 1e-9)},
        "targets": {"rtf_cpu": TARGET_RTF_CPU, "ratio": TARGET_RATIO},
    }
    a = figures["all"]
    print(f"{'all':10s} {a['base_rtf_cpu']:7.1f} {a['new_rtf_cpu']:7.1f} {a['ratio']:6.2f} "
          f"{a['process_ratio']:13.2f}")
    print(f"world alone ({WORLD_ROOM}, {WORLD_TICK_S * 1000:.0f} ms tick, best of "
          f"{world_runs}): base {wb:.0f}x, new {wn:.0f}x per CPU s, ratio {wn / wb:.2f}")
    print(f"load {load0:.2f} -> {load1:.2f}; targets: >= {TARGET_RTF_CPU:g} simulated s per "
          f"CPU s and >= {TARGET_RATIO:g}x the base per room ('!' marks a miss)")
    print(json.dumps(figures))
    return figures


@dataclass(frozen=True, slots=True)
class Campaign:
    """One tree's campaign run."""

    games: int
    cpu_s: float
    """CPU seconds of the whole ``hideseek campaign`` process and its workers."""
    wall_s: float
    hashes: dict[int, str]
    """Each game's trace hash, by index."""

    @property
    def games_per_cpu_min(self) -> float:
        """Games per CPU minute (the workers' and the parent's CPU together)."""
        return 60.0 * self.games / max(self.cpu_s, 1e-9)


def run_campaign(tree: str, games: int, workers: int, seed: int, timeout_s: float) -> Campaign:
    """Play a campaign (``hideseek campaign -n games --workers W --seed S``) in ``tree`` and
    measure it: the CPU time of the process and its workers (`children_cpu_s`, the pool
    reaped by the process), and each game's trace hash from its results file.

    Raises:
        RuntimeError: the campaign failed or stored other than ``games`` games.
    """
    import sqlite3  # noqa: PLC0415 - only the campaign comparison reads a results file
    import tempfile  # noqa: PLC0415
    import time  # noqa: PLC0415

    with tempfile.TemporaryDirectory(prefix="side-by-side-") as tmp:
        out = os.path.join(tmp, "campaign.sqlite")
        before, wall0 = children_cpu_s(), time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "tui.cli", "campaign", "-n", str(games),
                               "--workers", str(workers), "--seed", str(seed), "--out", out,
                               "--no-progress", "--json"], cwd=tree, capture_output=True,
                              text=True, timeout=timeout_s, check=False)
        cpu, wall = children_cpu_s() - before, time.perf_counter() - wall0
        try:
            with sqlite3.connect(out) as db:
                hashes = dict(db.execute("SELECT idx, trace_hash FROM campaign_games"))
        except sqlite3.Error as exc:
            raise RuntimeError(f"{tree}: campaign stored nothing (exit {proc.returncode}): "
                               f"{proc.stderr.strip().splitlines()[-1:]}") from exc
    if len(hashes) != games:
        raise RuntimeError(f"{tree}: {len(hashes)} of {games} games stored "
                           f"(exit {proc.returncode})")
    return Campaign(games, cpu, wall, hashes)


def compare_campaign(base: str, games: int, *, workers: int = 2, seed: int = 1,
                     rounds: int = 1, timeout_s: float = 7200.0) -> dict[str, Any]:
    """The same campaign in both trees, alternating (``rounds`` each, the tree that goes
    first swapping): games per CPU minute, their ratio and whether every game kept its
    trace hash. Prints a table and the figures as JSON (also returned).

    Raises:
        ValueError: ``base`` holds no tree, or counts below 1.
    """
    if games < 1 or workers < 1 or rounds < 1:
        raise ValueError(f"games, workers and rounds must be >= 1, got {games}, {workers}, "
                         f"{rounds}")
    trees = _trees(base)
    load0 = _load()
    print(f"campaign seed {seed}, {games} games, {workers} workers: this tree against "
          f"{trees['base']}; load {load0:.2f}", flush=True)
    runs: dict[str, list[Campaign]] = {k: [] for k in trees}
    for i in range(rounds):
        for name in (("base", "new") if i % 2 == 0 else ("new", "base")):
            c = run_campaign(trees[name], games, workers, seed, timeout_s)
            runs[name].append(c)
            print(f"  {name:4s}: {c.cpu_s:7.1f} CPU s, {c.wall_s:7.1f} wall s, "
                  f"{c.games_per_cpu_min:6.2f} games per CPU min", flush=True)
    load1 = _load()
    rate = {k: 60.0 * sum(c.games for c in v) / max(sum(c.cpu_s for c in v), 1e-9)
            for k, v in runs.items()}
    same = sum(h == runs["base"][0].hashes.get(i) for c in runs["new"]
               for i, h in c.hashes.items())
    total = sum(c.games for c in runs["new"])
    figures = {"benchmark": "campaign_side_by_side", "base": trees["base"], "seed": seed,
               "games": games, "workers": workers, "rounds": rounds,
               "base_games_per_cpu_min": rate["base"], "new_games_per_cpu_min": rate["new"],
               "ratio": rate["new"] / max(rate["base"], 1e-9), "same_games": same,
               "games_compared": total, "load": [load0, load1]}
    print(f"games per CPU minute: base {rate['base']:.2f}, new {rate['new']:.2f}, ratio "
          f"{figures['ratio']:.2f}; {same}/{total} games keep the base's trace hash; "
          f"load {load0:.2f} -> {load1:.2f}")
    print(json.dumps(figures))
    return figures
