"""Seeded procedural rooms whose parts are joined only by narrow passages.

`generate_passages` draws a room (5..8 m by 3..5 m) cut across by one or two
walls (10..40 cm thick) that run from the bottom wall to the top wall, each with
one gap `PASSAGE_RANGE_CM` wide (25..45 cm: a rover's body is 15 cm wide), plus
0..3 boxes and round obstacles kept well away (`CLUTTER_GAP_CM`) from the walls,
each other and the start corner, so the gaps are the room's only narrow places.
The hide spot lies beyond the last wall and the decoy guess before the first, so
the hider and the seeker must each cross every passage. Spots are cells the hider
can turn on (obstacles inflated by `world.generator.CLEARANCE_CM`) that connect to
the start through floor a rover's body fits along (`BODY_CLEARANCE_CM`). The same
(seed, index) always gives the same room.
"""

from __future__ import annotations

import numpy as np
import shapely

from world.generator import CLEARANCE_CM, START_ZONE, STARTS, random_obstacle, room_scenario
from world.geometry import room_polygon, union
from world.scenario import Scenario

FAMILY = "passages"
#: width of each passage [cm]
PASSAGE_RANGE_CM = (25.0, 45.0)
#: free space between the clutter and the walls, the room's sides and other clutter [cm]
CLUTTER_GAP_CM = 60.0
#: half a rover's width plus a margin [cm]: floor farther than this from everything is
#: floor the body fits along (driving straight, not turning)
BODY_CLEARANCE_CM = 8.5
#: the first wall stands at least this far right of the start zone [cm]
WALL_MARGIN_CM = 100.0
#: walls at least this far apart [cm], and the last one at least this far from the far wall
WALL_SPACING_CM = 150.0
#: the gap keeps at least this much wall on each side [cm]
END_WALL_CM = 30.0
_SEED_TAG = 34          # keeps this family's draws apart from `world.generator.generate`'s
_MAX_TRIES = 400
_CELL_CM = 5.0


def generate_passages(seed: int, index: int = 0) -> Scenario:
    """The passage room number ``index`` of campaign ``seed``."""
    rng = np.random.default_rng([int(seed), int(index), _SEED_TAG])
    w = float(rng.integers(50, 81) * 10)
    h = float(rng.integers(30, 51) * 10)
    first = float(START_ZONE.bounds[2] + WALL_MARGIN_CM)
    walls = 2 if w - first >= 3 * WALL_SPACING_CM and rng.random() < 0.5 else 1
    span = (w - WALL_SPACING_CM - first) / walls
    obstacles: list[tuple[str, list[float]]] = []
    geoms: list = []
    wall_x: list[tuple[float, float]] = []
    for k in range(walls):
        t = float(rng.integers(2, 9) * 5)
        x = float(np.floor((first + k * span + rng.uniform(0, span - WALL_SPACING_CM / 2 - t))
                           / 5) * 5)
        gap = round(float(rng.uniform(*PASSAGE_RANGE_CM)), 1)
        y0 = round(float(rng.uniform(END_WALL_CM, h - END_WALL_CM - gap)), 1)
        for y, bh in ((0.0, y0), (y0 + gap, round(h - y0 - gap, 1))):
            obstacles.append(("box", [x, y, t, bh]))
            geoms.append(shapely.box(x, y, x + t, y + bh))
        wall_x.append((x, x + t))
    _clutter(rng, w, h, obstacles, geoms)
    hide, decoy = _spots(rng, w, h, geoms, wall_x[0][0], wall_x[-1][1])
    heading = float(rng.integers(0, 4) * 90)
    return room_scenario(f"passages-{seed}-{index}",
                         f"Passage room {index} of campaign seed {seed}.",
                         f"generated:{FAMILY}:{seed}/{index}", (w, h), obstacles,
                         (*hide, heading), decoy)


def _clutter(rng: np.random.Generator, w: float, h: float,
             obstacles: list[tuple[str, list[float]]], geoms: list) -> None:
    """Add 0..3 boxes and round obstacles, `CLUTTER_GAP_CM` clear of everything."""
    sides = room_polygon(w, h).exterior
    keep_out = START_ZONE.buffer(CLUTTER_GAP_CM)
    want = len(geoms) + int(rng.integers(0, 4))
    for _ in range(_MAX_TRIES):
        if len(geoms) >= want:
            return
        g, spec = random_obstacle(rng, w, h, box_cm=80, radius_cm=30)
        if (g.intersects(keep_out) or g.distance(sides) < CLUTTER_GAP_CM
                or any(g.distance(o) < CLUTTER_GAP_CM for o in geoms)):
            continue
        geoms.append(g)
        obstacles.append(spec)


def _spots(rng: np.random.Generator, w: float, h: float, geoms: list, before_x: float,
           after_x: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """A hide spot beyond ``after_x`` and a decoy before ``before_x`` [cm], both cells a
    rover can turn on and reach from the start through the passages."""
    floor = room_polygon(w, h)
    obstacles = union(geoms)
    turn = floor.buffer(-CLEARANCE_CM).difference(obstacles.buffer(CLEARANCE_CM))
    fits = floor.buffer(-BODY_CLEARANCE_CM).difference(obstacles.buffer(BODY_CLEARANCE_CM))
    sx, sy, _ = STARTS["mapper"]
    start = shapely.Point(sx, sy)
    reach = next(p for p in getattr(fits, "geoms", [fits]) if p.intersects(start))
    nx, ny = int(w // _CELL_CM), int(h // _CELL_CM)
    xs, ys = np.meshgrid((np.arange(nx) + 0.5) * _CELL_CM, (np.arange(ny) + 0.5) * _CELL_CM)
    ok = shapely.contains_xy(turn, xs, ys) & shapely.contains_xy(reach, xs, ys)
    far = np.argwhere(ok & (xs > after_x + CLEARANCE_CM))
    near = np.argwhere(ok & (xs < before_x - CLEARANCE_CM) & (xs > START_ZONE.bounds[2]))
    if len(far) == 0 or len(near) == 0:
        raise RuntimeError("passage room without reachable spots on both sides")
    j, i = far[int(rng.integers(len(far)))]
    dj, di = near[int(rng.integers(len(near)))]
    return (float(xs[j, i]), float(ys[j, i])), (float(xs[dj, di]), float(ys[dj, di]))
