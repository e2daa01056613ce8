"""Small synthetic rooms and a ray caster for the localisation tests.

Rooms are grid maps built from axis-aligned boxes (map frame [cm], 5 cm cells);
the caster marches rays over the grid itself, so a scan fits its map exactly
where the rover truly stands.
"""

from __future__ import annotations

import math

import numpy as np

from actors.firmware.mapping.occupancy import FREE, OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose

RES = 5.0
"""Cell side of every test room [cm]."""


def room(width_cm: float, height_cm: float, *boxes: tuple[float, float, float, float],
         unknown_beyond_x: float | None = None, margin_cm: float = 50.0) -> GridMap:
    """A walled room (walls one cell thick on its border) with obstacle boxes.

    The room spans (0, 0)..(width, height); the grid extends ``margin_cm`` beyond it
    with unknown cells, as a map does beyond the walls no ray crossed.

    Args:
        width_cm, height_cm: the room's outer size [cm].
        boxes: obstacles as (x, y, w, h) [cm]: cells whose centre lies inside are occupied.
        unknown_beyond_x: cells with a centre beyond this x are unknown (not yet mapped).
        margin_cm: unknown margin round the room [cm], a multiple of the cell side.
    """
    m = round(margin_cm / RES)
    ny, nx = round(height_cm / RES) + 2 * m, round(width_cm / RES) + 2 * m
    cells = np.full((ny, nx), UNKNOWN, np.int8)
    inner = cells[m:ny - m, m:nx - m]
    inner[...] = FREE
    inner[0, :] = inner[-1, :] = OCCUPIED
    inner[:, 0] = inner[:, -1] = OCCUPIED
    cx = (np.arange(nx) - m + 0.5) * RES
    cy = (np.arange(ny) - m + 0.5) * RES
    for x0, y0, w, h in boxes:
        mx = (cx > x0) & (cx < x0 + w)
        my = (cy > y0) & (cy < y0 + h)
        cells[np.ix_(my, mx)] = OCCUPIED
    if unknown_beyond_x is not None:
        cells[:, cx > unknown_beyond_x] = UNKNOWN
    return GridMap(cells, RES, (-m * RES, -m * RES))


def cast(grid: GridMap, pose: Pose, angles_deg: np.ndarray, max_cm: float = 600.0,
         step_cm: float = 0.25) -> np.ndarray:
    """Range [cm] to the first occupied cell along each ray from ``pose``; 0 for none."""
    t = np.arange(step_cm, max_cm, step_cm)
    a = np.radians(np.asarray(angles_deg, dtype=float)) + pose.heading_rad
    x = pose.x + np.cos(a)[:, None] * t[None, :]
    y = pose.y + np.sin(a)[:, None] * t[None, :]
    ox, oy = grid.origin_cm
    col = np.floor((x - ox) / grid.resolution_cm).astype(np.int64)
    row = np.floor((y - oy) / grid.resolution_cm).astype(np.int64)
    ny, nx = grid.shape
    inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
    hit = np.zeros_like(inside)
    hit[inside] = grid.cells[row[inside], col[inside]] == OCCUPIED
    first = np.argmax(hit, axis=1)
    return np.where(hit.any(axis=1), t[first], 0.0)


def turn_treads(turn_deg: float, track_width_cm: float) -> tuple[float, float]:
    """Left and right tread travel [cm] of an in-place turn by ``turn_deg``."""
    half = math.radians(turn_deg) * track_width_cm / 2
    return -half, half
