"""Seeded procedural rooms for campaigns.

`generate` draws a room (4..9 m by 3..7 m), 3..12 boxes and round obstacles
kept apart by at least a rover's passage (40 cm) and out of the start corner,
then picks the hide spot among floor the hider can actually drive to (obstacles
inflated by 15 cm, a rover's half diagonal plus clearance) far from the start,
and two seek guesses (a decoy, then the hide spot). The scenario is emitted as
TOML and parsed back, so it passes the same validation as a file. The same
(seed, index) always gives the same room.
"""

from __future__ import annotations

import numpy as np
import shapely

from world.geometry import circle, room_polygon, union
from world.scenario import Scenario, parse_scenario
from world.truth import flood_fill

STARTS = {"mapper": (50, 50, 0), "hider": (50, 110, 0), "seeker": (50, 170, 0)}
START_ZONE = shapely.box(0, 0, 120, 230)
PASSAGE_CM = 40.0
CLEARANCE_CM = 15.0
MAX_TRIES = 400


def generate(seed: int, index: int = 0) -> Scenario:
    """The procedural scenario number ``index`` of campaign ``seed``."""
    rng = np.random.default_rng([int(seed), int(index)])
    w = float(rng.integers(40, 91) * 10)
    h = float(rng.integers(30, 71) * 10)
    want = int(rng.integers(3, 13))
    obstacles: list[tuple[str, list[float]]] = []
    geoms: list = []
    keep_out = START_ZONE.buffer(PASSAGE_CM)
    for _ in range(MAX_TRIES):
        if len(geoms) >= want:
            break
        g, spec = random_obstacle(rng, w, h)
        if g.intersects(keep_out) or any(g.distance(o) < PASSAGE_CM for o in geoms):
            continue
        geoms.append(g)
        obstacles.append(spec)
    hide, decoy = _spots(rng, w, h, geoms)
    heading = float(rng.integers(0, 4) * 90)
    return room_scenario(f"generated-{seed}-{index}",
                         f"Procedural room {index} of campaign seed {seed}.",
                         f"generated:{seed}/{index}", (w, h), obstacles,
                         (*hide, heading), decoy)


def random_obstacle(rng: np.random.Generator, w: float, h: float, box_cm: int = 120,
                    radius_cm: int = 40) -> tuple[shapely.Geometry, tuple[str, list[float]]]:
    """A box (60 %: sides 20..``box_cm`` on a 10 cm grid) or a round obstacle (radius
    10..``radius_cm``) inside a ``w`` x ``h`` room [cm]: (geometry, scenario spec)."""
    if rng.random() < 0.6:
        top = box_cm // 10 + 1
        bw, bh = float(rng.integers(2, top) * 10), float(rng.integers(2, top) * 10)
        x = float(rng.integers(0, int(w - bw) // 10 + 1) * 10)
        y = float(rng.integers(0, int(h - bh) // 10 + 1) * 10)
        return shapely.box(x, y, x + bw, y + bh), ("box", [x, y, bw, bh])
    r = float(rng.integers(10, radius_cm + 1))
    cx = float(rng.uniform(r + 1, w - r - 1))
    cy = float(rng.uniform(r + 1, h - r - 1))
    return circle(cx, cy, r), ("circle", [round(cx, 1), round(cy, 1), r])


def room_scenario(name: str, description: str, source: str, size: tuple[float, float],
                  obstacles: list[tuple[str, list[float]]],
                  hide: tuple[float, float, float], decoy: tuple[float, float]) -> Scenario:
    """A generated room as TOML, parsed back (so it passes a file's validation): the
    rovers at `STARTS`, the hide spot ``(x, y, heading)`` and guesses (decoy, hide spot)."""
    w, h = size
    lines = [f'name = "{name}"', f'description = "{description}"',
             "[room]", f"size_cm = [{w:g}, {h:g}]"]
    for kind, vals in obstacles:
        lines += ["[[obstacles]]", f"{kind} = [{', '.join(f'{v:g}' for v in vals)}]"]
    lines.append("[rovers]")
    lines += [f"{role} = [{x}, {y}, {a}]" for role, (x, y, a) in STARTS.items()]
    lines += ["[game]", f"hide_at = [{hide[0]:g}, {hide[1]:g}, {hide[2]:g}]",
              f"seek_at = [[{decoy[0]:g}, {decoy[1]:g}], [{hide[0]:g}, {hide[1]:g}]]"]
    return parse_scenario("\n".join(lines) + "\n", source)


def _spots(rng: np.random.Generator, w: float, h: float,
           geoms: list) -> tuple[tuple[float, float], tuple[float, float]]:
    """A far reachable hide spot and a decoy guess, cell centres at 5 cm [cm]."""
    res = 5.0
    floor = room_polygon(w, h)
    blocked = union([*(g.buffer(CLEARANCE_CM) for g in geoms),
                     floor.difference(floor.buffer(-CLEARANCE_CM))])
    nx, ny = int(w // res), int(h // res)
    xs, ys = np.meshgrid((np.arange(nx) + 0.5) * res, (np.arange(ny) + 0.5) * res)
    free = ~shapely.contains_xy(blocked, xs, ys)
    sx, sy, _ = STARTS["mapper"]
    reach = flood_fill(free, (int(sy // res), int(sx // res)))
    rows, cols = np.nonzero(reach)
    d = np.hypot(xs[rows, cols] - sx, ys[rows, cols] - sy)
    far = np.nonzero(d >= np.quantile(d, 0.7))[0]
    k = far[int(rng.integers(len(far)))]
    j = int(rng.integers(len(rows)))
    return ((float(xs[rows[k], cols[k]]), float(ys[rows[k], cols[k]])),
            (float(xs[rows[j], cols[j]]), float(ys[rows[j], cols[j]])))
