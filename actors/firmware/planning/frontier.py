"""Frontier-based exploration: where the known-free space meets the unknown.

Algorithm
    1. Frontier cells: free cells with at least one 4-neighbour unknown
       (cells outside the grid do not count as unknown).
    2. Clusters: 8-connected components of frontier cells (`scipy.ndimage.label`);
       each has a size [cells] and a centroid [cm].
    3. Reachability: a layered BFS (`actors.firmware.planning.grid_search.bfs_steps`) over
       the cells where the rover's centre may be (occupied cells inflated by
       its radius plus a margin, unknown blocked) gives the step distance from
       the rover. A frontier cell is approachable from any reachable cell
       within ``approach_cm`` of it (the LIDAR sees the unknown from there;
       frontier cells by walls are often inside the inflation themselves).
       A cluster's distance is that of its nearest approachable cell, and its
       target is the reachable cell nearest (Euclidean) to that frontier cell.
    4. Each cluster also says how much unknown lies round it (``unknown_share``:
       the share of unknown cells in a square of half-side ``explore_radius_cm``
       around the centroid). Where to go is chosen by viewpoint
       (`planning.viewpoint`: what a pose would see), not by the cluster.

    Work is done on the known part of the map only (cropped with a margin),
    so the cost follows the explored area, not the grid's fixed extent.

Reference
    Yamauchi, "A Frontier-Based Approach for Autonomous Exploration",
    IEEE CIRA 1997.

Frame and units
    Positions [cm] in the rover frame; sizes [cells] and [cm] as named;
    grids as in `actors.firmware.mapping.occupancy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware import ndimage
from actors.firmware.arrays import pad_border
from actors.firmware.planning.grid_search import bfs_steps
from actors.firmware.planning.planner import snap_to_passable, traversable
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

__all__ = [
    "Frontier",
    "frontier_mask",
    "label_clusters",
    "find_frontiers",
    "steps_from",
]


@dataclass(frozen=True, slots=True, eq=False)
class Frontier:
    """One frontier cluster."""

    size: int
    """Frontier cells in the cluster [cells]."""
    centroid_cm: tuple[float, float]
    """Mean of the cells' centres (x, y) [cm]; it need not lie on the frontier."""
    cells_cm: np.ndarray
    """Centres (x, y) of the cluster's cells, float (size, 2) [cm], read-only."""
    distance_cm: float
    """Path distance from the rover to the nearest approach point [cm]
    (8-connected steps times the resolution); ``inf`` when unreachable."""
    target_cm: tuple[float, float] | None
    """A reachable point from which the cluster is seen, to plan to; None when unreachable."""
    unknown_share: float
    """Share of unknown cells around the centroid, 0..1 (high: little explored)."""
    resolution_cm: float
    """Cell side of the map the cluster was found in [cm]."""
    open_share: float = 1.0
    """Share of the cluster's cells with no occupied cell within ``open_cm`` (find_frontiers),
    0..1: low for the ragged edge along a wall or a pocket behind furniture, high for the
    edge of what an obstacle hid in open space."""

    @property
    def reachable(self) -> bool:
        """Whether the rover can reach an approach point."""
        return self.target_cm is not None

    @property
    def size_cm(self) -> float:
        """Frontier length, approximately [cm]."""
        return self.size * self.resolution_cm


def frontier_mask(cells: np.ndarray) -> np.ndarray:
    """Free cells with a 4-neighbour unknown: bool, the shape of ``cells``."""
    unknown = pad_border(cells == UNKNOWN, 1, False)
    near = unknown[:-2, 1:-1] | unknown[2:, 1:-1] | unknown[1:-1, :-2] | unknown[1:-1, 2:]
    return (cells == FREE) & near


_EIGHT = np.ones((3, 3), dtype=bool)
"""The 8-neighbourhood as a `scipy.ndimage` structuring element."""


def label_clusters(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """8-connected components of ``mask`` (`scipy.ndimage.label` with a 3 x 3 structure).

    Returns:
        (labels, count): int32 labels, 0 outside ``mask`` and 1..count inside,
        numbered in row-major order of each component's first cell.
    """
    labels, count = ndimage.label(np.asarray(mask, dtype=bool), structure=_EIGHT)
    return labels.astype(np.int32, copy=False), int(count)


def _min_filter(values: np.ndarray, k: int) -> np.ndarray:
    """Minimum over a (2k+1) square window (separable; edges use the part inside)."""
    out = values.copy()
    for axis in (0, 1):
        src = out.copy()
        n = src.shape[axis]
        for d in range(1, min(k, n - 1) + 1):
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(0, n - d), slice(d, n)
            np.minimum(out[tuple(lo)], src[tuple(hi)], out=out[tuple(lo)])
            np.minimum(out[tuple(hi)], src[tuple(lo)], out=out[tuple(hi)])
    return out


def _split_clusters(labels: np.ndarray, side: int) -> tuple[np.ndarray, int]:
    """Relabel so each (cluster, ``side`` x ``side`` block) pair is its own cluster,
    numbered in row-major order of each piece's first cell."""
    rows, cols = np.nonzero(labels)
    if rows.size == 0:
        return labels, 0
    nbx = labels.shape[1] // side + 1
    key = labels[rows, cols].astype(np.int64) * (nbx * (labels.shape[0] // side + 1)) \
        + (rows // side) * nbx + cols // side
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first, kind="stable"), kind="stable")  # by first cell
    out = np.zeros_like(labels)
    out[rows, cols] = order[inverse] + 1
    return out, int(first.size)


def find_frontiers(
    grid: GridMap,
    rover_cm: tuple[float, float],
    *,
    robot_radius_cm: float,
    margin_cm: float = 3.0,
    approach_cm: float = 30.0,
    explore_radius_cm: float = 100.0,
    snap_radius_cm: float = 30.0,
    split_cm: float | None = 100.0,
    open_cm: float = 30.0,
) -> list[Frontier]:
    """Every frontier cluster of ``grid``, with its distance from the rover.

    Args:
        grid: the map snapshot.
        rover_cm: rover position (x, y) [cm].
        robot_radius_cm: the rover's turning radius [cm] (obstacle inflation).
        margin_cm: extra clearance from obstacles [cm].
        approach_cm: how close to a frontier cell the rover must get [cm].
        explore_radius_cm: half-side of the window for ``unknown_share`` [cm].
        snap_radius_cm: how far the rover's cell may move to a passable one [cm]
            (after mapping near a wall the rover may stand inside the inflation).
        split_cm: clusters are cut into pieces by a square grid of this side [cm]
            (None: whole clusters). A long frontier (a wall's ragged edge running
            from the rover into the next room) would otherwise have one target, the
            approach point nearest the rover, and be given up as a whole once that
            point was reached without seeing anything new.
        open_cm: a frontier cell with no occupied cell this near is in the open
            (`Frontier.open_share`) [cm].

    Returns:
        Clusters in label order (see `label_clusters`); empty when there is no
        frontier. Unreachable clusters are included, with ``target_cm`` None.
    """
    res = grid.resolution_cm
    k_app = max(1, math.ceil(approach_cm / res))
    sub = grid.crop_known(margin_cells=k_app + 1)
    cells = sub.cells
    mask = frontier_mask(cells)
    labels, count = label_clusters(mask)
    if count == 0:
        return []
    if split_cm is not None and split_cm > 0:
        labels, count = _split_clusters(labels, max(1, round(split_cm / res)))

    steps = steps_from(sub, rover_cm, robot_radius_cm, margin_cm, snap_radius_cm)
    big = np.iinfo(np.int32).max
    reach_steps = np.where(steps >= 0, steps, big)
    near_steps = _min_filter(reach_steps, k_app)
    share_of = _UnknownShare(cells, max(1, math.ceil(explore_radius_cm / res)))

    k_open = max(1, math.ceil(open_cm / res))
    near_occ = _min_filter(-(cells == OCCUPIED).astype(np.int32), k_open) < 0

    rows_all, cols_all = np.nonzero(labels)
    lab = labels[rows_all, cols_all]
    order = np.argsort(lab, kind="stable")
    rows_all, cols_all, lab = rows_all[order], cols_all[order], lab[order]
    bounds = np.searchsorted(lab, np.arange(1, count + 2))
    ox, oy = sub.origin_cm
    ny, nx = cells.shape
    out: list[Frontier] = []
    for i in range(count):
        rows = rows_all[bounds[i]:bounds[i + 1]]
        cols = cols_all[bounds[i]:bounds[i + 1]]
        pts = np.column_stack([ox + (cols + 0.5) * res, oy + (rows + 0.5) * res])
        pts.flags.writeable = False
        cx, cy = (float(v) for v in pts.mean(axis=0))
        cr, cc = min(max(int((cy - oy) // res), 0), ny - 1), min(max(int((cx - ox) // res), 0),
                                                                 nx - 1)
        share = share_of(cr, cc)
        target, distance = _approach(sub, steps, near_steps[rows, cols], rows, cols, k_app, big)
        open_share = 1.0 - float(np.count_nonzero(near_occ[rows, cols])) / rows.size
        out.append(Frontier(int(rows.size), (cx, cy), pts, distance, target, share, res,
                            open_share))
    return out


def steps_from(sub: GridMap, rover_cm: tuple[float, float], robot_radius_cm: float,
                margin_cm: float, snap_radius_cm: float) -> np.ndarray:
    """BFS steps from the rover's cell (snapped to a passable one) to every cell the
    inflated map lets it reach; -1 elsewhere, and everywhere when no cell is near."""
    passable = traversable(sub, robot_radius_cm, margin_cm, "blocked")
    start = snap_to_passable(passable, sub.world_to_cell(*rover_cm),
                             snap_radius_cm / sub.resolution_cm)
    if start is None:
        return np.full(sub.cells.shape, -1, dtype=np.int32)
    return bfs_steps(passable, start)


class _UnknownShare:
    """Share of unknown cells in the window of half-side ``k`` cells around a cell, from
    an integral image over the cells padded with unknown."""

    def __init__(self, cells: np.ndarray, k: int) -> None:
        unknown = pad_border(cells == UNKNOWN, k, True).astype(np.int32)
        self._integral = np.pad(unknown.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
        self._area = (2 * k + 1) ** 2
        self._k = k

    def __call__(self, cr: int, cc: int) -> float:
        integral, k_exp = self._integral, self._k
        r0, c0 = cr, cc  # window [cr - k, cr + k] in the padded integral image
        total = (integral[r0 + 2 * k_exp + 1, c0 + 2 * k_exp + 1] - integral[r0, c0 + 2 * k_exp + 1]
                 - integral[r0 + 2 * k_exp + 1, c0] + integral[r0, c0])
        return float(total) / self._area


def _approach(sub: GridMap, steps: np.ndarray, near: np.ndarray, rows: np.ndarray,
              cols: np.ndarray, k_app: int, big: int
              ) -> tuple[tuple[float, float] | None, float]:
    """The reachable cell within ``k_app`` of the cluster's nearest-reached cell, and its
    path length [cm]; (None, inf) when no cell of the cluster can be approached.

    Args:
        sub: the map crop the search ran on.
        steps: BFS steps from the rover per cell, -1 unreachable.
        near: per cluster cell, the fewest steps to a cell within ``k_app`` (``big``: none).
        rows, cols: the cluster's cells.
        k_app: approach distance [cells].
        big: the "none" value of ``near``.
    """
    j = int(np.argmin(near))
    if not near[j] < big:
        return None, math.inf
    ny, nx = steps.shape
    fr, fc = int(rows[j]), int(cols[j])
    wr0, wr1 = max(0, fr - k_app), min(ny, fr + k_app + 1)
    wc0, wc1 = max(0, fc - k_app), min(nx, fc + k_app + 1)
    rr, cc_ = np.nonzero(steps[wr0:wr1, wc0:wc1] >= 0)
    d2 = (rr + wr0 - fr) ** 2 + (cc_ + wc0 - fc) ** 2
    b = int(np.argmin(d2))
    tr, tc = int(rr[b] + wr0), int(cc_[b] + wc0)
    return sub.cell_to_world(tr, tc), float(steps[tr, tc]) * sub.resolution_cm
