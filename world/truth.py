"""Ground-truth occupancy raster of a scenario (5 cm cells by default).

Cell ``[j, i]`` covers x in ``[i*r, (i+1)*r)`` and y in ``[j*r, (j+1)*r)`` of
the room frame (row 0 at the bottom, as maps are stored). A cell is occupied
when an obstacle overlaps its interior. Reachable cells are the free cells
4-connected to the mapper's start cell: the ground a LIDAR on the floor could
see by driving around, with no inflation for the rover's size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from world.geometry import union
from world.scenario import Scenario

#: flood fill gives up after this many sweeps (far more than any room needs)
MAX_FILL_SWEEPS = 100_000


@dataclass(frozen=True, slots=True)
class TruthGrid:
    """Ground truth at a fixed resolution, origin at the room's (0, 0)."""

    occupied: np.ndarray
    """bool (ny, nx): an obstacle overlaps the cell."""
    reachable: np.ndarray
    """bool (ny, nx): free and connected to the mapper's start."""
    resolution_cm: float


def truth_raster(scenario: Scenario, resolution_cm: float = 5.0) -> TruthGrid:
    """Rasterise a scenario's obstacles and flood-fill the reachable floor."""
    if resolution_cm <= 0:
        raise ValueError(f"resolution_cm must be > 0, got {resolution_cm!r}")
    w, h = scenario.room_size
    nx, ny = int(np.ceil(w / resolution_cm)), int(np.ceil(h / resolution_cm))
    occ = np.zeros((ny, nx), dtype=bool)
    if scenario.obstacles:
        occ = _overlapped(union(list(scenario.obstacles)), (w, h), resolution_cm, (ny, nx))
    start = scenario.starts["mapper"]
    seed = (min(int(start.y // resolution_cm), ny - 1), min(int(start.x // resolution_cm), nx - 1))
    return TruthGrid(occ, flood_fill(~occ, seed), resolution_cm)


def _overlapped(obs: shapely.Geometry, room: tuple[float, float], r: float,
                shape: tuple[int, int]) -> np.ndarray:
    """Whether ``obs`` overlaps each cell's interior (the cell shrunk by 1e-6 cm, clipped
    to the room): bool ``shape``.

    A cell whose centre lies in ``obs`` overlaps it, and one whose centre is farther
    from ``obs`` than half its diagonal does not: each is decided from its centre alone
    (`shapely.intersects_xy`, no geometry made). Only the cells of the band between,
    round the obstacles' outlines, are made as boxes and intersected, which is what
    deciding every cell that way cost (a box per cell, a room's ten thousand).
    """
    ny, nx = shape
    w, h = room
    e = 1e-6
    x0, y0 = np.meshgrid(np.arange(nx) * r, np.arange(ny) * r)
    x1, y1 = np.minimum(x0 + r, w) - e, np.minimum(y0 + r, h) - e
    x0, y0 = x0 + e, y0 + e
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)  # inside the box, whatever its rounding
    shapely.prepare(obs)
    inside = shapely.intersects_xy(obs, cx, cy)
    # the buffer's arcs are chords inside the true buffer: a buffer of a whole cell holds
    # every point within r * cos(pi / 32) of obs, more than the half diagonal r / sqrt(2)
    near = shapely.buffer(obs, r)
    shapely.prepare(near)
    band = ~inside & shapely.intersects_xy(near, cx, cy)
    band |= (x1 - x0 < 4 * e) | (y1 - y0 < 4 * e)  # a sliver at the room's edge: exactly
    occ = inside.copy()
    occ[band] = shapely.intersects(obs, shapely.box(x0[band], y0[band], x1[band], y1[band]))
    return occ


def flood_fill(free: np.ndarray, seed: tuple[int, int]) -> np.ndarray:
    """Cells of ``free`` 4-connected to ``seed`` (row, col), by repeated dilation."""
    out = np.zeros_like(free)
    if not free[seed]:
        return out
    out[seed] = True
    for _ in range(MAX_FILL_SWEEPS):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        grown &= free
        if np.array_equal(grown, out):
            break
        out = grown
    return out
