"""Navigation on a map downloaded from the server: the hider's and the seeker's base.

`RouteNav` gets the server's map, origin and destination, plans a route
(`route.plan_route`, in tiers from cautious to tight) and follows it with the
ADP loop; what it does when the route is blocked is in `recovery`.
"""

from __future__ import annotations

import math

import trio

from actors import BufferPool
from actors.firmware.addresses import Addresses
from actors.firmware.hardware import HardwareSpec
from actors.firmware.nav.base import NavBase
from actors.firmware.nav.belief_tracking import BeliefTracking
from actors.firmware.nav.nudge import NUDGE_REACH_CM, Nudge
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.recovery import RouteRecovery
from actors.firmware.nav.route import PathFollower, plan_route, route_points, shorten
from server.protocol.grid_map import GridMap

__all__ = ["RouteNav", "MAP_RETRY_S", "MAP_RETRY_MAX_S"]

MAP_RETRY_S = 20.0
"""Waiting for the map this long asks the server again, the wait doubling each time up to
``MAP_RETRY_MAX_S`` [s]. A map lost on the way (a chunk corrupted on the link is refused
and the map never completes, and waiting for it could last the game) or refused ("no map
yet", "outbox full; request the map later") comes again; the doubling lets a slow
transfer finish before it is asked for once more. A protocol timing, not the rover's."""
MAP_RETRY_MAX_S = MAP_RETRY_S * 2 ** 3
"""The longest wait between map requests: ``MAP_RETRY_S`` doubled three times [s]."""


class RouteNav(RouteRecovery, BeliefTracking, NavBase):
    """Navigation on a map downloaded from the server: the hider's and the seeker's base.

    Flow: ``start`` -> ``map_request`` -> NAV_MAP_DOWNLOAD; ``origin`` and
    ``destination`` frames are kept as they come (the server sends origin,
    start and destination together, before the map has arrived); once map,
    origin and a destination are all known, `on_goal` runs. `goto` plans with
    A* on the map (obstacles inflated by the rover's radius) and follows the
    route with the ADP loop. When the motor reports blocked, something the map
    does not show is ahead (another rover): it is added to a working copy of the
    map, the rover backs off and replans, at most ``REPLAN_LIMIT`` times at one place.
    """

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec | None = None,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 addresses: Addresses | None = None) -> None:
        super().__init__(pool=pool, spec=spec, options=options, memory=memory,
                         addresses=addresses)
        self.map: GridMap | None = None
        """The server's map (map frame), None until downloaded."""
        self.work_map: GridMap | None = None
        """The map plus obstacles learned from blocked motions."""
        self.pending: tuple[float, float, float | None] | None = None
        """A destination waiting for the map or the origin."""
        self.follower: PathFollower | None = None
        self.goal: tuple[float, float] | None = None
        self.goal_heading: float | None = None
        self.replans = 0
        """Blocks counted toward ``REPLAN_LIMIT`` (`RouteRecovery._count_block`)."""
        self._progress_mark = math.inf  # the route's remaining length when the count started
        self._stall_holds = 0  # holds for a stalled tread on this route (`RouteRecovery._stalled`)
        self.stop_short_cm = 0.0
        """The current route ends this far before its goal [cm] (see `goto`)."""
        self.tier: tuple[float, float] | None = None
        """(radius, margin) [cm] of the planning tier the current route used (`plan_tiers`)."""
        self._replan = False  # replan after the backoff in flight
        # blocks are held in the rover's own frame (`RouteRecovery._here`)
        self._last_block: tuple[float, float, float] | None = None  # (x, y, heading) of a block
        self._nudge: Nudge | None = None  # the offset of the series being driven
        self._anchor: tuple[float, float, float] | None = None  # the block nudges start from
        self._nudges = 0  # nudges tried on this route
        self._probe = False  # the block in flight was in a narrow passage: probe sideways
        self._nudge_off = 0.0  # the last sideways offset tried [cm], signed (left +)
        self._nudge_first = 1.0  # the side a series of nudges tries first
        self._sidestep = False  # the nudge in flight starts with a sidestep (`_nudged`)
        self._probe_step: float | None = None  # the probe series' step (`nudge.probe_step`)
        self._mouth = False  # the probe series is at a passage's mouth (`nudge.at_mouth`)
        self.map_requests = 0
        """``map_request`` frames sent (see ``MAP_RETRY_S``)."""
        self._map_wait = 0.0  # the wait before the next request [s]
        self._map_again = math.inf  # ask again at this time, if still waiting
        self._init_belief()

    # ------------------------------------------------------------------ server
    async def on_start_cmd(self) -> None:
        if self.map is None:
            await self._request_map(MAP_RETRY_S)
            await self.set_state("waiting_map", "map requested")
        await self._proceed()

    async def _request_map(self, wait_s: float) -> None:
        """Ask the server for the map; ask again after ``wait_s`` if none came."""
        self.map_requests += 1
        self._map_wait = wait_s
        self._map_again = trio.current_time() + wait_s
        await self.report("map_request")

    async def on_stop_cmd(self) -> None:
        self.follower = None
        self.pending = None
        await super().on_stop_cmd()

    async def on_map_download(self, grid: GridMap) -> None:
        if self.map is not None and self.map_requests > 1 and self.state != "waiting_map":
            return  # a second answer to a repeated request: keep the obstacles learned
        self.map = self.work_map = grid
        if self.state == "waiting_map":
            await self.set_state("ready", "map received")
        await self._proceed()

    async def on_destination(self, x: float, y: float, heading: float | None,
                             within: float | None = None) -> None:
        self.pending = self.memory.goal = (x, y, heading)
        self.memory.within = within
        await self._proceed()

    async def on_restart(self) -> None:
        if self.memory.started:  # resume: the map is gone with the old incarnation
            self.started = True
            self.pending = self.memory.goal
            await self.on_start_cmd()

    def answered(self) -> None:
        """The destination got its answer: a restart must not act on it again."""
        self.memory.goal = None

    async def _proceed(self) -> None:
        if (self.pending is None or self.map is None or self.origin is None
                or self.follower is not None or self.moving or not self.can_move):
            return  # retried on every tick
        x, y, heading = self.pending
        self.pending = None
        await self.on_goal(x, y, heading)

    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        """Hook: map, origin and destination are known; act on the destination."""

    async def on_tick(self, now: float) -> None:
        if self.state == "waiting_map" and self.map is None and now >= self._map_again:
            await self._request_map(min(2.0 * self._map_wait, MAP_RETRY_MAX_S))
        await self._proceed()

    # ------------------------------------------------------------------ routes
    async def goto(self, goal: tuple[float, float], heading: float | None, *,
                   stop_short_cm: float = 0.0) -> bool:
        """Plan to ``goal`` (map frame [cm]) and start driving; False when there is no path.

        ``stop_short_cm`` ends the route that far before the goal, along the path
        (the seeker's approach to a place where the hider may stand) [cm].
        """
        assert self.work_map is not None
        self.goal, self.goal_heading = goal, heading
        self.stop_short_cm = stop_short_cm
        self.replans, self._progress_mark, self._stall_holds = 0, math.inf, 0
        self.forget_tread_check()
        self._last_block, self._nudge, self._nudges, self._anchor = None, None, 0, None
        self._probe, self._nudge_off, self._mouth = False, 0.0, False
        if not self._plan():
            return False
        await self.set_state("driving", f"to ({goal[0]:.0f}, {goal[1]:.0f})")
        await self._step()
        return True

    async def goto_as(self, goal: tuple[float, float], heading: float | None, state: str,
                      detail: str, *, stop_short_cm: float = 0.0) -> bool:
        """`goto`, then say ``state`` (``detail``) while the route is driven.

        A route may end as it starts (the goal already within tolerance): `goto` then
        calls `on_arrived`, which moves on to the next state (a scan). Only a route
        still being driven is relabelled; relabelling after that would leave the rover
        in a state that nothing ends (no motion in flight, no scan running).
        """
        if not await self.goto(goal, heading, stop_short_cm=stop_short_cm):
            return False
        if self.state == "driving":
            await self.set_state(state, detail)
        return True

    def plan_tiers(self) -> tuple[tuple[float, float], ...]:
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
        r, m = self.radius_cm, self.o.plan_margin_cm
        half = 0.5 * self.width_cm
        tiers = [(r, m), (r, 0.0), (half, self.o.narrow_margin_cm), (half, 0.0)]
        out: list[tuple[float, float]] = []
        for t in tiers:
            if t not in out and t[0] + t[1] <= r + m:
                out.append(t)
        return tuple(out)

    def _plan(self) -> bool:
        assert self.work_map is not None and self.goal is not None
        p = self.map_pose
        plan = None
        for radius, margin in self.plan_tiers():
            plan = plan_route(self.work_map, (p.x, p.y), self.goal, radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                self.tier = (radius, margin)
                break
        if plan is None:
            self.follower = None
            return False
        pts = route_points(plan, (p.x, p.y))
        if plan.goal_snapped:
            pts.append(self.goal)  # the goal itself; the spot check vouched for it
        if self._anchor is not None and math.dist(self._anchor[:2], (self.pose.x, self.pose.y)) > \
                2.0 * NUDGE_REACH_CM:
            self._nudge, self._anchor, self._nudges = None, None, 0  # past the tight spot
        if self._nudge is not None:
            nudged = self._nudged(pts)
            if nudged is None:
                self.follower = None
                return False
            pts = nudged
        if self.stop_short_cm > 0:
            pts = shorten(pts, (p.x, p.y), self.stop_short_cm) or [(p.x, p.y)]
        self.follower = PathFollower(pts, self.goal_heading, self.o)
        self._budget = self.follower.budget(p)
        return True

    async def _step(self) -> None:
        if self.follower is None or self.moving:
            return
        if self.follower.steps >= self._budget:
            await self._blocked_route("no progress")
            return
        motion = self.follower.next_motion(self.map_pose)
        if motion is None:
            self.follower = None
            await self.on_arrived()
            return
        await self.command(motion)

    async def after_motion(self, blocked: bool, done: float) -> None:
        if self.follower is None:
            await self.after_other_motion(blocked, done)
            return
        if await self.check_treads(blocked, done):
            return
        if blocked:
            await self._blocked_route("blocked")
            return
        if self._replan:
            self._replan = False
            probe, self._probe = self._probe, False
            if probe and self._probe_plan():
                pass
            elif not self._plan() and not self._nudged_plan():
                await self._give_up("no path after being blocked")
                return
        await self._step()

    async def on_origin(self) -> None:
        self.on_server_origin()  # a new belief round a new origin; a retry's widened

    def on_pose_at_rest(self) -> None:
        self.track_belief()

    async def _give_up(self, reason: str) -> None:
        self.follower = None
        self._replan = False
        await self.on_route_failed(reason)
        await self._proceed()

    async def on_blocked(self) -> bool:
        """Hook: the route is blocked; return True when handled (no replan)."""
        return False

    async def on_arrived(self) -> None:
        """Hook: at the goal (and heading)."""

    async def on_route_failed(self, reason: str) -> None:
        """Hook: the goal could not be reached."""

    async def after_other_motion(self, blocked: bool, done: float) -> None:
        """Hook: a motion outside a route (e.g. a scan turn) ended."""

    def pose_data(self) -> dict[str, float]:
        """The map-frame pose as a frame payload."""
        p = self.map_pose
        return {"x": round(p.x, 1), "y": round(p.y, 1), "heading": round(p.heading_deg, 1)}

