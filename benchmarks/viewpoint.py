"""Benchmark of one exploration decision's viewpoint scoring (`planning/viewpoint.py`).

Run from the repo root::

    python -m benchmarks.viewpoint [--reps 5] [--json]

The map: a furnished 6 x 4.5 m room (5 cm cells) with four boxes whose insides
were never seen and a part of the room not seen yet, scored from one rover
position with the mapper's quantities (`face_field` then `viewpoints`). The
figure is the best CPU time of ``--reps`` decisions [ms]: CPU time, so the
load of a shared machine does not decide it; the best, as the floor of what
one decision costs. A decision is taken a few times per simulated second
while mapping, so a few ms each keeps mapping well ahead of real time.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from actors.firmware.planning.viewpoint import face_field, viewpoints
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

RES_CM = 5.0
RANGE_CM = 250.0
VIEW = {"robot_radius_cm": 7.5, "margin_cm": 0.0, "stand_radius_cm": 12.5,
        "max_incidence_deg": 70.0, "min_face_cells": 2}
"""The mapper's quantities (as the viewpoint tests use them)."""
ROVER = (100.0, 100.0)  # [cm]


def furnished_room() -> GridMap:
    """The benchmark's map (see the module docstring)."""
    rows, cols = 90, 120
    cells = np.full((rows + 6, cols + 6), UNKNOWN, dtype=np.int8)
    cells[2:rows + 4, 2:cols + 4] = OCCUPIED
    cells[3:rows + 3, 3:cols + 3] = FREE
    for r0, c0 in ((20, 20), (20, 70), (60, 40), (60, 90)):
        cells[r0:r0 + 12, c0:c0 + 16] = OCCUPIED
        cells[r0 + 1:r0 + 11, c0 + 1:c0 + 15] = UNKNOWN
    cells[40:60, 100:123] = UNKNOWN
    return GridMap(cells, RES_CM, (0.0, 0.0))


def measure(reps: int) -> dict:
    """CPU time of ``reps`` decisions on `furnished_room`: best and median [ms]."""
    grid = furnished_room()
    times, found = [], 0
    for _ in range(reps):
        t0 = time.process_time()
        found = len(viewpoints(face_field(grid, range_cm=RANGE_CM), ROVER, **VIEW))
        times.append((time.process_time() - t0) * 1000.0)
    return {"reps": reps, "viewpoints": found, "best_ms": min(times),
            "median_ms": float(np.median(times))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.viewpoint", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=5, help="decisions timed (default 5)")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args(argv)
    if args.reps < 1:
        print(f"viewpoint: --reps must be at least 1, got {args.reps}", file=sys.stderr)
        return 2
    figures = measure(args.reps)
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"viewpoint scoring, furnished 6 x 4.5 m room: {figures['viewpoints']} viewpoints; "
          f"CPU per decision best {figures['best_ms']:.1f} ms, median "
          f"{figures['median_ms']:.1f} ms over {args.reps}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
