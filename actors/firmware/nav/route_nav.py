"""The hider's and the seeker's navigation actor: a route on the server's map.

`RouteNav` is one actor that owns and wires its parts (Nav2's split):

* the **localiser** (`localiser.Localiser`: the pose belief, and from it the
  map -> own frame origin; the tread reports widen it),
* the **controller** (`controller.Controller` in `base.NavBase`: the ADP loop's
  motion in flight) and the route it follows (`route.PathFollower`),
* the **recovery behaviours** (`recovery.RECOVERIES`, tried in order when the
  route is blocked; the sideways search's state in `nudge_series.NudgeSeries`)
  and what a tread report does (`tread_faults.TreadFaults`),
* the **role behaviour** (`hider.Hide` or `seeker.Seek`: `role.RoleBehaviour`),
  which sets the goals and answers the server.

It gets the server's map, origin and destination, plans a route
(`route.plan_route`, in tiers from cautious to tight) and follows it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import trio

from actors import BufferPool
from actors.firmware.addresses import Addresses
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.belief import Spread
from actors.firmware.nav.base import NavBase
from actors.firmware.nav.lateral_touch import LateralTouch
from actors.firmware.nav.localiser import Localiser
from actors.firmware.nav.nudge_series import NudgeSeries
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.passage_approach import square_to_axis
from actors.firmware.nav.place import SAME_PLACE_CM
from actors.firmware.nav.recovery import (
    RECOVERIES,
    Action,
    BackOffAndReplan,
    BlockView,
    GiveUpRoute,
    Hold,
    Replan,
)
from actors.firmware.nav.role import RoleBehaviour
from actors.firmware.nav.route import (
    Motion,
    PathFollower,
    plan_route,
    plan_tiers,
    route_points,
    shorten,
    with_obstacle,
)
from actors.firmware.nav.tread_faults import TreadFaults
from actors.firmware.planning.clearance import occupied_near
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


class RouteNav(NavBase):
    """The hider's and the seeker's navigation actor (see the module docstring).

    Flow: ``start`` -> ``map_request`` -> NAV_MAP_DOWNLOAD; ``origin`` and
    ``destination`` frames are kept as they come (the server sends origin,
    start and destination together, before the map has arrived); once map,
    origin and a destination are all known, `on_goal` runs. `goto` plans with
    A* on the map (obstacles inflated by the rover's radius) and follows the
    route with the ADP loop. When the motor reports blocked, something the map
    does not show is ahead (another rover): it is added to a working copy of the
    map, the rover backs off and replans, at most ``REPLAN_LIMIT`` times at one place.

    Args:
        role: ``hider`` or ``seeker`` (the actor's names and its belief's generator).
        behaviour: makes the role behaviour for this actor (`hider.Hide`,
            `seeker.Seek`).
        pool, spec, options, memory, addresses: as for `base.NavBase`.
    """

    def __init__(self, role: str, behaviour: Callable[[RouteNav], RoleBehaviour], *,
                 pool: BufferPool, spec: HardwareSpec,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 addresses: Addresses | None = None) -> None:
        self.role = role
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
        """Blocks counted toward ``REPLAN_LIMIT`` (`count_block`)."""
        self.stall_holds = 0
        """Uncounted holds for a stalled tread on this route (`recovery.WaitOutStall`)."""
        self._progress_mark = math.inf  # the route's remaining length when the count started
        self._budget = 0  # steps the route may take (`PathFollower.budget`)
        self.stop_short_cm = 0.0
        """The current route ends this far before its goal [cm] (see `goto`)."""
        self.tier: tuple[float, float] | None = None
        """(radius, margin) [cm] of the planning tier the current route used (`plan_tiers`)."""
        self._replan = False  # replan after the backoff in flight
        self._probe = False  # the block in flight was in a narrow passage: probe sideways
        self.map_requests = 0
        """``map_request`` frames sent (see ``MAP_RETRY_S``)."""
        self._map_wait = 0.0  # the wait before the next request [s]
        self._map_again = math.inf  # ask again at this time, if still waiting
        self.localiser = Localiser(self)
        """The pose belief: the origin and the doubt (`drift_cm`)."""
        self.treads = TreadFaults(self)
        """What a tread report does (stop, hold, check the treads)."""
        self.nudges = NudgeSeries(self)
        """The route's sideways search."""
        self.touch = LateralTouch(self)
        """The route's touch of a face across a passage it may miss."""
        self.recoveries = RECOVERIES
        """The recovery behaviours, in the order they are tried."""
        self.behaviour = behaviour(self)
        """The role behaviour: it sets the goals and answers the server."""

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
        """Map, origin and destination are known: the role behaviour acts on it."""
        await self.behaviour.on_goal(x, y, heading)

    async def on_tick(self, now: float) -> None:
        if self.state == "waiting_map" and self.map is None and now >= self._map_again:
            await self._request_map(min(2.0 * self._map_wait, MAP_RETRY_MAX_S))
        await self._proceed()
        await self.behaviour.on_tick(now)

    async def on_ir(self, in_range: bool, *, pinned: bool = False) -> None:
        await self.behaviour.on_ir(in_range, pinned=pinned)

    async def command(self, motion: Motion) -> None:
        self.behaviour.before_command(motion)
        await super().command(motion)

    async def on_tread_fault(self, fault: TreadFault) -> None:
        await self.treads.on_tread_fault(fault)

    def note_tread_driven(self, left_cm: float, right_cm: float) -> None:
        self.localiser.note_tread_driven(left_cm, right_cm)

    # ------------------------------------------------------------------ the belief
    @property
    def spread(self) -> Spread | None:
        """The pose belief's spread (None before the belief exists)."""
        return self.localiser.spread

    @property
    def drift_cm(self) -> float:
        """How far the map-frame pose may be off [cm]: the belief's 95 % radius."""
        return self.localiser.drift_cm

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
        self.replans, self._progress_mark, self.stall_holds = 0, math.inf, 0
        self.treads.forget_tread_check()
        self.nudges.new_route()
        self.touch.new_route()
        self._probe = False
        if not self.plan():
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
        """(radius, margin) pairs to plan with, most cautious first [cm] (`route.plan_tiers`)."""
        return plan_tiers(self.radius_cm, self.width_cm, self.o.plan_margin_cm,
                          self.o.narrow_margin_cm)

    def plan(self) -> bool:
        """Plan the route to the goal from the map-frame pose, in tiers (`plan_tiers`),
        with the sideways search's nudge applied; False when there is no route.

        A route whose first narrow passage the rover may miss goes first to touch a
        face across it (`lateral_touch.LateralTouch.detour`), or crosses it square to
        its axis (`passage_approach.square_to_axis`)."""
        assert self.work_map is not None and self.goal is not None
        p = self.map_pose
        pts = self._route_to(self.goal)
        if pts is None:
            self.follower = None
            return False
        spread = self.spread
        if self.nudges.nudge is None and spread is not None:
            touch = self.touch.detour(pts)
            to_stand = None if touch is None else self._route_to(touch.stand)
            if touch is not None and to_stand is not None:
                self.follower = PathFollower(to_stand, touch.heading_deg, self.o)
                self._budget = self.follower.budget(p)
                return True
            self.touch.touch = None
            pts = square_to_axis(self.work_map, (p.x, p.y), pts, covariance=spread.covariance,
                                 body_cm=(self.length_cm, self.width_cm),
                                 turn_radius_cm=self.radius_cm)
        nudged = self.nudges.nudged(pts)
        if nudged is None:
            self.follower = None
            return False
        pts = nudged
        if self.stop_short_cm > 0:
            pts = shorten(pts, (p.x, p.y), self.stop_short_cm) or [(p.x, p.y)]
        self.follower = PathFollower(pts, self.goal_heading, self.o)
        self._budget = self.follower.budget(p)
        return True

    def _route_to(self, goal: tuple[float, float]) -> list[tuple[float, float]] | None:
        """A*'s waypoints from the map-frame pose to ``goal`` [cm] on the working map, in
        tiers (`plan_tiers`; the tier used is kept in ``tier``); None when no tier has
        a path."""
        assert self.work_map is not None
        p = self.map_pose
        plan = None
        for radius, margin in self.plan_tiers():
            plan = plan_route(self.work_map, (p.x, p.y), goal, radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                self.tier = (radius, margin)
                break
        if plan is None:
            return None
        pts = route_points(plan, (p.x, p.y))
        if plan.goal_snapped:
            pts.append(goal)  # the goal itself; the spot check vouched for it
        return pts

    async def _step(self) -> None:
        if self.follower is None or self.moving:
            return
        if self.follower.steps >= self._budget:
            await self.blocked_route("no progress")
            return
        if self.touch.passed() and not self.plan():  # the next passage gets its check
            await self.give_up("no path beyond the passage")
            return
        motion = self.follower.next_motion(self.map_pose)
        if motion is None:
            motion = self.touch.touch_motion()
            if motion is not None:
                await self.command(motion)
                return
            self.follower = None
            await self.behaviour.on_arrived()
            return
        await self.command(motion)

    async def after_motion(self, blocked: bool, done: float) -> None:
        if self.follower is None:
            await self.after_other_motion(blocked, done)
            return
        touched = self.touch.take_touch()
        if await self.treads.check_treads(blocked, done):
            return
        if touched:  # weigh the belief by the contact, back off, plan from the new pose
            if blocked:
                self.localiser.contact_update()
            self._replan = True
            await self.command(Motion("move", -self.o.backoff_cm))
            return
        if blocked:
            await self.blocked_route("blocked")
            return
        if self._replan:
            self._replan = False
            probe, self._probe = self._probe, False
            if probe and self.nudges.probe(self.plan):
                pass
            elif not self.plan() and not self.nudges.plan(self.plan):
                await self.give_up("no path after being blocked")
                return
        await self._step()

    async def on_origin(self) -> None:
        self.localiser.on_server_origin()  # a new belief round a new origin; a retry's widened

    def on_pose_at_rest(self) -> None:
        self.localiser.track_belief()

    async def give_up(self, reason: str) -> None:
        """Give the route up: the role behaviour answers (`RoleBehaviour.on_route_failed`)."""
        self.follower = None
        self._replan = False
        await self.behaviour.on_route_failed(reason)
        await self._proceed()

    async def after_other_motion(self, blocked: bool, done: float) -> None:
        """A motion outside a route (a scan's turn, a sweep's leg) ended."""
        await self.behaviour.after_other_motion(blocked, done)

    def pose_data(self) -> dict[str, float]:
        """The map-frame pose as a frame payload."""
        p = self.map_pose
        return {"x": round(p.x, 1), "y": round(p.y, 1), "heading": round(p.heading_deg, 1)}

    # ------------------------------------------------------------------ blocks
    def count_block(self) -> None:
        """Count a block toward ``REPLAN_LIMIT``, afresh when the route made progress.

        Why: a rover with a few degrees of heading doubt scrapes the side walls of a
        long passage every metre or so; each scrape is a block, but one that comes
        after the route got nearer its goal is not the same place tried again. What
        the limit bounds is trying one place: the count starts again once the route's
        remaining length is ``SAME_PLACE_CM`` under what it was at the block that
        last started it. Still bounded: that mark only falls, by that much each time.
        """
        left = self.follower.remaining_cm(self.map_pose) if self.follower is not None \
            else math.inf
        if left < self._progress_mark - SAME_PLACE_CM:
            self.replans = 0
            self._progress_mark = left
        self.replans += 1

    async def blocked_route(self, why: str) -> None:
        """The route is blocked (``why``: ``blocked`` or ``no progress``): count it, let
        the role behaviour take it (the seeker near its place looks from there), else
        carry out the first recovery behaviour's action (`recovery`)."""
        self.count_block()
        if await self.behaviour.on_blocked():
            return
        assert self.work_map is not None
        view = BlockView(self, why)
        for recovery in self.recoveries:
            action = recovery.decide(view)
            if action is not None:
                await self._act(action, view)
                return

    async def _act(self, action: Action, view: BlockView) -> None:
        if isinstance(action, Hold):
            self.stall_holds += 1
            self.replans = max(0, self.replans - action.uncount)
            self.counters["stall_holds"] += 1
            self._replan = True
            await self.hold_still(trio.current_time() + action.seconds,
                                  f"a tread stalls; holding {action.seconds:.0f} s")
        elif isinstance(action, GiveUpRoute):
            await self.give_up(action.reason)
        elif isinstance(action, Replan):
            self._replan = True
            await self.after_motion(False, 0.0)
        elif isinstance(action, BackOffAndReplan):
            self._learn(action, view)
            self._replan = True
            await self.command(Motion("move", -action.cm))

    def _learn(self, action: BackOffAndReplan, view: BlockView) -> None:
        """What a back-off's block teaches the sideways search and the working map."""
        if action.probe:
            self.nudges.last_block, self.nudges.mouth = view.here, action.mouth
            self._probe = True
        elif action.anchor:
            self.nudges.last_block = self.nudges.anchor = view.here
        elif action.mark:
            self.nudges.last_block = view.here
        if action.obstacle is not None and self.work_map is not None:
            x, y, r = action.obstacle
            self.work_map = with_obstacle(self.work_map, x, y, r)

    def wall_within_drift(self) -> bool:
        """A mapped wall lies within the body's radius plus ``drift_cm`` of the believed
        position: the rover may be touching it, though it believes itself clear.

        Why: both treads counting short in a move read the same whether both encoders
        slip (the rover goes 2-3 times what counts: hold) or the rover slides along a
        wall it met at an angle (counting about 0.3 of its travel: a hider 45 cm from
        where it believed after a 7 m leg; holding for it leaves the hider far from
        its spot). Only the map and the doubt about the pose tell them apart: slipping
        on open floor far from any wall, a slide only where a wall can be. Occupied
        cells' centres.
        """
        if self.map is None:
            return False
        reach = self.radius_cm + self.drift_cm
        near = occupied_near(self.map, self.map_pose, reach)
        if near is None:
            return False
        px, py, _, _ = near
        return float(np.min(np.hypot(px, py))) <= reach

    def check_sign(self) -> float:
        """The tread check's direction (`tread_faults.TreadFaults.check_treads`): in
        reverse when the nearest occupied cell of the map within the body's radius plus
        the drift and the check's length lies ahead, else forward. A turn that reported a
        silent tread may have been jammed by that wall; a check into it would end
        blocked with the treads well and hold for nothing."""
        if self.map is None:
            return 1.0
        reach = self.radius_cm + self.drift_cm + self.treads.check_cm
        near = occupied_near(self.map, self.map_pose, reach)
        if near is None:
            return 1.0
        px, py, fwd, _ = near
        return -1.0 if fwd[int(np.argmin(np.hypot(px, py)))] > 0.0 else 1.0
