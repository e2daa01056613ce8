"""Distance to the nearest mapped obstacle, precomputed for a grid map.

Why
    Every measurement model of the pose belief asks the same question of the
    map for thousands of points at once (a few hundred particles times the
    points of a body outline or a scan): how far is this point from the
    nearest occupied cell? A distance transform answers it for every cell in
    one pass; a point then costs one bilinear read. This is the "likelihood
    field" of Thrun et al. (below) and of Nav2 AMCL's ``likelihood_field``
    model, before the Gaussian is applied.

Algorithm
    Exact Euclidean distance transform (``scipy.ndimage.distance_transform_edt``)
    of the grid's non-occupied cells, in [cm] (``sampling`` = the cell side):
    the distance from each cell's centre to the nearest occupied cell's
    centre, 0 on occupied cells, capped at ``max_dist_cm``. Read at any point
    by bilinear interpolation between the four nearest cell centres, so the
    distance is continuous (a point moving across a cell does not jump by half
    a cell). Points off the grid read ``max_dist_cm`` and "unknown".

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, section 6.4 (likelihood
    fields for range finders); Nav2 ``nav2_amcl`` ``LikelihoodFieldModel``
    (``map_update_cspace``, ``max_occ_dist``).

Frame and units
    The grid's frame (the map frame) [cm]; cells as in `occupancy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from actors.firmware.mapping.occupancy import OCCUPIED, UNKNOWN, GridMap
from actors.firmware.ndimage import distance_transform_edt

__all__ = ["DistanceField"]


@dataclass(frozen=True, slots=True, eq=False)
class DistanceField:
    """Distance [cm] from every cell centre of a grid to the nearest occupied cell centre.

    Immutable; build one per map snapshot with `DistanceField.from_grid` (a
    snapshot is immutable too, so the field stays valid as long as the map it
    came from is the one in use). It covers the map's known cells widened by the
    cap (`_known_window`); every point outside reads as it would on the whole grid:
    unknown, the cap.
    """

    distance_cm: np.ndarray
    """float64 (ny, nx): distance to the nearest occupied cell's centre [cm], capped."""
    known: np.ndarray
    """bool (ny, nx): the cell is free or occupied (not unknown)."""
    resolution_cm: float
    """Cell side [cm]."""
    origin_cm: tuple[float, float]
    """Lower-left corner of cell [0, 0] (the window's) in the map frame [cm]."""
    max_dist_cm: float
    """The cap: no obstacle within this distance reads as this distance [cm]."""
    _occupied: np.ndarray = field(init=False, repr=False)
    # flat bool (ny * nx): the distance is 0 (an occupied cell), for `occupied_at`

    def __post_init__(self) -> None:
        object.__setattr__(self, "_occupied", (self.distance_cm == 0.0).reshape(-1))

    @classmethod
    def from_grid(cls, grid: GridMap, max_dist_cm: float = 50.0) -> DistanceField:
        """The field of a map snapshot.

        Args:
            grid: the map; only its occupied cells are obstacles.
            max_dist_cm: cap on the distance [cm] (a point this far from every
                obstacle is "far"; Nav2 AMCL's ``laser_likelihood_max_dist``).

        Raises:
            ValueError: when ``max_dist_cm`` is not a positive finite number.
        """
        if not (math.isfinite(max_dist_cm) and max_dist_cm > 0):
            raise ValueError(f"max_dist_cm must be positive, got {max_dist_cm!r}")
        cells, origin = _known_window(grid, max_dist_cm)
        occupied = cells == OCCUPIED
        if occupied.any():
            dist = distance_transform_edt(~occupied, sampling=grid.resolution_cm)
            dist = np.minimum(dist, max_dist_cm)
        else:
            dist = np.full(cells.shape, float(max_dist_cm))
        dist.flags.writeable = False
        known = cells != UNKNOWN
        known.flags.writeable = False
        return cls(dist, known, grid.resolution_cm, origin, float(max_dist_cm))

    def at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance to the nearest obstacle [cm] at points (x, y) [cm], any shape.

        Bilinear between the four nearest cell centres; ``max_dist_cm`` off the grid.
        """
        gx, gy, c0, r0 = self._corners(x, y)
        fx, fy = gx - c0, gy - r0
        d = self.distance_cm
        ny, nx = d.shape
        # clamp the corners onto the grid; points whose box leaves it read the cap
        inside = (c0 >= 0) & (r0 >= 0) & (c0 + 1 < nx) & (r0 + 1 < ny)
        c0c = np.clip(c0, 0, nx - 2) if nx > 1 else np.zeros_like(c0)
        r0c = np.clip(r0, 0, ny - 2) if ny > 1 else np.zeros_like(r0)
        c1c = np.minimum(c0c + 1, nx - 1)
        r1c = np.minimum(r0c + 1, ny - 1)
        v = ((1 - fx) * (1 - fy) * d[r0c, c0c] + fx * (1 - fy) * d[r0c, c1c]
             + (1 - fx) * fy * d[r1c, c0c] + fx * fy * d[r1c, c1c])
        return np.where(inside, v, self.max_dist_cm)

    def occupied_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether the cell holding each point (x, y) [cm] is occupied (False off the grid)."""
        flat, inside = self._cell(x, y)
        return inside & self._occupied[flat]

    def known_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether the cell holding each point (x, y) [cm] is known (False off the grid)."""
        flat, inside = self._cell(x, y)
        return inside & self.known.reshape(-1)[flat]

    def _cell(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The flat index of the cell holding each point (0 off the grid) and whether
        the point is on the grid (called per particle and body point: few passes)."""
        ox, oy = self.origin_cm
        res = self.resolution_cm
        c = np.floor((np.asarray(x, dtype=float) - ox) / res).astype(np.int64)
        r = np.floor((np.asarray(y, dtype=float) - oy) / res).astype(np.int64)
        ny, nx = self.distance_cm.shape
        # a negative index reads as a huge unsigned one: one comparison per axis
        inside = (r.view(np.uint64) < ny) & (c.view(np.uint64) < nx)
        return np.where(inside, r * nx + c, 0), inside

    def _corners(self, x: np.ndarray, y: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Point positions in cell-centre units and their lower-left neighbour centre."""
        ox, oy = self.origin_cm
        res = self.resolution_cm
        gx = (np.asarray(x, dtype=float) - ox) / res - 0.5
        gy = (np.asarray(y, dtype=float) - oy) / res - 0.5
        return gx, gy, np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)


def _known_window(grid: GridMap, max_dist_cm: float) -> tuple[np.ndarray, tuple[float, float]]:
    """The part of ``grid`` the field needs, and that part's lower-left corner [cm].

    Every occupied cell is known, so beyond the known cells' bounding box widened by
    the cap (and two cells, for the bilinear read) every cell is unknown and reads the
    cap: the same answers as the whole grid's field, which a mapper's grid (mostly
    unknown while it maps) would make costly to build every few batches.
    """
    known = grid.cells != UNKNOWN
    rows = np.flatnonzero(known.any(axis=1))
    if rows.size == 0:
        return grid.cells, grid.origin_cm
    cols = np.flatnonzero(known.any(axis=0))
    res = grid.resolution_cm
    k = int(math.ceil(max_dist_cm / res)) + 2
    r0, r1 = max(0, int(rows[0]) - k), int(rows[-1]) + k + 1
    c0, c1 = max(0, int(cols[0]) - k), int(cols[-1]) + k + 1
    return grid.cells[r0:r1, c0:c1], (grid.origin_cm[0] + c0 * res, grid.origin_cm[1] + r0 * res)

