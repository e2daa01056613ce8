"""A* planning, inflation, line of sight and BFS distances (actors.firmware.planning.planner
and its searches, actors.firmware.planning.grid_search)."""

from __future__ import annotations

import collections
import math
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from actors.firmware.hardware import HardwareSpec
from actors.firmware.planning.clearance import turning_radius_cm
from actors.firmware.planning.grid_search import MOVES, _astar_padded, astar, bfs_steps
from actors.firmware.planning.planner import (
    inflate,
    line_of_sight,
    plan_path,
    simplify,
    snap_to_passable,
    traversable,
)
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap

BENCH = HardwareSpec.bench("mapper")
RADIUS_CM = turning_radius_cm(BENCH.length_cm, BENCH.width_cm)
"""The bench rover's turning radius (half its 20 x 15 cm body's diagonal: 12.5 cm)."""


def room(ny: int = 40, nx: int = 60) -> np.ndarray:
    """A free room of 5 cm cells with a one-cell wall all round."""
    cells = np.zeros((ny, nx), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    return cells


def test_inflate_uses_distance_to_the_square_not_its_centre():
    """Radius 1 cell reaches the 4 neighbours only; radius 1.5 adds the diagonals."""
    blocked = np.zeros((5, 5), dtype=bool)
    blocked[2, 2] = True
    assert inflate(blocked, 0.6).sum() == 1 + 4  # orthogonal gap 0.5 < 0.6 <= diagonal 0.707
    assert inflate(blocked, 1.0).sum() == 1 + 4 + 4
    assert inflate(blocked, 0).sum() == 1


def test_inflate_matches_the_definition_on_random_grids():
    """Every cell whose centre lies within the radius of a blocked cell's square, and
    no other (brute force over all pairs), also on grids smaller than the reach."""
    rng = np.random.default_rng(11)
    for _ in range(60):
        ny, nx = (int(v) for v in rng.integers(1, 14, 2))
        blocked = rng.random((ny, nx)) < rng.uniform(0.0, 0.3)
        radius = float(rng.uniform(0.0, 5.0))
        want = blocked.copy()
        for r, c in np.argwhere(blocked):
            for rr in range(ny):
                for cc in range(nx):
                    gap = math.hypot(max(abs(rr - r) - 0.5, 0.0), max(abs(cc - c) - 0.5, 0.0))
                    if gap < radius:
                        want[rr, cc] = True
        assert np.array_equal(inflate(blocked, radius), want)


def test_inflate_radius_blocks_cells_within_reach():
    """Every cell whose centre is within r of the blocked square is blocked, others not."""
    blocked = np.zeros((21, 21), dtype=bool)
    blocked[10, 10] = True
    r = 3.2
    out = inflate(blocked, r)
    for row in range(21):
        for col in range(21):
            gap = math.hypot(max(abs(row - 10) - 0.5, 0), max(abs(col - 10) - 0.5, 0))
            assert out[row, col] == (gap < r), (row, col)


def test_traversable_keeps_the_rover_radius_off_walls():
    """With 12.5 + 3 cm at 5 cm cells, the 3 cells next to a wall are blocked, the 4th free."""
    m = GridMap(room(), 5.0, (0, 0))
    p = traversable(m, RADIUS_CM, 3.0)
    assert not p[20, 1:4].any()  # gaps 0.5..2.5 cells = 2.5..12.5 cm < 15.5 cm
    assert p[20, 4]  # gap 3.5 cells = 17.5 cm
    assert not traversable(m, RADIUS_CM, 5.1)[20, 4]


def test_unknown_is_blocked_or_costly_as_asked():
    """Unknown cells block by default and are passable when 'costly'."""
    cells = room()
    cells[:, 30] = UNKNOWN
    cells[0, 30] = cells[-1, 30] = OCCUPIED
    m = GridMap(cells, 5.0, (0, 0))
    assert plan_path(m, (50, 100), (250, 100), robot_radius_cm=RADIUS_CM) is None
    plan = plan_path(m, (50, 100), (250, 100), robot_radius_cm=RADIUS_CM,
                     unknown="costly")
    assert plan is not None
    assert plan.cost_cm > 200  # the unknown crossing costs extra


def test_open_room_path_is_one_straight_leg_to_the_exact_goal():
    """In an empty room the plan is start -> goal, exactly, with the straight length."""
    m = GridMap(room(), 5.0, (0, 0))
    plan = plan_path(m, (52.0, 51.0), (247.0, 149.0), robot_radius_cm=RADIUS_CM)
    assert plan.waypoints_cm == ((52.0, 51.0), (247.0, 149.0))
    assert plan.length_cm == pytest.approx(math.dist((52, 51), (247, 149)))
    assert not plan.goal_snapped


def test_path_goes_around_a_wall_through_the_gap():
    """A wall with a gap at the top forces the path through the gap."""
    cells = room()
    cells[1:30, 30] = OCCUPIED  # gap rows 30..38 (45 cm) at the top
    m = GridMap(cells, 5.0, (0, 0))
    plan = plan_path(m, (50, 50), (250, 50), robot_radius_cm=RADIUS_CM)
    assert plan is not None
    assert max(y for _, y in plan.waypoints_cm) > 150  # went up to the gap
    assert len(plan.waypoints_cm) >= 3
    passable = traversable(m, RADIUS_CM)
    assert all(passable[r, c] for r, c in plan.cells)


def test_unreachable_goal_returns_none():
    """A goal behind a full wall has no plan."""
    cells = room()
    cells[:, 30] = OCCUPIED
    assert plan_path(GridMap(cells, 5.0, (0, 0)), (50, 50), (250, 50),
                     robot_radius_cm=RADIUS_CM) is None


def _four_connected(p: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Reference: plain breadth-first search over 4-neighbours."""
    seen, todo = {a}, [a]
    while todo:
        r, c = todo.pop()
        for v in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if v not in seen and 0 <= v[0] < p.shape[0] and 0 <= v[1] < p.shape[1] and p[v]:
                seen.add(v)
                todo.append(v)
    return b in seen


def test_astar_finds_a_path_exactly_between_4_connected_cells():
    """The up-front reachability check agrees with the search it short-cuts.

    A diagonal step needs both orthogonal neighbours, so A* reaches exactly the
    start's 4-connected component; `astar` answers None without searching
    otherwise, and must agree with the search itself (`_astar_padded`).
    """
    rng = np.random.default_rng(7)
    seen = {True: 0, False: 0}
    for _ in range(400):
        ny, nx = (int(v) for v in rng.integers(1, 16, 2))
        p = rng.random((ny, nx)) < rng.uniform(0.3, 0.9)
        cells = np.argwhere(p)
        if len(cells) == 0:
            continue
        a, b = (tuple(int(v) for v in cells[rng.integers(len(cells))]) for _ in range(2))
        want = _four_connected(p, a, b)
        seen[want] += 1
        assert (astar(p, a, b) is not None) == want
        assert (_astar_padded(p, a, b, None, 1.001, ny * nx) is not None) == want
    assert min(seen.values()) > 50  # both answers were tried


def test_goal_inside_inflation_snaps_to_nearest_passable_cell():
    """A goal 5 cm from a wall is moved to the nearest cell the rover can occupy."""
    m = GridMap(room(), 5.0, (0, 0))
    plan = plan_path(m, (100, 100), (100, 7.5), robot_radius_cm=RADIUS_CM)
    assert plan.goal_snapped
    assert plan.waypoints_cm[-1] == pytest.approx((102.5, 22.5), abs=5)
    assert plan_path(m, (100, 100), (100, 7.5), robot_radius_cm=RADIUS_CM,
                     snap_radius_cm=5) is None


def test_snap_to_passable_prefers_the_cell_itself():
    """A passable cell snaps to itself; an isolated blocked one to its nearest passable cell."""
    p = np.ones((5, 5), dtype=bool)
    p[2, 2] = False
    assert snap_to_passable(p, (1, 1), 2) == (1, 1)
    assert snap_to_passable(p, (2, 2), 2) in {(1, 2), (2, 1), (2, 3), (3, 2)}
    assert snap_to_passable(np.zeros((5, 5), dtype=bool), (2, 2), 10) is None


def test_astar_matches_dijkstra_cost_and_expands_fewer_nodes():
    """The tie-broken heuristic costs at most 0.1 % extra and saves expansions."""
    cells = room(80, 100)
    cells[10:70, 50] = OCCUPIED
    p = traversable(GridMap(cells, 5.0, (0, 0)), RADIUS_CM)
    a = astar(p, (40, 10), (40, 90))
    d = astar(p, (40, 10), (40, 90), heuristic_weight=0.0)
    assert a[1] <= d[1] * 1.001
    assert a[2] < d[2]


def test_astar_does_not_cut_corners():
    """A diagonal step between two blocked orthogonal cells is not taken."""
    p = np.ones((3, 3), dtype=bool)
    p[1, 0] = False
    path, cost, _ = astar(p, (1, 1), (0, 0))
    assert path == [(1, 1), (0, 1), (0, 0)]
    assert cost == pytest.approx(2.0)
    p[0, 1] = False
    assert astar(p, (1, 1), (0, 0)) is None  # (0, 0) would be reachable only diagonally


def test_line_of_sight_through_a_corner_is_blocked():
    """A segment passing exactly through a blocked cell's corner has no line of sight."""
    p = np.ones((3, 3), dtype=bool)
    p[1, 0] = False
    assert not line_of_sight(p, (0, 0), (2, 2))
    p2 = np.ones((2, 2), dtype=bool)
    p2[0, 1] = False
    assert not line_of_sight(p2, (0, 0), (1, 1))  # through the corner shared with (0, 1)
    assert line_of_sight(np.ones((2, 2), dtype=bool), (0, 0), (1, 1))


def test_bfs_steps_counts_chebyshev_steps_and_marks_unreachable():
    """Open cells get their 8-connected step count; walled-off cells get -1."""
    p = np.ones((5, 7), dtype=bool)
    p[:, 3] = False
    d = bfs_steps(p, (2, 0))
    assert d[0, 2] == 2 and d[4, 2] == 2 and d[2, 2] == 2
    assert (d[:, 4:] == -1).all()
    assert (d[:, 3] == -1).all()
    assert (bfs_steps(p, (2, 3)) == -1).all()


def test_bfs_steps_equals_a_cell_by_cell_breadth_first_search():
    """On random grids (blocked cells on the edges too) every cell's step count is a
    plain queue's, and -1 where the queue never comes."""
    rng = np.random.default_rng(4)
    for trial in range(30):
        ny, nx = int(rng.integers(1, 40)), int(rng.integers(1, 40))
        p = rng.random((ny, nx)) > rng.uniform(0.0, 0.6)
        start = (int(rng.integers(0, ny)), int(rng.integers(0, nx)))
        want = np.full((ny, nx), -1, dtype=np.int32)
        if p[start]:
            want[start] = 0
            queue = collections.deque([start])
            while queue:
                r, c = queue.popleft()
                for dr, dc, _ in MOVES:
                    v = (r + dr, c + dc)
                    if 0 <= v[0] < ny and 0 <= v[1] < nx and p[v] and want[v] < 0:
                        want[v] = want[r, c] + 1
                        queue.append(v)
        got = bfs_steps(p, start)
        assert got.dtype == np.int32 and np.array_equal(got, want), trial


@st.composite
def obstacle_maps(draw):
    cells = room(30, 40)
    for _ in range(draw(st.integers(0, 8))):
        r = draw(st.integers(1, 26))
        c = draw(st.integers(1, 36))
        cells[r:r + draw(st.integers(1, 6)), c:c + draw(st.integers(1, 6))] = OCCUPIED
    start = (draw(st.floats(10, 190)), draw(st.floats(10, 140)))
    goal = (draw(st.floats(10, 190)), draw(st.floats(10, 140)))
    return GridMap(cells, 5.0, (0, 0)), start, goal


@settings(max_examples=60, deadline=None)
@given(obstacle_maps())
def test_every_plan_stays_on_passable_ground(case):
    """Every A* cell and every straight leg of the waypoints is passable on the inflated grid."""
    m, start, goal = case
    p = traversable(m, RADIUS_CM)
    plan = plan_path(m, start, goal, robot_radius_cm=RADIUS_CM, passable=p)
    if plan is None:
        return
    assert all(p[r, c] for r, c in plan.cells)
    steps = [max(abs(a[0] - b[0]), abs(a[1] - b[1])) for a, b in pairwise(plan.cells)]
    assert all(s == 1 for s in steps)
    corners = simplify(p, list(plan.cells))
    for a, b in pairwise(corners):
        assert line_of_sight(p, a, b)
    assert plan.length_cm <= plan.cost_cm + 2 * m.resolution_cm * math.sqrt(2) + 1e-6


def test_plan_path_needs_a_matching_mask():
    """A precomputed mask of the wrong shape is refused."""
    m = GridMap(room(), 5.0, (0, 0))
    with pytest.raises(ValueError, match="passable must have the grid's shape"):
        plan_path(m, (50, 50), (60, 60), robot_radius_cm=RADIUS_CM,
                  passable=np.ones((3, 3), dtype=bool))


def test_traversable_rejects_bad_unknown_mode():
    """The unknown mode is checked."""
    with pytest.raises(ValueError, match="unknown must be 'blocked' or 'costly'"):
        traversable(GridMap(room(), 5.0, (0, 0)), RADIUS_CM, unknown="maybe")  # type: ignore[arg-type]


def test_free_constant_is_zero():
    """Cells read 0 for free (the planner relies on the snapshot convention)."""
    assert FREE == 0
