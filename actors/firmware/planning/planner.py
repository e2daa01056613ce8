"""A* path planning on an occupancy grid inflated by the rover's radius.

Algorithm
    1. Traversability: occupied cells are inflated by the rover's turning
       radius plus a margin (a cell is blocked when the nearest point of an
       occupied cell's square lies closer to its centre than that radius);
       unknown cells are either blocked or passable at an extra cost.
    2. Start and goal snap to the nearest passable cell within a radius.
    3. A* over the 8-connected grid (`grid_search.astar`: octile step costs,
       no corner cutting, a tie-breaking heuristic).
    4. Line-of-sight pruning: from each waypoint, jump to the farthest later
       turning point the rover can reach in a straight line over passable cells
       (conservative test: samples every 0.1 cell and every cell touched at a
       corner counts).

    The searches themselves, A* and the breadth-first step counts used for
    frontier selection (`bfs_steps`), work on cells only and live in
    `grid_search`; this module turns a map in [cm] into a mask and a path back
    into waypoints [cm].

Reference
    Hart, Nilsson, Raphael, "A Formal Basis for the Heuristic Determination of
    Minimum Cost Paths", IEEE Trans. SSC 4(2), 1968; PythonRobotics
    ``PathPlanning/AStar/a_star.py``.

Frame and units
    Grids are (row, col) = (y, x) arrays as in `actors.firmware.mapping.occupancy`;
    positions and radii are [cm] in the rover frame, path costs [cm].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from actors.firmware.planning.grid_search import astar
from server.protocol.grid_map import OCCUPIED, UNKNOWN, GridMap

__all__ = [
    "Plan",
    "inflate",
    "traversable",
    "snap_to_passable",
    "line_of_sight",
    "simplify",
    "plan_path",
]


@dataclass(frozen=True, slots=True)
class Plan:
    """A planned path."""

    waypoints_cm: tuple[tuple[float, float], ...]
    """Straight-line legs' end points [cm], from the start to the goal inclusive."""
    cells: tuple[tuple[int, int], ...]
    """The A* path, (row, col) from the start cell to the goal cell."""
    cost_cm: float
    """A* path cost [cm] (length plus any unknown-cell penalty)."""
    length_cm: float
    """Length of the waypoint polyline [cm]."""
    expanded: int
    """Nodes A* expanded (a measure of search effort)."""
    goal_snapped: bool
    """True when the goal cell was not passable and a nearby cell was used."""


# -- traversability -----------------------------------------------------------


def inflate(blocked: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells whose centre lies within ``radius_cells`` of a blocked cell's square.

    Args:
        blocked: bool (ny, nx).
        radius_cells: inflation radius [cells]; 0 returns a copy.

    Returns:
        bool (ny, nx), a superset of ``blocked``.
    """
    blocked = np.asarray(blocked, dtype=bool)
    out = blocked.copy()
    if radius_cells <= 0:
        return out
    k = math.ceil(radius_cells + 0.5)
    ny, nx = blocked.shape
    # The offsets (dr, dc) within reach: distance from a cell centre to the nearest point
    # of the square offset by them. For each dr the dc within reach are one interval
    # [-m, m] (the distance grows with |dc|), so the dilation is a dilation along the
    # rows by m, shifted by dr: about 2 k + 2 m_max array ORs instead of one per offset
    # (the same cells: OR is exact).
    reach: dict[int, int] = {}
    for dr in range(-k, k + 1):
        for dc in range(k, -1, -1):
            if math.hypot(max(abs(dr) - 0.5, 0.0), max(dc - 0.5, 0.0)) < radius_cells:
                reach[dr] = dc
                break
    along = [blocked]  # along[m]: blocked dilated by up to m columns each way
    for m in range(1, min(max(reach.values(), default=0), nx - 1) + 1):
        h = along[-1].copy()
        h[:, m:] |= blocked[:, :nx - m]
        h[:, :nx - m] |= blocked[:, m:]
        along.append(h)
    for dr, m in reach.items():
        if abs(dr) >= ny:
            continue  # shifted off the grid
        src = along[min(m, len(along) - 1)][max(0, dr):ny + min(0, dr)]
        out[max(0, -dr):ny + min(0, -dr)] |= src
    return out


def traversable(
    grid: GridMap,
    robot_radius_cm: float,
    margin_cm: float = 3.0,
    unknown: Literal["blocked", "costly"] = "blocked",
) -> np.ndarray:
    """Cells where the rover's centre may be: bool (ny, nx).

    Occupied cells are inflated by ``robot_radius_cm + margin_cm``; unknown cells
    are not inflated, and are blocked only when ``unknown == "blocked"``.

    Raises:
        ValueError: for a negative radius or margin, or an unknown ``unknown``.
    """
    if robot_radius_cm < 0 or margin_cm < 0:
        raise ValueError(f"robot_radius_cm and margin_cm must be >= 0, got "
                         f"{robot_radius_cm}, {margin_cm}")
    if unknown not in ("blocked", "costly"):
        raise ValueError(f"unknown must be 'blocked' or 'costly', got {unknown!r}")
    cells = grid.cells
    blocked = inflate(cells == OCCUPIED, (robot_radius_cm + margin_cm) / grid.resolution_cm)
    if unknown == "blocked":
        blocked |= cells == UNKNOWN
    return ~blocked


def snap_to_passable(
    passable: np.ndarray, cell: tuple[int, int], max_radius_cells: float
) -> tuple[int, int] | None:
    """The passable cell nearest ``cell`` (Euclidean) within a radius, or None.

    ``cell`` itself wins when passable; it may lie outside the grid.
    """
    ny, nx = passable.shape
    r, c = cell
    if 0 <= r < ny and 0 <= c < nx and passable[r, c]:
        return r, c
    k = math.ceil(max_radius_cells)
    r0, r1 = max(0, r - k), min(ny, r + k + 1)
    c0, c1 = max(0, c - k), min(nx, c + k + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    rows, cols = np.nonzero(passable[r0:r1, c0:c1])
    if rows.size == 0:
        return None
    d2 = (rows + r0 - r) ** 2 + (cols + c0 - c) ** 2
    best = int(np.argmin(d2))
    if d2[best] > max_radius_cells**2:
        return None
    return int(rows[best] + r0), int(cols[best] + c0)


# -- pruning ------------------------------------------------------------------


def line_of_sight(passable: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether the segment between cell centres ``a`` and ``b`` crosses only passable cells.

    Conservative: the segment is sampled at most every 0.1 cell along each axis
    and, at each sample, every cell within 0.051 cell of it (per axis) counts, so
    a segment through or near a cell corner needs all cells at that corner
    passable (the segment is treated as about 0.1 cell wide).
    """
    ny, nx = passable.shape
    (r0, c0), (r1, c1) = a, b
    n = max(2, math.ceil(10 * math.hypot(r1 - r0, c1 - c0)) + 1)
    t = np.linspace(0.0, 1.0, n)
    rr = r0 + 0.5 + (r1 - r0) * t
    cc = c0 + 0.5 + (c1 - c0) * t
    eps = 0.051  # > half the sample spacing per axis: no corner slips between samples
    rl, rh = np.floor(rr - eps).astype(np.int64), np.floor(rr + eps).astype(np.int64)
    cl, ch = np.floor(cc - eps).astype(np.int64), np.floor(cc + eps).astype(np.int64)
    rows = np.concatenate([rl, rl, rh, rh])
    cols = np.concatenate([cl, ch, cl, ch])
    if rows.min() < 0 or cols.min() < 0 or rows.max() >= ny or cols.max() >= nx:
        return False
    return bool(passable[rows, cols].all())


def simplify(passable: np.ndarray, path: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Line-of-sight pruning of an A* path to its necessary turning points.

    The result starts and ends with the path's ends, and every leg between
    consecutive points has line of sight on ``passable``.
    """
    if len(path) <= 2:
        return list(path)
    # candidates: the ends and every cell where the step direction changes
    turns = [0]
    for i in range(1, len(path) - 1):
        d_in = (path[i][0] - path[i - 1][0], path[i][1] - path[i - 1][1])
        d_out = (path[i + 1][0] - path[i][0], path[i + 1][1] - path[i][1])
        if d_in != d_out:
            turns.append(i)
    turns.append(len(path) - 1)
    out = [path[0]]
    i = 0  # index into turns of the current anchor
    while i < len(turns) - 1:
        j = i + 1
        # farthest candidate still in sight; consecutive turning points always are
        while j + 1 < len(turns) and line_of_sight(passable, path[turns[i]], path[turns[j + 1]]):
            j += 1
        out.append(path[turns[j]])
        i = j
    return out


# -- planning -------------------------------------------------------------------


def plan_path(
    grid: GridMap,
    start_cm: tuple[float, float],
    goal_cm: tuple[float, float],
    *,
    robot_radius_cm: float,
    margin_cm: float = 3.0,
    unknown: Literal["blocked", "costly"] = "blocked",
    unknown_cost: float = 4.0,
    snap_radius_cm: float = 30.0,
    passable: np.ndarray | None = None,
) -> Plan | None:
    """Plan from ``start_cm`` to ``goal_cm`` [cm] on ``grid``.

    Args:
        grid: the map snapshot.
        start_cm: rover position (x, y) [cm].
        goal_cm: destination (x, y) [cm].
        robot_radius_cm: the rover's turning radius (half-diagonal) [cm].
        margin_cm: extra clearance kept from obstacles [cm].
        unknown: unknown cells ``"blocked"`` or ``"costly"``.
        unknown_cost: extra cost of entering an unknown cell [cells] when costly.
        snap_radius_cm: how far start and goal may move to a passable cell [cm].
        passable: a precomputed `traversable` mask for ``grid`` (saves the
            inflation when planning repeatedly on one snapshot).

    Returns:
        The plan; its first and last waypoints are ``start_cm`` and ``goal_cm``
        exactly when their cells were passable, else the snapped cells' centres.
        None when no path exists or start or goal cannot be snapped.
    """
    if passable is None:
        passable = traversable(grid, robot_radius_cm, margin_cm, unknown)
    elif passable.shape != grid.shape:
        raise ValueError(f"passable must have the grid's shape {grid.shape}, got "
                         f"{passable.shape}")
    extra = None
    if unknown == "costly" and unknown_cost > 0:
        extra = np.where(grid.cells == UNKNOWN, float(unknown_cost), 0.0)
    snap = snap_radius_cm / grid.resolution_cm
    s_cell = grid.world_to_cell(*start_cm)
    g_cell = grid.world_to_cell(*goal_cm)
    s = snap_to_passable(passable, s_cell, snap)
    g = snap_to_passable(passable, g_cell, snap)
    if s is None or g is None:
        return None
    found = astar(passable, s, g, extra_cost=extra)
    if found is None:
        return None
    path, cost, expanded = found
    corners = simplify(passable, path)
    pts = [grid.cell_to_world(r, c) for r, c in corners]
    if s == s_cell:
        pts[0] = (float(start_cm[0]), float(start_cm[1]))
    if g == g_cell:
        if len(pts) == 1:
            pts.append((float(goal_cm[0]), float(goal_cm[1])))
        else:
            pts[-1] = (float(goal_cm[0]), float(goal_cm[1]))
    length = sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))
    return Plan(tuple(pts), tuple(path), cost * grid.resolution_cm, length, expanded,
                goal_snapped=g != g_cell)
