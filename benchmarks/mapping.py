"""Benchmark of the firmware's map algorithms: grid updates, A*, frontier search.

Run from the repo root::

    python -m benchmarks.mapping [--quick]

Each figure comes with a baseline measured in the same run, so the ratio is
meaningful on any machine:

* occupancy: `OccupancyGrid.integrate` on 360-ray revolutions in a 10 m x 8 m
  room (24 m x 24 m grid, 5 cm cells) vs. a plain Python per-ray, per-sample loop
  doing the same update.
* A*: `plan_path` on a 200 x 160 grid (a 10 m x 8 m hall with boxes and a long
  wall) vs. Dijkstra (the same search with a zero heuristic).
* frontier: `find_frontiers` on a half-explored hall vs. a plain Python loop
  computing only the frontier mask.
* scan matching: `scan_match.match_scan` of one tick's batch (100 rays, a
  100 deg wedge) from a guess 3 cm / 2.5 deg off, vs. integrating the same batch
  into the grid (what Map Management does with it anyway); with the pose error
  before and after the match.

Prints a table and, last, one line of JSON with the figures.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time

import numpy as np

from actors.firmware.hardware import HardwareSpec
from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.mapping.scan_match import MatchFields, MatchOptions, hits_to_local, match_scan
from actors.firmware.planning.clearance import turning_radius_cm
from actors.firmware.planning.frontier import find_frontiers
from actors.firmware.planning.grid_search import astar
from actors.firmware.planning.planner import plan_path, traversable
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose

ROOM = (-300.0, 700.0, -200.0, 600.0)  # x0, x1, y0, y1 [cm]: a 10 m x 8 m hall
_BODY = HardwareSpec.bench("mapper")
RADIUS_CM = turning_radius_cm(_BODY.length_cm, _BODY.width_cm)  # the bench rover's [cm]


def box_ranges(pose: Pose, angles_deg: np.ndarray) -> np.ndarray:
    """Exact ranges [cm] from ``pose`` to the hall's walls, rounded to 1 cm."""
    x0, x1, y0, y1 = ROOM
    th = np.radians(angles_deg + pose.heading_deg)
    c, s = np.cos(th), np.sin(th)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (x1 - pose.x) / c, np.where(c < 0, (x0 - pose.x) / c, np.inf))
        ty = np.where(s > 0, (y1 - pose.y) / s, np.where(s < 0, (y0 - pose.y) / s, np.inf))
    return np.round(np.minimum(tx, ty))


def python_integrate(grid: OccupancyGrid, pose: Pose, angles, ranges) -> None:
    """Baseline: the same update with Python loops (dedupe per batch with a set)."""
    m = grid.model
    res = grid.resolution_cm
    ox, oy = grid.origin_cm
    ny, nx = grid.shape
    lo = grid._log_odds  # noqa: SLF001 - baseline writes the same array
    free, hits = set(), set()
    for a, r in zip(angles.tolist(), ranges.tolist(), strict=True):
        hit = 0 < r <= m.max_range_cm
        length = r if hit else m.max_range_cm
        th = math.radians(a + pose.heading_deg)
        c, s = math.cos(th), math.sin(th)
        px, py = (pose.x - ox) / res, (pose.y - oy) / res
        n = math.ceil(length / res / m.ray_step)
        for i in range(n):
            t = i * m.ray_step
            col, row = math.floor(px + c * t), math.floor(py + s * t)
            if 0 <= col < nx and 0 <= row < ny:
                free.add((row, col))
        if hit:
            col = math.floor(px + c * length / res)
            row = math.floor(py + s * length / res)
            if 0 <= col < nx and 0 <= row < ny:
                hits.add((row, col))
    for rc in free - hits:
        lo[rc] = min(max(lo[rc] + m.l_free, m.l_min), m.l_max)
    for rc in hits:
        lo[rc] = min(max(lo[rc] + m.l_occ, m.l_min), m.l_max)


def timed(fn, repeat: int) -> float:
    """Mean seconds per call over ``repeat`` calls."""
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def hall_cells(rng: np.random.Generator) -> np.ndarray:
    """A 200 x 160 hall of 5 cm cells: walls, 25 boxes and a long wall with a gap."""
    cells = np.zeros((160, 200), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    for _ in range(25):
        r, c = rng.integers(5, 150), rng.integers(5, 190)
        cells[r:r + 8, c:c + 8] = OCCUPIED
    cells[:120, 100] = OCCUPIED
    cells[60:70, 20:30] = FREE  # keep the start clear
    cells[60:70, 170:180] = FREE  # keep the goal clear
    return cells


def python_frontier_mask(cells: np.ndarray) -> int:
    """Baseline: frontier mask with Python loops; returns the count."""
    ny, nx = cells.shape
    rows = cells.tolist()
    n = 0
    for r in range(ny):
        for c in range(nx):
            if rows[r][c] != FREE:
                continue
            for rr, cc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
                if 0 <= rr < ny and 0 <= cc < nx and rows[rr][cc] == UNKNOWN:
                    n += 1
                    break
    return n


Row = tuple[str, str, str, str]
"""One table row: case, time, baseline, ratio."""


def _bench_occupancy(rng: np.random.Generator, rep: int, figures: dict[str, float],
                     rows: list[Row]) -> tuple[np.ndarray, list[Pose], list]:
    """Grid update, vectorised against Python loops; returns the angles, poses and scans
    the later cases reuse."""
    angles = np.arange(0.0, 360.0, 1.0)
    poses = [Pose(float(rng.uniform(-250, 650)), float(rng.uniform(-150, 550)),
                  float(rng.uniform(-180, 180))) for _ in range(8)]
    scans = [(p, box_ranges(p, angles)) for p in poses]
    grid = OccupancyGrid()
    base = OccupancyGrid()
    turn = itertools.cycle(scans)

    def vectorised() -> None:
        pose, ranges = next(turn)
        grid.integrate(pose, angles, ranges)

    def python_loops() -> None:
        pose, ranges = next(turn)
        python_integrate(base, pose, angles, ranges)

    t_vec = timed(vectorised, rep * 5)
    t_py = timed(python_loops, max(2, rep // 10))
    figures["occupancy_rev_per_s"] = 1 / t_vec
    figures["occupancy_python_rev_per_s"] = 1 / t_py
    figures["occupancy_speedup"] = t_py / t_vec
    rows.append(("occupancy integrate (360 rays)", f"{t_vec * 1e3:.2f} ms",
                 f"{t_py * 1e3:.1f} ms (python loops)", f"x{t_py / t_vec:.1f}"))
    return angles, poses, scans


def _bench_astar(rng: np.random.Generator, rep: int, figures: dict[str, float],
                 rows: list[Row]) -> None:
    """A* on a hall, against Dijkstra (A* with no heuristic), and the inflation."""
    m = GridMap(hall_cells(rng), 5.0, (0.0, 0.0))
    passable = traversable(m, RADIUS_CM)
    start, goal = (125.0, 325.0), (875.0, 325.0)
    plan = plan_path(m, start, goal, robot_radius_cm=RADIUS_CM, passable=passable)
    assert plan is not None, "benchmark hall must be solvable"
    t_astar = timed(lambda: plan_path(m, start, goal, robot_radius_cm=RADIUS_CM,
                                      passable=passable), rep)
    s_cell, g_cell = m.world_to_cell(*start), m.world_to_cell(*goal)
    dijkstra = astar(passable, s_cell, g_cell, heuristic_weight=0.0)
    t_dij = timed(lambda: astar(passable, s_cell, g_cell, heuristic_weight=0.0),
                  max(2, rep // 4))
    t_inflate = timed(lambda: traversable(m, RADIUS_CM), rep)
    figures.update(astar_ms=t_astar * 1e3, dijkstra_ms=t_dij * 1e3,
                   astar_speedup=t_dij / t_astar, astar_expanded=plan.expanded,
                   dijkstra_expanded=dijkstra[2], inflate_ms=t_inflate * 1e3,
                   path_cm=plan.length_cm, waypoints=len(plan.waypoints_cm))
    rows.append(("A* 200x160 (plan_path)", f"{t_astar * 1e3:.1f} ms",
                 f"{t_dij * 1e3:.1f} ms (dijkstra)", f"x{t_dij / t_astar:.1f}"))
    rows.append(("  expanded nodes", str(plan.expanded), str(dijkstra[2]), ""))
    rows.append(("inflate 200x160 (traversable)", f"{t_inflate * 1e3:.2f} ms", "", ""))


def _bench_frontier(angles: np.ndarray, poses: list[Pose], scans: list, rep: int,
                    figures: dict[str, float], rows: list[Row]) -> None:
    """Frontier search, against the frontier mask computed in Python."""
    explored = OccupancyGrid()
    for p, r in scans[:3]:
        explored.integrate(p, angles, r)
    snap = explored.snapshot()
    at = (poses[0].x, poses[0].y)
    fs = find_frontiers(snap, at, robot_radius_cm=RADIUS_CM)
    t_front = timed(lambda: find_frontiers(snap, at, robot_radius_cm=RADIUS_CM), rep)
    crop = snap.crop_known(8).cells
    t_mask_py = timed(lambda: python_frontier_mask(crop), max(2, rep // 4))
    figures.update(frontier_ms=t_front * 1e3, frontier_mask_python_ms=t_mask_py * 1e3,
                   frontier_clusters=len(fs), frontier_ratio=t_mask_py / t_front)
    rows.append((f"find_frontiers {crop.shape[1]}x{crop.shape[0]} ({len(fs)} clusters)",
                 f"{t_front * 1e3:.1f} ms", f"{t_mask_py * 1e3:.1f} ms (python mask only)",
                 f"x{t_mask_py / t_front:.1f}"))


def _bench_scan_match(angles: np.ndarray, poses: list[Pose], scans: list, rep: int,
                      figures: dict[str, float], rows: list[Row]) -> None:
    """Scan matching a 100-ray wedge, against integrating it, and the pose error."""
    ref = OccupancyGrid()
    for p, r in scans:
        ref.integrate(p, angles, r)
    occ = ref.log_odds() > ref.model.occ_threshold
    fields = MatchFields(np.where(occ, 1.0, 0.0), ref.origin_cm, ref.resolution_cm)
    wedge = np.arange(0.0, 100.0, 1.0)
    cases = []
    for k, p in enumerate(poses):
        a = (wedge + 45.0 * k) % 360.0
        pts = hits_to_local(a, box_ranges(p, a), MatchOptions())
        guess = Pose(p.x + 3.0, p.y - 2.0, p.heading_deg + 2.5)
        cases.append((p, a, pts, guess))
    case = itertools.cycle(cases)

    def matching() -> None:
        _, _, pts, guess = next(case)
        match_scan(fields, pts, guess)

    def integrating() -> None:
        p, a, _, _ = next(case)
        ref.integrate(p, a, box_ranges(p, a))

    t_match = timed(matching, rep * 5)
    t_int = timed(integrating, rep * 5)
    errs = []
    for p, _, pts, guess in cases:
        res = match_scan(fields, pts, guess).pose
        errs.append((math.dist((res.x, res.y), (p.x, p.y)),
                     abs(res.heading_deg - p.heading_deg)))
    err_cm = float(np.mean([e[0] for e in errs]))
    err_deg = float(np.mean([e[1] for e in errs]))
    figures.update(match_ms=t_match * 1e3, match_integrate_ms=t_int * 1e3,
                   match_ratio=t_match / t_int, match_err_cm=err_cm, match_err_deg=err_deg)
    rows.append(("scan match, 100-ray wedge", f"{t_match * 1e3:.2f} ms",
                 f"{t_int * 1e3:.2f} ms (integrate it)", f"x{t_match / t_int:.1f}"))
    rows.append(("  pose error 3.6 cm / 2.5 deg ->", f"{err_cm:.2f} cm / {err_deg:.2f} deg",
                 "", ""))


def _print_rows(rows: list[Row]) -> None:
    widths = [max(len(r[i]) for r in rows + [("case", "time", "baseline", "ratio")])
              for i in range(4)]
    header = ("case", "time", "baseline", "ratio")
    print("  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)))


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args(argv)
    rep = 5 if args.quick else 40
    rng = np.random.default_rng(1)
    figures: dict[str, float] = {}
    rows: list[Row] = []
    angles, poses, scans = _bench_occupancy(rng, rep, figures, rows)
    _bench_astar(rng, rep, figures, rows)
    _bench_frontier(angles, poses, scans, rep, figures, rows)
    _bench_scan_match(angles, poses, scans, rep, figures, rows)
    _print_rows(rows)
    out = {k: round(v, 3) if isinstance(v, float) else v for k, v in figures.items()}
    print(json.dumps(out))
    return out

if __name__ == "__main__":
    main()
