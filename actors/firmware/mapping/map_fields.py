"""The fields Map Management matches scans against, built from its grid, and a restore.

`build_fields` turns the occupancy grid's obstacle surfaces (its known part)
into the scan matcher's `scan_match.MatchFields` and the scan likelihood's
`localisation.distance_field.DistanceField`. Units: [cm], cells of the grid.
"""

from __future__ import annotations

import numpy as np

from actors.firmware.arrays import pad_border
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.mapping.occupancy import OCCUPIED, OccupancyGrid
from actors.firmware.mapping.scan_match import BLUR_WIDE, MatchFields
from server.protocol.grid_map import GridMap

__all__ = ["build_fields", "max3", "restore_unknown"]


def max3(values: np.ndarray) -> np.ndarray:
    """Maximum over each cell's 3 x 3 neighbourhood."""
    p = pad_border(values)
    rows = np.maximum(np.maximum(p[:-2], p[1:-1]), p[2:])
    return np.maximum(np.maximum(rows[:, :-2], rows[:, 1:-1]), rows[:, 2:])


def build_fields(grid: OccupancyGrid) -> tuple[MatchFields, DistanceField]:
    """Matching fields of the grid's obstacle surfaces (known part only), and the
    distance field of its snapshot.

    The returns splatted on the cell centres (`OccupancyGrid.hit_counts`) near
    occupied cells, relative to the most hit centre around (3 x 3): where the
    returns fell, not which cells are occupied, says where a wall's face is. A face
    on a cell edge weighs on both sides equally, so the ridge lies on the edge; the
    band a wall grows behind its face (returns a little beyond it are never cleared
    by rays from behind) holds few returns, so it barely pulls.
    """
    snap = grid.snapshot()  # its classes are the log-odds' (occupied: over the threshold)
    known = snap.known_bounds()  # every occupied cell is known: one pass finds both
    res = grid.resolution_cm
    rows = cols = np.zeros(0, dtype=np.int64)
    if known is not None:
        kr0, kr1, kc0, kc1 = known
        occupied = snap.cells[kr0:kr1, kc0:kc1] == OCCUPIED
        rows = np.flatnonzero(occupied.any(axis=1)) + kr0
        cols = np.flatnonzero(occupied.any(axis=0)) + kc0
    if rows.size == 0:
        fields = MatchFields(np.zeros((1, 1), dtype=bool), grid.origin_cm, res)
    else:
        k = BLUR_WIDE + 2
        r0, r1 = max(0, int(rows[0]) - k), int(rows[-1]) + k + 1
        c0, c1 = max(0, int(cols[0]) - k), int(cols[-1]) + k + 1
        occupied = snap.cells[r0:r1, c0:c1] == OCCUPIED
        near_occ = max3(occupied.astype(np.float32)) > 0
        hits = np.where(near_occ, grid.hit_counts()[r0:r1, c0:c1], 0.0)
        weights = hits / np.maximum(max3(hits), 1.0)
        origin = (grid.origin_cm[0] + c0 * res, grid.origin_cm[1] + r0 * res)
        fields = MatchFields(weights, origin, res)
    return fields, DistanceField.from_grid(snap, known_bounds=known)


def restore_unknown(grid: OccupancyGrid, snap: GridMap) -> bool | None:
    """Seed the cells ``grid`` has not observed from ``snap`` (a restarted Map
    Management's ``MAP_RESTORE``): whether a cell changed class, None when ``snap`` does
    not overlap the grid.

    Raises:
        ValueError: ``snap``'s resolution is not the grid's.
    """
    if abs(snap.resolution_cm - grid.resolution_cm) > 1e-9:
        raise ValueError(f"MAP_RESTORE needs resolution {grid.resolution_cm} cm, "
                         f"got {snap.resolution_cm}")
    r0, c0 = grid.world_to_cell(snap.origin_cm[0] + 1e-6, snap.origin_cm[1] + 1e-6)
    ny, nx = snap.shape
    gy, gx = grid.shape
    rs, cs = max(0, r0), max(0, c0)
    re, ce = min(gy, r0 + ny), min(gx, c0 + nx)
    if rs >= re or cs >= ce:
        return None
    src = snap.cells[rs - r0:re - r0, cs - c0:ce - c0]
    return bool(grid.fill_unknown(rs, cs, src))
