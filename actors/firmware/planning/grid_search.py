"""Searches over a mask of passable cells: A* for a path, breadth-first for step counts.

Algorithm
    `astar`: A* over the 8-connected grid, octile step costs (1 or sqrt 2
    cells), no corner cutting (a diagonal step needs both orthogonal neighbours
    passable), octile-distance heuristic scaled by (1 + 1e-3) to break ties
    toward the goal (paths within 0.1 % of optimal, far fewer expansions in
    open rooms). A goal outside start's 4-connected component is refused before
    the search (a union-find over the rows' runs of passable cells).

    `bfs_steps`: a layered breadth-first search vectorised with numpy: the
    8-connected step distance from one cell to every passable cell, for
    frontier selection.

    Both work on cells only; what is passable, and the metric frame, are the
    planner's (`planner.traversable`, `planner.plan_path`).

Reference
    Hart, Nilsson, Raphael, "A Formal Basis for the Heuristic Determination of
    Minimum Cost Paths", IEEE Trans. SSC 4(2), 1968; PythonRobotics
    ``PathPlanning/AStar/a_star.py``.

Frame and units
    Masks are bool (row, col) = (y, x) arrays as in `actors.firmware.mapping.occupancy`;
    costs [cells].
"""

from __future__ import annotations

import bisect
import heapq
import math

import numpy as np

from actors.firmware.arrays import pad_border

__all__ = ["MOVES", "astar", "bfs_steps"]

SQRT2 = math.sqrt(2.0)

# 8-connected moves: (d_row, d_col, cost [cells]); orthogonal first
MOVES: tuple[tuple[int, int, float], ...] = (
    (0, 1, 1.0), (1, 0, 1.0), (0, -1, 1.0), (-1, 0, 1.0),
    (1, 1, SQRT2), (1, -1, SQRT2), (-1, 1, SQRT2), (-1, -1, SQRT2),
)


def astar(
    passable: np.ndarray,
    start: tuple[int, int],
    goal: tuple[int, int],
    *,
    extra_cost: np.ndarray | None = None,
    heuristic_weight: float = 1.0 + 1e-3,
    max_expansions: int | None = None,
) -> tuple[list[tuple[int, int]], float, int] | None:
    """A* over the 8-connected passable cells.

    Args:
        passable: bool (ny, nx).
        start: (row, col), must be passable.
        goal: (row, col), must be passable.
        extra_cost: optional float (ny, nx) added [cells] when entering a cell.
        heuristic_weight: multiplies the octile heuristic; 0 gives Dijkstra.
        max_expansions: give up (None) after this many expansions; default the
            number of cells (bounded work).

    Returns:
        (path cells from start to goal, cost [cells], expansions), or None when
        the goal cannot be reached (or a cell is not passable).
    """
    ny, nx = passable.shape
    for r, c in (start, goal):
        if not (0 <= r < ny and 0 <= c < nx) or not passable[r, c]:
            return None
    limit = max_expansions if max_expansions is not None else ny * nx
    # Only passable cells are ever visited: search the box around them (plus the
    # blocked border). Row-major indices keep their order in the box, so ties in the
    # heap break the same way and the path is the one the whole grid gives.
    passable = np.asarray(passable, dtype=bool)
    if not _connected(passable, start, goal):
        return None  # what the search gives after expanding start's whole component
    if extra_cost is None:
        rows = np.flatnonzero(passable.any(axis=1))
        cols = np.flatnonzero(passable.any(axis=0))
        r0, c0 = int(rows[0]), int(cols[0])
        box = passable[r0:int(rows[-1]) + 1, c0:int(cols[-1]) + 1]
        found = _astar_padded(box, (start[0] - r0, start[1] - c0),
                              (goal[0] - r0, goal[1] - c0), None, heuristic_weight, limit)
        if found is None:
            return None
        path, cost, expanded = found
        return [(r + r0, c + c0) for r, c in path], cost, expanded
    return _astar_padded(passable, start, goal,
                         np.asarray(extra_cost, dtype=np.float64), heuristic_weight, limit)


def _connected(passable: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Whether passable cells ``a`` and ``b`` are 4-connected on ``passable``.

    Why: that is exactly when `astar` (without an expansion limit) finds a path. Its
    diagonal step needs both orthogonal neighbours passable, so it can be replaced by
    two orthogonal steps and the search reaches the 4-connected component of start.
    An unreachable goal costs A* that whole component (milliseconds in Python: most
    of the planner's time in long mapping runs, whose frontier targets are often cut
    off by the inflation); this check costs one pass over the row runs.

    Algorithm: the horizontal runs of passable cells, joined (union-find) with the
    runs they overlap in the row above.
    """
    ny, nx = passable.shape
    w = nx + 1  # one blocked column ends every row's last run
    row = np.zeros((ny, w), dtype=np.int8)
    row[:, :nx] = passable
    d = np.diff(row.ravel(), prepend=np.int8(0))
    starts = np.flatnonzero(d == 1).tolist()
    ends = np.flatnonzero(d == -1).tolist()  # exclusive; same count as starts
    parent = list(range(len(starts)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    prev_lo = prev_hi = 0  # run indices of the previous row: [prev_lo, prev_hi)
    i = 0
    n = len(starts)
    while i < n:
        r = starts[i] // w
        base = r * w
        j = i
        while j < n and starts[j] < base + w:
            j += 1
        # runs [i, j) lie in row r; join those overlapping runs of row r - 1
        if prev_hi > prev_lo and starts[prev_lo] // w == r - 1:
            p, q = prev_lo, i
            while p < prev_hi and q < j:
                p0, p1 = starts[p] + w, ends[p] + w  # shifted into row r
                q0, q1 = starts[q], ends[q]
                if p0 < q1 and q0 < p1:
                    rp, rq = find(p), find(q)
                    if rp != rq:
                        parent[rq] = rp
                if p1 <= q1:
                    p += 1
                else:
                    q += 1
        prev_lo, prev_hi = i, j
        i = j
    ra = bisect.bisect_right(starts, a[0] * w + a[1]) - 1
    rb = bisect.bisect_right(starts, b[0] * w + b[1]) - 1
    return find(ra) == find(rb)


def _astar_padded(passable: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
                  extra_cost: np.ndarray | None, hw: float, limit: int,
                  ) -> tuple[list[tuple[int, int]], float, int] | None:
    """`astar` on ``passable`` padded with a blocked border (start and goal checked):
    no bounds checks in the loop."""
    ny, nx = passable.shape
    w = nx + 2
    pas = pad_border(passable).view(np.uint8).ravel().tobytes()
    extra = pad_border(extra_cost).ravel().tolist() if extra_cost is not None else None
    n = len(pas)
    s = (start[0] + 1) * w + start[1] + 1
    g = (goal[0] + 1) * w + goal[1] + 1
    gr, gc = divmod(g, w)
    k = SQRT2 - 2.0
    best = [math.inf] * n
    parent = [-1] * n
    avail = bytearray(pas)  # passable and not yet expanded
    best[s] = 0.0
    heap = [(0.0, 0.0, s)]
    push, pop = heapq.heappush, heapq.heappop
    moves = [(dr * w + dc, cost, dr * w, dc) for dr, dc, cost in MOVES]
    expanded = 0
    while heap:
        _, gu, u = pop(heap)
        if not avail[u]:
            continue  # expanded already (a stale heap entry)
        if u == g:
            path = []
            while u != -1:
                r, c = divmod(u, w)
                path.append((r - 1, c - 1))
                u = parent[u]
            path.reverse()
            return path, gu, expanded
        avail[u] = 0
        expanded += 1
        if expanded > limit:
            return None
        for off, cost, orow, ocol in moves:
            v = u + off
            if not avail[v]:
                continue
            if orow and ocol and not (pas[u + orow] and pas[u + ocol]):
                continue  # no corner cutting
            gv = gu + cost
            if extra is not None:
                gv += extra[v]
            if gv < best[v]:
                best[v] = gv
                parent[v] = u
                vr, vc = divmod(v, w)
                dr, dc = abs(vr - gr), abs(vc - gc)
                h = dr + dc + k * (dr if dr < dc else dc)
                push(heap, (gv + hw * h, gv, v))
    return None


def bfs_steps(passable: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """8-connected step count from ``start`` to every passable cell.

    A layered breadth-first search: each layer is expanded with numpy at once.
    A step counts 1 whether straight or diagonal, so this is the Chebyshev
    path length (it underestimates diagonal travel by up to 29 %): good for
    ranking goals by distance, not for exact path costs. No corner cutting is
    checked.

    Returns:
        int32 (ny, nx): steps, -1 for cells not reachable (or not passable).
        All -1 when ``start`` is outside the grid or not passable.
    """
    ny, nx = passable.shape
    w = nx + 2
    pas = pad_border(np.asarray(passable, dtype=bool))
    # one array for "passable and not reached yet" (-1) and the steps: the blocked cells
    # (the border too) hold a count no search reaches, and read -1 at the end
    blocked = np.iinfo(np.int32).max
    dist = np.where(pas, np.int32(-1), np.int32(blocked)).ravel()
    r, c = start
    if 0 <= r < ny and 0 <= c < nx and passable[r, c]:
        offsets = np.array([dr * w + dc for dr, dc, _ in MOVES], dtype=np.int64)
        front = np.array([(r + 1) * w + c + 1], dtype=np.int64)
        dist[front] = 0
        # the next layer's cells, once each, without sorting: each candidate writes its
        # position in `slot`, and the one whose position stays there is kept
        slot = np.zeros(dist.size, dtype=np.int64)
        step = 0
        while front.size:
            step += 1
            cand = (front[:, None] + offsets[None, :]).ravel()
            cand = cand[dist[cand] < 0]
            dist[cand] = step  # duplicates write the same value
            pos = np.arange(cand.size)
            slot[cand] = pos
            front = cand[slot[cand] == pos]
    out = dist.reshape(ny + 2, w)[1:-1, 1:-1].copy()
    out[out == blocked] = -1
    return out
