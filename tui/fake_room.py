"""The fake system's room: its ground truth, the mapper's tour, and LIDAR ray casting.

Pure functions and constants in the room frame [cm] (x right, y up, origin at
the room's lower left corner); `tui.fake.FakeSystem` drives its rovers through
this room, grows its map from `cast` and `carve` and exports it with `write_map`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tui.snapshot import FREE, OCCUPIED

__all__ = ["RES_CM", "ROOM_CM", "START_CM", "TOUR_CM", "BOXES_CM", "CIRCLE_CM", "LIDAR_RAYS",
           "LIDAR_RANGE_CM", "room_grid", "clearance", "RayCast", "cast", "carve", "write_map"]

#: Cell size of the truth grid and the map [cm].
RES_CM = 5.0
ROOM_CM = (400.0, 300.0)
#: The mapper's start in the room frame [cm]; the map frame's origin.
START_CM = (60.0, 60.0)
#: The mapper's tour in the room frame [cm] (straight legs are obstacle-free).
TOUR_CM = ((240.0, 50.0), (360.0, 140.0), (250.0, 180.0), (100.0, 250.0),
           (40.0, 160.0), (120.0, 170.0))
BOXES_CM = ((150.0, 90.0, 200.0, 150.0), (280.0, 210.0, 330.0, 270.0))
CIRCLE_CM = (330.0, 70.0, 25.0)
LIDAR_RAYS = 90
LIDAR_RANGE_CM = 400.0


def room_grid() -> np.ndarray:
    """Ground truth of the fake room: int8 (ny, nx), walls and obstacles occupied."""
    nx, ny = int(ROOM_CM[0] / RES_CM), int(ROOM_CM[1] / RES_CM)
    xs = (np.arange(nx) + 0.5) * RES_CM
    ys = (np.arange(ny) + 0.5) * RES_CM
    gx, gy = np.meshgrid(xs, ys)
    occ = (gx < 10) | (gx > ROOM_CM[0] - 10) | (gy < 10) | (gy > ROOM_CM[1] - 10)
    for x0, y0, x1, y1 in BOXES_CM:
        occ |= (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    cx, cy, r = CIRCLE_CM
    occ |= (gx - cx) ** 2 + (gy - cy) ** 2 <= r * r
    return np.where(occ, OCCUPIED, FREE).astype(np.int8)


def clearance(truth: np.ndarray, x: float, y: float) -> float:
    """Distance from (x, y) to the nearest occupied cell's centre [cm]."""
    occ = np.argwhere(truth == OCCUPIED)
    centres = (occ[:, ::-1] + 0.5) * RES_CM
    return float(np.min(np.hypot(centres[:, 0] - x, centres[:, 1] - y)))


@dataclass(frozen=True, slots=True)
class RayCast:
    """One revolution cast in the truth grid: each ray's cells and its first hit."""

    steps: np.ndarray
    """Distances sampled along every ray [cm]."""
    rows: np.ndarray
    cols: np.ndarray
    """Grid cell of each sample (rays x steps), clipped to the grid."""
    first: np.ndarray
    """Index of each ray's first occupied sample (the last sample when none)."""
    has: np.ndarray
    """Whether each ray hit something."""


def cast(truth: np.ndarray, x: float, y: float, angles: np.ndarray) -> RayCast:
    """Cast rays from (x, y) [cm] at ``angles`` [rad] up to `LIDAR_RANGE_CM`."""
    steps = np.arange(0.0, LIDAR_RANGE_CM, RES_CM / 2)
    xs = x + np.cos(angles)[:, None] * steps[None, :]
    ys = y + np.sin(angles)[:, None] * steps[None, :]
    ny, nx = truth.shape
    cols = np.clip((xs / RES_CM).astype(int), 0, nx - 1)
    rows = np.clip((ys / RES_CM).astype(int), 0, ny - 1)
    hit = truth[rows, cols] == OCCUPIED
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(steps) - 1)
    return RayCast(steps, rows, cols, first, hit.any(axis=1))


def carve(grid: np.ndarray, rays: RayCast) -> None:
    """Mark the cells each ray crossed free and the cells it hit occupied, in ``grid``."""
    mask = np.arange(len(rays.steps))[None, :] < rays.first[:, None]
    grid[rays.rows[mask], rays.cols[mask]] = FREE
    has = rays.has
    r = np.arange(len(has))[has]
    grid[rays.rows[r, rays.first[has]], rays.cols[r, rays.first[has]]] = OCCUPIED


def write_map(cells: np.ndarray, out: Path) -> Path:
    """Write a map grid (map frame: origin at `START_CM`) as ``map.pgm`` and ``map.yaml``
    in ``out`` (map_server's convention: 0 occupied, 254 free, 205 unknown, top row
    first); returns the PGM's path."""
    pgm = np.full(cells.shape, 205, np.uint8)
    pgm[cells == FREE] = 254
    pgm[cells == OCCUPIED] = 0
    ny, nx = cells.shape
    (out / "map.pgm").write_bytes(b"P5\n%d %d\n255\n" % (nx, ny) + pgm[::-1].tobytes())
    (out / "map.yaml").write_text(
        f"image: map.pgm\nresolution: {RES_CM / 100}\n"
        f"origin: [{-START_CM[0] / 100}, {-START_CM[1] / 100}, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return out / "map.pgm"
