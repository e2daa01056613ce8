"""Routes: planning a route on a map and following it one Command A at a time.

`plan_route` plans with A* on the map (obstacles inflated by a radius plus a
margin), `route_points` and `shorten` turn the plan into waypoints, and
`PathFollower` is the ADP loop's decision: from the pose at rest to the next
`Motion` (a turn toward the next waypoint, else a straight move of at most
``step_cm``). `with_obstacle` and `passable_at` are the map edits and checks
the recovery behaviours use. Pure: no actor, no messages.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.nav.options import NavOptions
from actors.firmware.planning.planner import Plan, plan_path, traversable
from server.protocol.grid_map import OCCUPIED, GridMap
from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["plan_tiers", "MAX_CORRECTIONS", "Motion", "PathFollower", "plan_route",
           "route_points", "shorten",
           "with_obstacle", "passable_at"]

MAX_CORRECTIONS = 6
"""Extra ADP steps allowed beyond the plan's length before giving up on a route (a bound:
the route is replanned from where the rover is)."""


@dataclass(frozen=True, slots=True)
class Motion:
    """One Command A: ``kind`` is ``"turn"`` ([deg], CCW positive) or ``"move"`` ([cm])."""

    kind: str
    amount: float


class PathFollower:
    """The ADP loop's decision: from a pose to the next `Motion` along waypoints.

    Pure (no I/O, no clock): give it the pose after each motion.

    Args:
        waypoints: points to pass through (x, y) [cm], the last being the goal.
        heading_deg: heading to turn to at the goal, or None for any [deg].
        options: tolerances and step length.
    """

    def __init__(self, waypoints: list[tuple[float, float]] | tuple[tuple[float, float], ...],
                 heading_deg: float | None, options: NavOptions) -> None:
        if not waypoints:
            raise ValueError("waypoints must not be empty")
        self.waypoints = [(float(x), float(y)) for x, y in waypoints]
        self.heading_deg = heading_deg
        self.o = options
        self.index = 0
        """Index of the waypoint being driven to."""
        self.steps = 0
        """Motions handed out so far."""
        self._turned_from: float | None = None  # heading when the last motion, a turn, began

    @property
    def goal(self) -> tuple[float, float]:
        """The last waypoint [cm]."""
        return self.waypoints[-1]

    def remaining_cm(self, pose: Pose) -> float:
        """Distance along the remaining waypoints from ``pose`` [cm]."""
        pts = [(pose.x, pose.y), *self.waypoints[self.index:]]
        return sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))

    def budget(self, pose: Pose) -> int:
        """Most motions still reasonable: two per step of the remaining route, plus slack."""
        return 2 * math.ceil(self.remaining_cm(pose) / self.o.step_cm) + len(self.waypoints) \
            + MAX_CORRECTIONS

    def next_motion(self, pose: Pose) -> Motion | None:
        """The next motion from ``pose``, or None when at the goal (and heading).

        A turn that changed nothing (smaller than Motor Control can resolve: one
        Int E is 0.5 cm of tread, about 2 [deg] on a 13 cm track) is not asked
        again: the leg is driven as it is, or the final heading accepted.
        """
        futile = self._turned_from is not None and abs(
            angle_diff_deg(pose.heading_deg, self._turned_from)) < 0.5
        self._turned_from = None
        last = len(self.waypoints) - 1
        while self.index <= last:
            tol = self.o.goal_tol_cm if self.index == last else self.o.waypoint_tol_cm
            if math.dist((pose.x, pose.y), self.waypoints[self.index]) <= tol:
                self.index += 1
            else:
                break
        if self.index > last:
            if self.heading_deg is None:
                return None
            err = angle_diff_deg(self.heading_deg, pose.heading_deg)
            if abs(err) <= self.o.heading_tol_deg or futile:
                return None
            self.steps += 1
            self._turned_from = pose.heading_deg
            return Motion("turn", err)
        tx, ty = self.waypoints[self.index]
        dist = math.hypot(tx - pose.x, ty - pose.y)
        bearing = math.degrees(math.atan2(ty - pose.y, tx - pose.x))
        err = angle_diff_deg(bearing, pose.heading_deg)
        # the tolerance shrinks with distance: at most ~1 cm lateral error per step
        tol = max(self.o.align_tol_deg,
                  math.degrees(math.atan2(1.0, max(min(dist, self.o.step_cm), 1e-6))))
        self.steps += 1
        if abs(err) > tol and not futile:
            self._turned_from = pose.heading_deg
            return Motion("turn", err)
        return Motion("move", min(dist, self.o.step_cm))


def plan_route(grid: GridMap, start: tuple[float, float], goal: tuple[float, float], *,
               radius_cm: float, margin_cm: float, unknown: str = "blocked",
               snap_radius_cm: float = 30.0) -> Plan | None:
    """A* from ``start`` to ``goal`` [cm] on the known part of ``grid`` (cropped: cheaper).

    Returns:
        The plan, or None when there is none (see `planner.plan_path`).
    """
    if grid.known_bounds() is None:
        return None
    k = math.ceil((radius_cm + margin_cm + snap_radius_cm) / grid.resolution_cm) + 2
    sub = grid.crop_known(margin_cells=k)
    return plan_path(sub, start, goal, robot_radius_cm=radius_cm, margin_cm=margin_cm,
                     unknown=unknown, snap_radius_cm=snap_radius_cm)  # type: ignore[arg-type]


def route_points(plan: Plan, start: tuple[float, float]) -> list[tuple[float, float]]:
    """The waypoints to drive: the plan's, without its first point when that is ``start``.

    (A start snapped out of an inflated obstacle keeps its first point: the
    rover must drive there first.)
    """
    pts = list(plan.waypoints_cm)
    if len(pts) > 1 and math.dist(pts[0], start) < 1.0:
        pts = pts[1:]
    return pts


def shorten(points: list[tuple[float, float]], start: tuple[float, float],
            cut_cm: float) -> list[tuple[float, float]]:
    """The polyline ``start`` -> ``points`` ending ``cut_cm`` before its end, along it [cm].

    Returns:
        The waypoints after ``start`` (the last one moved back along its leg);
        empty when the whole polyline is shorter than ``cut_cm``.
    """
    pts = [start, *points]
    remaining = sum(math.dist(a, b) for a, b in zip(pts, pts[1:], strict=False)) - cut_cm
    if remaining <= 0:
        return []
    out: list[tuple[float, float]] = []
    for a, b in zip(pts, pts[1:], strict=False):
        leg = math.dist(a, b)
        if leg >= remaining:
            t = remaining / leg if leg > 0 else 0.0
            out.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
            return out
        out.append(b)
        remaining -= leg
    return out


def with_obstacle(grid: GridMap, x: float, y: float, radius_cm: float) -> GridMap:
    """A copy of ``grid`` with a disc of occupied cells at (x, y) [cm].

    Used after NAV_MOTION_BLOCKED: something the map does not show (another
    rover) stands ahead, so the next plan must go round it.
    """
    cells = np.array(grid.cells, dtype=np.int8)
    ny, nx = cells.shape
    rows, cols = np.mgrid[0:ny, 0:nx]
    ox, oy = grid.origin_cm
    res = grid.resolution_cm
    d = np.hypot(ox + (cols + 0.5) * res - x, oy + (rows + 0.5) * res - y)
    cells[d <= radius_cm] = OCCUPIED
    return GridMap(cells, res, grid.origin_cm)


def passable_at(grid: GridMap, x: float, y: float, radius_cm: float, margin_cm: float) -> bool:
    """Whether the rover's centre may stand at (x, y) [cm] on ``grid``."""
    r, c = grid.world_to_cell(x, y)
    if not grid.contains(r, c):
        return False
    k = math.ceil((radius_cm + margin_cm) / grid.resolution_cm) + 2
    ny, nx = grid.shape
    r0, r1, c0, c1 = max(0, r - k), min(ny, r + k + 1), max(0, c - k), min(nx, c + k + 1)
    sub = grid.crop(r0, r1, c0, c1)
    ok = traversable(sub, radius_cm, margin_cm, "blocked")
    sr, sc = sub.world_to_cell(x, y)
    return bool(ok[sr, sc])


def plan_tiers(radius_cm: float, width_cm: float, plan_margin_cm: float,
               narrow_margin_cm: float) -> tuple[tuple[float, float], ...]:
    """(radius, margin) pairs to plan with, most cautious first [cm] (the first that
    gives a path is used).

    1. The turning radius plus ``plan_margin_cm``: room to turn anywhere on
       the route, with a margin for map error.
    2. The turning radius alone: a doorway or gap that is only a few cm
       wider than the turning disc (a 35 cm gap leaves 17.5 cm each side of
       its middle; radius plus margin needs 15.5 cm from the noisy edges
       of a 5 cm grid, often not there).
    3. Half the body width plus ``narrow_margin_cm``: a passage the rover
       fits through driving straight. The route's turns may then touch an
       edge; the motor reports blocked and the route is replanned.
    4. Half the body width alone: the map's walls are up to a cell thicker
       than the walls (a LIDAR hit on a wall's face lands in the cell on the
       free side), so a 30 cm corridor can map as 20-25 cm of free cells.
    """
    r, m = radius_cm, plan_margin_cm
    half = 0.5 * width_cm
    tiers = [(r, m), (r, 0.0), (half, narrow_margin_cm), (half, 0.0)]
    out: list[tuple[float, float]] = []
    for t in tiers:
        if t not in out and t[0] + t[1] <= r + m:
            out.append(t)
    return tuple(out)
