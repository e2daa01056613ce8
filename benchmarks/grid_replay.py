"""One game's grid updates and LIDAR batch checks, replayed into this tree and an earlier commit.

Run from the repo root::

    python -m benchmarks.grid_replay [--scenario round] [--seed 1] [--base REV] [--reps 5]

Why a replay: the grid update (`OccupancyGrid.integrate`, `integrate_batches`) and
LIDAR Control's check of each batch (`lidar.batch_health`) cost a few percent of a
game each, less than a whole game's CPU time varies on a shared machine, and their
cost depends on the game's own sizes (rays per batch, batches per window, ray
lengths). So the game is played once in this process with those calls recorded
(the game is the same: the recording only copies the arguments), and each call is
then made into both versions, alternating which goes first, each version on its
own grids; per call the fastest of ``--reps`` rounds counts. Every call's result,
and each grid's log-odds, hit counts and classes at the end, are compared bit for
bit: a change that keeps them keeps every game that makes these calls.

The earlier version is ``--base``'s `occupancy.py` with its `sensor_model.py`, and
its `lidar.batch_health` (each loaded from ``git show``, beside this tree's other
modules). Prints a table and, last, one line of JSON with the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from actors.firmware.drivers import lidar
from actors.firmware.mapping import occupancy
from world.scenario import builtin_scenarios

ROOT = Path(__file__).resolve().parent.parent
_SENSOR_MODEL = "actors.firmware.mapping.sensor_model"


@dataclass
class Recording:
    """The grid calls of one game in order (``(kind, grid id, args)``) and its batch checks."""

    calls: list[tuple[str, int, tuple]] = field(default_factory=list)
    checks: list[tuple] = field(default_factory=list)
    trace_hash: str = ""


def record(scenario: str, seed: int) -> Recording:
    """Play one game in this process and record its grid calls and batch checks."""
    rec = Recording()
    grid = occupancy.OccupancyGrid
    saved = {name: getattr(grid, name) for name in
             ("__init__", "integrate", "integrate_batches", "fill_unknown")}
    saved_health = lidar.batch_health

    def init(self: Any, *a: Any, **k: Any) -> None:
        saved["__init__"](self, *a, **k)
        rec.calls.append(("init", id(self), (a, k)))

    def integrate(self: Any, pose: Any, angles: Any, ranges: Any) -> int:
        rec.calls.append(("integrate", id(self), (pose, np.array(angles), np.array(ranges))))
        return saved["integrate"](self, pose, angles, ranges)

    def integrate_batches(self: Any, origins: Any, sizes: Any, angles: Any, ranges: Any) -> int:
        rec.calls.append(("batches", id(self), (np.array(origins), list(sizes),
                                                np.array(angles), np.array(ranges))))
        return saved["integrate_batches"](self, origins, sizes, angles, ranges)

    def fill_unknown(self: Any, row0: int, col0: int, cells: Any) -> bool:
        rec.calls.append(("fill", id(self), (row0, col0, np.array(cells))))
        return saved["fill_unknown"](self, row0, col0, cells)

    def batch_health(angles: Any, ranges: Any, bad_frames: int, *rest: Any) -> Any:
        rec.checks.append((np.array(angles), np.array(ranges), bad_frames, *rest))
        return saved_health(angles, ranges, bad_frames, *rest)

    from tui.cli import main  # the game's own entry point

    out = io.StringIO()
    try:
        for name, fn in (("__init__", init), ("integrate", integrate),
                         ("integrate_batches", integrate_batches), ("fill_unknown", fill_unknown)):
            setattr(grid, name, fn)
        lidar.batch_health = batch_health
        with contextlib.redirect_stdout(out):
            main(["run", "--scenario", scenario, "--seed", str(seed), "--json"])
    finally:
        for name, fn in saved.items():
            setattr(grid, name, fn)
        lidar.batch_health = saved_health
    rec.trace_hash = json.loads(out.getvalue().strip().splitlines()[-1]).get("trace_hash", "")
    return rec


def _module(name: str, source: str) -> ModuleType:
    spec = importlib.util.spec_from_loader(name, loader=None)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while it runs
    exec(compile(source, f"<{name}>", "exec"), module.__dict__)  # noqa: S102 - a commit's own file
    return module


def load_base(rev: str) -> tuple[ModuleType, ModuleType]:
    """``rev``'s occupancy module (with ``rev``'s sensor model) and its lidar module.

    Raises:
        ValueError: when git cannot show the files at ``rev``.
    """
    def show(path: str) -> str:
        done = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True,
                              text=True, check=False)
        if done.returncode != 0:
            raise ValueError(f"cannot read {path} at {rev!r}: {done.stderr.strip()}")
        return done.stdout

    tag = "".join(c if c.isalnum() else "_" for c in rev)
    model = _module(f"_base_{tag}_sensor_model", show("actors/firmware/mapping/sensor_model.py"))
    occ = show("actors/firmware/mapping/occupancy.py").replace(_SENSOR_MODEL, model.__name__)
    return (_module(f"_base_{tag}_occupancy", occ),
            _module(f"_base_{tag}_lidar", show("actors/firmware/drivers/lidar.py")))


def replay_grid(rec: Recording, versions: dict[str, ModuleType], reps: int
                ) -> tuple[dict[str, np.ndarray], bool]:
    """Each grid call into every version, alternating which goes first; the fastest time
    per call over ``reps`` rounds [s], and whether all results were equal."""
    names = list(versions)
    best = {n: np.full(len(rec.calls), np.inf) for n in names}
    same = True
    for rep in range(reps):
        grids: dict[str, dict[int, Any]] = {n: {} for n in names}
        for j, (kind, gid, args) in enumerate(rec.calls):
            order = names if (j + rep) % 2 == 0 else names[::-1]
            results = []
            for n in order:
                if kind == "init":
                    a, k = args
                    grids[n][gid] = versions[n].OccupancyGrid(*a, **k)
                    continue
                g = grids[n][gid]
                if kind == "fill":
                    results.append(g.fill_unknown(*args))
                    continue
                t0 = time.perf_counter()
                r = g.integrate(*args) if kind == "integrate" else g.integrate_batches(*args)
                best[n][j] = min(best[n][j], time.perf_counter() - t0)
                results.append(r)
            same = same and all(r == results[0] for r in results)
        for gs in zip(*(grids[n].values() for n in names), strict=True):
            a = gs[0]
            same = same and all(
                np.array_equal(a.log_odds(), b.log_odds())
                and np.array_equal(a.hit_counts(), b.hit_counts())
                and np.array_equal(a.cells(), b.cells()) for b in gs[1:])
    return best, same


def replay_checks(rec: Recording, versions: dict[str, ModuleType], reps: int
                  ) -> tuple[dict[str, float], bool]:
    """Every batch check into each version, alternating; the fastest round's mean time
    per check [s], and whether every verdict was equal."""
    names = list(versions)
    best = dict.fromkeys(names, np.inf)
    verdicts: dict[str, list] = {}
    for rep in range(reps):
        for n in (names if rep % 2 == 0 else names[::-1]):
            check = versions[n].batch_health
            t0 = time.perf_counter()
            verdicts[n] = [int(check(*c)) for c in rec.checks]
            best[n] = min(best[n], (time.perf_counter() - t0) / max(len(rec.checks), 1))
    return best, all(verdicts[n] == verdicts[names[0]] for n in names)


def main(argv: list[str] | None = None) -> int:
    """Record, replay, print; 2 (and one error line) for a bad argument."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="round", help="built-in room (default round)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--base", default="main", help="the earlier commit (default main)")
    parser.add_argument("--reps", type=int, default=5, help="rounds per call (default 5)")
    args = parser.parse_args(argv)
    try:
        if not 1 <= args.reps <= 100:
            raise ValueError(f"--reps must be 1..100, got {args.reps}")
        if args.scenario not in builtin_scenarios():
            raise ValueError(f"unknown scenario {args.scenario!r}")
        base_occ, base_lidar = load_base(args.base)
    except ValueError as e:
        print(f"grid_replay: {e}", file=sys.stderr)
        return 2
    rec = record(args.scenario, args.seed)
    kinds = np.array([kind for kind, _, _ in rec.calls])
    best, same = replay_grid(rec, {"base": base_occ, "this": occupancy}, args.reps)
    check_s, same_verdicts = replay_checks(rec, {"base": base_lidar, "this": lidar}, args.reps)
    figures: dict[str, Any] = {"scenario": args.scenario, "seed": args.seed, "base": args.base,
                               "trace_hash": rec.trace_hash, "identical_grids": same,
                               "identical_verdicts": same_verdicts}
    print(f"{args.scenario} seed {args.seed} (trace hash {rec.trace_hash}), "
          f"this tree against {args.base}, fastest of {args.reps} per call")
    for kind, label in (("batches", "integrate_batches"), ("integrate", "integrate")):
        mask = kinds == kind
        n = int(np.count_nonzero(mask))
        if n == 0:
            continue
        b, t = (float(best[v][mask].sum()) for v in ("base", "this"))
        print(f"  {label:18s} {n:5d} calls  {b / n * 1e6:7.1f} -> {t / n * 1e6:7.1f} us/call"
              f"  ({b * 1e3:.0f} -> {t * 1e3:.0f} ms a game)")
        figures[f"{label}_us"] = [round(b / n * 1e6, 1), round(t / n * 1e6, 1)]
    print(f"  {'batch_health':18s} {len(rec.checks):5d} calls  {check_s['base'] * 1e6:7.1f} -> "
          f"{check_s['this'] * 1e6:7.1f} us/call")
    figures["batch_health_us"] = [round(check_s["base"] * 1e6, 2), round(check_s["this"] * 1e6, 2)]
    print(f"  grids and change counts identical: {same}; verdicts identical: {same_verdicts}")
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
