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
    Exact Euclidean distance transform of the grid's non-occupied cells, in
    [cm]: the distance from each cell's centre to the nearest occupied cell's
    centre, 0 on occupied cells, capped at ``max_dist_cm`` (`capped_edt`: only
    obstacles within the cap are looked for; the floats of
    ``scipy.ndimage.distance_transform_edt``). Read at any point
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

from actors.firmware.localisation.capped_edt import capped_distance
from server.protocol.grid_map import OCCUPIED, UNKNOWN, GridMap

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
    _corners: np.ndarray = field(init=False, repr=False)
    # (4, ny * nx): row k of each column is the distance at the cell (r, c), (r, c + 1),
    # (r + 1, c), (r + 1, c + 1) of flat index r * nx + c: one gather reads a point's
    # four bilinear corners (past the last column or row it reads the cap, never used)
    _known_flat: np.ndarray = field(init=False, repr=False)
    # flat bool (ny * nx): `known`, raveled
    _rim_unknown: bool = field(init=False, repr=False)
    # the window's outermost cells are all unknown (what `_known_window` leaves round
    # the known cells): a point whose bilinear box leaves the window is then unknown

    def __post_init__(self) -> None:
        d = self.distance_cm
        ny, nx = d.shape
        n = d.size
        flat = d.reshape(-1)
        corners = np.empty((4, n))
        corners[0] = flat
        for row, shift in ((1, 1), (2, nx), (3, nx + 1)):
            corners[row, :max(n - shift, 0)] = flat[shift:]
            corners[row, max(n - shift, 0):] = self.max_dist_cm
        known = self.known
        rim = ny >= 2 and nx >= 2 and not (known[0].any() or known[-1].any()
                                           or known[:, 0].any() or known[:, -1].any())
        object.__setattr__(self, "_corners", corners)
        object.__setattr__(self, "_known_flat", known.reshape(-1))
        object.__setattr__(self, "_rim_unknown", rim)

    @classmethod
    def from_grid(cls, grid: GridMap, max_dist_cm: float = 50.0, *,
                  known_bounds: tuple[int, int, int, int] | None = None) -> DistanceField:
        """The field of a map snapshot.

        Args:
            grid: the map; only its occupied cells are obstacles.
            max_dist_cm: cap on the distance [cm] (a point this far from every
                obstacle is "far"; Nav2 AMCL's ``laser_likelihood_max_dist``).
            known_bounds: the grid's `GridMap.known_bounds` when the caller has it (a
                pass over the whole grid saved); None finds it here.

        Raises:
            ValueError: when ``max_dist_cm`` is not a positive finite number.
        """
        if not (math.isfinite(max_dist_cm) and max_dist_cm > 0):
            raise ValueError(f"max_dist_cm must be positive, got {max_dist_cm!r}")
        if known_bounds is None:
            known_bounds = grid.known_bounds()
        cells, origin = _known_window(grid, max_dist_cm, known_bounds)
        occupied = cells == OCCUPIED
        if occupied.any():
            dist = capped_distance(occupied, grid.resolution_cm, max_dist_cm)
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
        return self.at_known(x, y, known=False)[0]

    def at_known(self, x: np.ndarray, y: np.ndarray, *, known: bool = True,
                 near_cm: float | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """`at` and `known_at` of the same points (x, y) [cm] (any shape), in one pass.

        Why: a scan's likelihood reads both for every hit, and with a hundred hits a
        numpy call's fixed cost outweighs its arithmetic. The point's cell-centre
        coordinate ``g`` (what `at` interpolates at) gives its cell too: for a point
        whose bilinear box lies on the window, ``g >= 0`` holds and ``g + 1/2`` is the
        exact coordinate, so the cell is the box's lower-left corner plus one where
        the fraction is at least a half. A point whose box leaves the window lies in
        its outermost cells or off it; those cells are unknown (`_rim_unknown`) in
        every field `from_grid` builds away from the grid's edge, else the cell is
        found as `known_at` does. Same floats as `at` and `known_at` apart.

        Args:
            known: False skips the second answer (None).
            near_cm: when given, the second answer is whether the cell is known or the
                point lies within ``near_cm`` of an obstacle (what a scan's likelihood
                judges), and the cells are looked up only when some point is farther.
        """
        shape = np.shape(x)
        ox, oy = self.origin_cm
        res = self.resolution_cm
        gx = (np.asarray(x, dtype=float).reshape(-1) - ox) / res - 0.5
        gy = (np.asarray(y, dtype=float).reshape(-1) - oy) / res - 0.5
        cx, cy = np.floor(gx), np.floor(gy)
        fx, fy = gx - cx, gy - cy
        c0, r0 = cx.astype(np.int64), cy.astype(np.int64)
        ny, nx = self.distance_cm.shape
        # a negative index reads as a huge unsigned one: one comparison per axis
        inside = (c0.view(np.uint64) < nx - 1) & (r0.view(np.uint64) < ny - 1)
        flat = r0 * nx
        flat += c0
        flat *= inside  # off the window: any cell (the value read is replaced by the cap)
        d00, d01, d10, d11 = self._corners.take(flat, axis=1)
        ax, ay = 1 - fx, 1 - fy
        v = ax * ay * d00 + fx * ay * d01 + ax * fy * d10 + fx * fy * d11
        dist = np.where(inside, v, self.max_dist_cm).reshape(shape)
        if not known:
            return dist, None
        near = None
        if near_cm is not None:
            near = dist <= near_cm
            if near.all():
                return dist, near
        if self._rim_unknown:
            flat += fx >= 0.5
            flat += (fy >= 0.5) * nx
            cell_known = self._known_flat.take(flat)
            cell_known &= inside
            cell_known = cell_known.reshape(shape)
        else:
            cell_known = self.known_at(x, y)
        if near is not None:
            cell_known |= near
        return dist, cell_known

    def occupied_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether the cell holding each point (x, y) [cm] is occupied (False off the grid)."""
        flat, inside = self._cell(x, y)
        return inside & (self.distance_cm.reshape(-1)[flat] == 0.0)

    def cell_farther_than(self, x: np.ndarray, y: np.ndarray, radius_cm: float
                          ) -> np.ndarray:
        """Whether the cell holding each point (x, y) [cm] lies on the window with its
        centre farther than ``radius_cm`` from every occupied cell's centre (False off
        the window, and where the cap is not beyond ``radius_cm``)."""
        flat, inside = self._cell(x, y)
        return inside & (self.distance_cm.reshape(-1)[flat] > radius_cm)

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


def _known_window(grid: GridMap, max_dist_cm: float,
                  known: tuple[int, int, int, int] | None
                  ) -> tuple[np.ndarray, tuple[float, float]]:
    """The part of ``grid`` the field needs, and that part's lower-left corner [cm];
    ``known`` is the grid's box of known cells (`GridMap.known_bounds`; None: none).

    Every occupied cell is known, so beyond the known cells' bounding box widened by
    the cap (and two cells, for the bilinear read) every cell is unknown and reads the
    cap: the same answers as the whole grid's field, which a mapper's grid (mostly
    unknown while it maps) would make costly to build every few batches.
    """
    if known is None:
        return grid.cells, grid.origin_cm
    row0, row1, col0, col1 = known
    res = grid.resolution_cm
    k = int(math.ceil(max_dist_cm / res)) + 2
    r0, r1 = max(0, row0 - k), row1 + k
    c0, c1 = max(0, col0 - k), col1 + k
    return grid.cells[r0:r1, c0:c1], (grid.origin_cm[0] + c0 * res, grid.origin_cm[1] + r0 * res)

