"""Map quality metrics of DESIGN.md section 8, scored against ground truth.

A firmware map is ``cells`` int8 (ny, nx): -1 unknown, 0 free, 100 occupied
(values 1..99 count as known: >= 50 occupied, else free), with ``resolution_cm``
and ``origin_cm``: the lower-left corner of cell [0, 0] in the MAPPER'S OWN
frame, whose origin is the mapper's start pose (heading 0 along +x). Metrics
take the mapper's start pose in the room to place the map on the truth raster.

* coverage: share of reachable free truth cells whose centre falls in a known
  map cell.
* accuracy: share of known map cells whose claim (free / occupied) matches the
  truth within one truth cell (a 3 x 3 neighbourhood; outside the room counts
  as occupied), so an edge drawn one cell off is not an error. Cells under a
  rover's body when the map was made (``bodies``) are left out: the rasterised
  truth holds the room, not the rovers standing in it, so a parked rover the
  LIDAR outlined (or the mapper's own body, marked where it parks) is neither
  right nor wrong there.
* T90 / T99: first time the coverage series reaches 90 % / 99 %.
* path length: sum of the distances between consecutive poses.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from world.geometry import Pose
from world.truth import TruthGrid


def _to_map_cells(xr: np.ndarray, yr: np.ndarray, start: Pose, resolution_cm: float,
                  origin_cm: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Room points -> (row, col) of the map (may be out of bounds)."""
    h = math.radians(start.heading_deg)
    c, s = math.cos(h), math.sin(h)
    dx, dy = xr - start.x, yr - start.y
    xm = c * dx + s * dy
    ym = -s * dx + c * dy
    col = np.floor((xm - origin_cm[0]) / resolution_cm).astype(np.int64)
    row = np.floor((ym - origin_cm[1]) / resolution_cm).astype(np.int64)
    return row, col


def _check_map(cells: np.ndarray, resolution_cm: float) -> np.ndarray:
    cells = np.asarray(cells)
    if cells.ndim != 2:
        raise ValueError(f"cells must be a 2-D array, got shape {cells.shape}")
    if resolution_cm <= 0:
        raise ValueError(f"resolution_cm must be > 0, got {resolution_cm!r}")
    return cells


def coverage(cells: np.ndarray, resolution_cm: float, origin_cm: tuple[float, float],
             start: Pose, truth: TruthGrid) -> float:
    """Share [0..1] of the reachable free truth cells that the map knows (one map: for a
    series of maps, `CoverageProbe` places the truth cells once)."""
    return CoverageProbe(start, truth)(cells, resolution_cm, origin_cm)


class CoverageProbe:
    """`coverage` of many maps of one extent, as a game's probe samples it every second.

    Why: where each reachable truth cell falls on the map depends only on the start
    pose and the map's resolution, origin and shape, which stay put for a whole game;
    placing them for every sample cost a few percent of a game's CPU. `coverage` of a
    single map is a probe used once.
    """

    def __init__(self, start: Pose, truth: TruthGrid) -> None:
        self.start = start
        self.truth = truth
        self._key: tuple | None = None
        self._flat = np.zeros(0, dtype=np.int64)  # map cells of the truth cells on the map
        self._n = 0  # reachable truth cells

    def __call__(self, cells: np.ndarray, resolution_cm: float,
                 origin_cm: tuple[float, float]) -> float:
        """Share [0..1] of the reachable free truth cells that the map knows."""
        cells = _check_map(cells, resolution_cm)
        key = (cells.shape, float(resolution_cm), tuple(origin_cm))
        if key != self._key:
            rows, cols = np.nonzero(self.truth.reachable)
            r = self.truth.resolution_cm
            mr, mc = _to_map_cells((cols + 0.5) * r, (rows + 0.5) * r, self.start,
                                   resolution_cm, origin_cm)
            inside = (mr >= 0) & (mr < cells.shape[0]) & (mc >= 0) & (mc < cells.shape[1])
            self._flat = mr[inside] * cells.shape[1] + mc[inside]
            self._n = len(rows)
            self._key = key
        if self._n == 0:
            return 0.0
        known = np.count_nonzero(cells.reshape(-1)[self._flat] >= 0)
        return float(known / self._n)


def accuracy(cells: np.ndarray, resolution_cm: float, origin_cm: tuple[float, float],
             start: Pose, truth: TruthGrid,
             bodies: Sequence[tuple[Pose, float, float]] = ()) -> float:
    """Share [0..1] of known map cells that agree with the truth (one cell of tolerance).

    Args:
        bodies: the rovers standing in the room when the map was made, each (room-frame
            pose, length, width [cm]); known cells whose centre lies within one truth
            cell of a body are not counted.

    Returns 1.0 for a map with no known cells (nothing claimed, nothing wrong).
    """
    cells = _check_map(cells, resolution_cm)
    mr, mc = np.nonzero(cells >= 0)
    # map cell centres in the mapper frame -> room frame
    xm = origin_cm[0] + (mc + 0.5) * resolution_cm
    ym = origin_cm[1] + (mr + 0.5) * resolution_cm
    h = math.radians(start.heading_deg)
    c, s = math.cos(h), math.sin(h)
    xr = start.x + c * xm - s * ym
    yr = start.y + s * xm + c * ym
    keep = ~_under_bodies(xr, yr, bodies, truth.resolution_cm)
    mr, mc, xr, yr = mr[keep], mc[keep], xr[keep], yr[keep]
    if len(mr) == 0:
        return 1.0
    occ = np.pad(truth.occupied, 2, constant_values=True)  # outside the room: walls
    near_occ = _dilate(occ)
    near_free = _dilate(~occ)
    r = truth.resolution_cm
    ti = np.clip(np.floor(xr / r).astype(np.int64) + 2, 0, occ.shape[1] - 1)
    tj = np.clip(np.floor(yr / r).astype(np.int64) + 2, 0, occ.shape[0] - 1)
    claims_occ = cells[mr, mc] >= 50
    ok = np.where(claims_occ, near_occ[tj, ti], near_free[tj, ti])
    return float(ok.mean())


def _under_bodies(x: np.ndarray, y: np.ndarray, bodies: Sequence[tuple[Pose, float, float]],
                  margin_cm: float) -> np.ndarray:
    """Whether each room-frame point lies within ``margin_cm`` of one of the ``bodies``'
    rectangles (pose, length along its heading, width [cm])."""
    under = np.zeros(x.shape, dtype=bool)
    for pose, length, width in bodies:
        h = math.radians(pose.heading_deg)
        dx, dy = x - pose.x, y - pose.y
        along = dx * math.cos(h) + dy * math.sin(h)
        across = -dx * math.sin(h) + dy * math.cos(h)
        under |= ((np.abs(along) <= 0.5 * length + margin_cm)
                  & (np.abs(across) <= 0.5 * width + margin_cm))
    return under


def _dilate(a: np.ndarray) -> np.ndarray:
    """3 x 3 dilation of a boolean raster."""
    out = a.copy()
    out[1:] |= a[:-1]
    out[:-1] |= a[1:]
    b = out.copy()
    out[:, 1:] |= b[:, :-1]
    out[:, :-1] |= b[:, 1:]
    return out


def time_to_coverage(series: Sequence[tuple[float, float]], level: float) -> float | None:
    """First time [s] at which coverage reaches ``level`` (e.g. 0.9 for T90), or None.

    Args:
        series: (time [s], coverage [0..1]) pairs in time order.
    """
    for t, cov in series:
        if cov >= level:
            return float(t)
    return None


def t90(series: Sequence[tuple[float, float]]) -> float | None:
    """Time to 90 % coverage [s] (None if never)."""
    return time_to_coverage(series, 0.9)


def t99(series: Sequence[tuple[float, float]]) -> float | None:
    """Time to 99 % coverage [s] (None if never)."""
    return time_to_coverage(series, 0.99)


def path_length(poses: Sequence[Pose | tuple[float, float]]) -> float:
    """Length of the polyline through the poses' (x, y) [cm]."""
    if len(poses) < 2:
        return 0.0
    xy = np.array([(p[0], p[1]) for p in poses], dtype=float)
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())
