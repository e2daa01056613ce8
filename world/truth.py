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
        obs = union(list(scenario.obstacles))
        shapely.prepare(obs)
        r, e = resolution_cm, 1e-6
        xs = np.arange(nx) * r
        ys = np.arange(ny) * r
        x0, y0 = np.meshgrid(xs, ys)
        cells = shapely.box(x0 + e, y0 + e, np.minimum(x0 + r, w) - e, np.minimum(y0 + r, h) - e)
        occ = shapely.intersects(obs, cells)
    start = scenario.starts["mapper"]
    seed = (min(int(start.y // resolution_cm), ny - 1), min(int(start.x // resolution_cm), nx - 1))
    return TruthGrid(occ, flood_fill(~occ, seed), resolution_cm)


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
