"""Is the hider's and seeker's pose belief honest? Its 95 % spread against the truth.

Run as ``python -m benchmarks.calibration [--scenarios a,b] [--seeds 6-7] [--workers W]``.

A filter that says "95 %" should hold the truth inside its 95 % radius (and
its 95 % heading) in about 95 % of the moments it is asked. Each game is
played headless, exactly as ``hideseek run`` plays it; at every ``pose``
frame the hider and the seeker send, a frame observer (no extra task, so the
game keeps its trace hash) reads the rover's true pose from the world and
the belief's published spread (`localisation.belief.Spread`) from its
navigation. The true error is the distance between the true pose and the
reported one, both in the map frame (the offset between the room and the map
frame is the one at the rover's first frame, where the belief starts round
the server's ``origin``).

Per game and role the table shows the frames counted and the share of them
whose position error is within ``radius95_cm`` and whose heading error is
within ``heading95_deg``; the worst excess is the largest ``error - radius``
[cm]. Shares well under 0.95 say the belief is overconfident (the truth
leaves it, and nothing but a contact brings it back); shares at 1.00 with
large radii say it is too timid (searches wider than they need). The last
line is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import sys
from typing import Any

from benchmarks.game import parse_seeds

ROLES = ("hider", "seeker")
DEFAULT_SCENARIOS = "corridor,gap,furniture,cluttered"


def play_one(job: tuple[str, int]) -> dict[str, Any]:
    """Play one game and return, per role, the calibration figures (spawn-pool function)."""
    import trio  # noqa: PLC0415 - imported in the worker

    from actors import seed_trio_scheduler, virtual_clock  # noqa: PLC0415
    from supervisors.harness.headless import run_game  # noqa: PLC0415
    from world.scenario import load_scenario  # noqa: PLC0415

    name, seed = job
    samples: dict[str, list[tuple[float, ...]]] = {r: [] for r in ROLES}

    class Sampler:
        """A `RunObserver`: notes each pose frame with the true pose and the belief's spread."""

        def started(self, system: Any) -> None:
            def observe(_rover_id: str, role: str, frame: Any) -> None:
                if role not in samples or frame.cmd != "pose":
                    return
                cell = system.actors.whereis(f"{role}/nav")
                spread = getattr(cell.actor, "spread", None) if cell is not None else None
                if spread is None:
                    return
                t = system.world.true_pose(role)
                d = frame.data
                samples[role].append((t.x, t.y, t.heading_deg, d["x"], d["y"], d["heading"],
                                      spread.radius95_cm, spread.heading95_deg))

            system.server.observe_frames(observe)

        def finished(self, system: Any, report: Any) -> None:
            pass

    seed_trio_scheduler(seed)
    report = trio.run(lambda: run_game(load_scenario(name), seed, observers=[Sampler()]),
                      clock=virtual_clock())
    out: dict[str, Any] = {"scenario": name, "seed": seed, "outcome": report.outcome,
                           "trace_hash": report.trace_hash}
    for role, rows in samples.items():
        out[role] = calibration(rows)
    return out


def calibration(rows: list[tuple[float, ...]]) -> dict[str, Any] | None:
    """Shares of frames whose true error lies within the belief's 95 % radius and heading.

    ``rows`` are (true x, y, heading, reported x, y, heading, radius95, heading95), the
    true pose in the room frame and the reported one in the map frame, translated
    into each other by the offset at the first row.
    """
    if not rows:
        return None
    ox, oy = rows[0][0] - rows[0][3], rows[0][1] - rows[0][4]
    in_xy = in_h = 0
    worst = 0.0
    for tx, ty, th, x, y, h, r95, h95 in rows:
        err = math.hypot(tx - ox - x, ty - oy - y)
        err_h = abs((th - h + 180.0) % 360.0 - 180.0)
        in_xy += err <= r95
        in_h += err_h <= h95
        worst = max(worst, err - r95)
    n = len(rows)
    return {"frames": n, "xy95": in_xy / n, "heading95": in_h / n, "worst_excess_cm": worst}


def _cell(c: dict[str, Any] | None) -> str:
    if c is None:
        return f"{'-':>28}"
    return f"{c['frames']:>5} {c['xy95']:>6.2f} {c['heading95']:>6.2f} {c['worst_excess_cm']:>7.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.calibration",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default=DEFAULT_SCENARIOS,
                    help=f"comma-separated built-in rooms (default {DEFAULT_SCENARIOS})")
    ap.add_argument("--seeds", default="6-7", help="seeds, e.g. 6-7 or 6,9 (default 6-7)")
    ap.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    args = ap.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as exc:
        print(f"benchmarks.calibration: {exc}", file=sys.stderr)
        return 2
    jobs = [(name, seed) for name in args.scenarios.split(",") for seed in seeds]
    if args.workers > 1:
        with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
            rows = pool.map(play_one, jobs)
    else:
        rows = [play_one(job) for job in jobs]
    head = "frames   xy95   hd95  excess"
    print(f"{'scenario':<10} {'seed':>4} {'outcome':<8} hider {head:>23}   seeker {head:>23}")
    for r in rows:
        print(f"{r['scenario']:<10} {r['seed']:>4} {r['outcome']:<8} "
              f"{_cell(r['hider'])}   {_cell(r['seeker'])}")
    print(json.dumps({"benchmark": "calibration", "games": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
