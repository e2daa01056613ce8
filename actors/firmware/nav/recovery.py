"""Recovery behaviours of a route that is blocked: back off, weigh the pose belief by
the contact, nudge the route sideways, probe a narrow passage. The doubt they size
themselves by (`drift_cm`) is the pose belief's 95 % radius.

`RouteRecovery` is a mixin of `route_nav.RouteNav`: it works on the route's
state (the goal, the working map, the follower, the nudge series) and is not
used on its own.
"""

from __future__ import annotations

import math

import numpy as np
import trio

from actors.firmware.nav.route import Motion, passable_at, with_obstacle
from actors.firmware.planning.clearance import occupied_near, passage_width
from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["RouteRecovery", "NUDGE_STEP_MAX_CM", "MAX_NUDGES", "NUDGE_REACH_CM", "REPLAN_LIMIT",
           "BACKOFF_REPEAT_CM", "STALL_TURN_DEG", "PROBE_WIDTH_CM", "PROBE_PROGRESS_CM"]

# The fixed geometry and bounds of the recovery behaviours. The distances follow from the
# game's passages (a 35 cm gap) and the body (20 x 15 cm); the counts bound how long a
# route may try before it is given up. The doubt they scale with is the belief's.
NUDGE_STEP_MAX_CM = 12.0
"""Largest lateral step of the search for a narrow passage [cm]: below the free width a
35 cm gap leaves a 15 cm wide body (20 cm), so the offsets tried leave no hole between
them; a seeker can reach a gap 21-36 cm off, beyond the +-24 cm six steps of 8 reach."""
MAX_NUDGES = 6
"""Sideways offsets tried per route, at most."""
NUDGE_REACH_CM = 50.0
"""Waypoints this close to the block point are shifted by a nudge [cm]."""
REPLAN_LIMIT = 10
"""Replans after being blocked before a route is given up."""
BACKOFF_REPEAT_CM = 20.0
"""Reverse this far after a second block at one place: room to come back sideways [cm]."""
STALL_TURN_DEG = 8.0
"""A back-off that ends blocked having turned more than this holds
``NavOptions.tread_hold_s`` before the route goes on: a tread stalled (see
`RouteRecovery._backoff_turned`) [deg]."""
PROBE_WIDTH_CM = 40.0
"""A block where the map's passage across the heading is narrower than this probes
sideways at once (see `RouteRecovery._probe_plan`), the nudged route beginning with a
sidestep across the heading of the block (`RouteRecovery._with_sidestep`) [cm]."""
PROBE_PROGRESS_CM = 25.0
"""A block this far from the last one starts a new sideways probe [cm]."""


class RouteRecovery:
    """What a `RouteNav` does when its route is blocked (a mixin; see the module docstring)."""

    def _nudged(self, pts: list[tuple[float, float]]) -> list[tuple[float, float]] | None:
        """``pts`` with the nudge applied: waypoints near the block point shifted sideways;
        when none is near (a long corridor), a shifted waypoint ``NUDGE_REACH_CM`` ahead of
        the block point is driven to first. None when a shifted point is not on free
        ground of the server's map: the search went wider than the passage."""
        assert self._nudge is not None and self._anchor is not None
        dx, dy, cx, cy = self._nudge
        reach = NUDGE_REACH_CM
        near = [i < len(pts) - 1 and math.dist(q, (cx, cy)) <= reach for i, q in enumerate(pts)]
        # an offset within the drift may put the point in a mapped wall: dead reckoning
        # is that far off, so the wall may well be where the rover can pass
        free = math.hypot(dx, dy) <= self.drift_cm
        if any(near):
            out = [(x + dx, y + dy) if n else (x, y) for (x, y), n in zip(pts, near, strict=True)]
            ok = free or all(self._fits(*q) for q, n in zip(out, near, strict=True) if n)
            if ok and self._sidestep:
                out = self._with_sidestep(out)
            return out if ok else None
        h = math.radians(self._anchor[2])
        ahead = (cx + reach * math.cos(h) + dx, cy + reach * math.sin(h) + dy)
        to_goal = math.dist((cx, cy), pts[-1])
        if to_goal <= reach or math.dist(ahead, pts[-1]) >= to_goal:
            return pts  # the goal is near, or ahead of the block leads away from it
        if not (free or self._fits(*ahead)):
            return None
        out = [ahead, *pts]
        return self._with_sidestep(out) if self._sidestep else out

    def _with_sidestep(self, pts: list[tuple[float, float]]) -> list[tuple[float, float]]:
        """``pts`` (a nudged route) preceded by a sidestep: the point beside the rover on
        the shifted line, across the heading of the block.

        Why: driven straight from where the back-off left it, the nudged route meets
        the passage's mouth at an angle; with a heading error of 7 deg the nose then
        hits the face before the body has moved across, or the body slides along the
        face, which the encoders do not see (from 26 to 60 cm off within a few
        probes). A sidestep moves the rover across first, square to the
        heading of the block, so the shifted line is joined where the rover stands
        and the mouth is met head-on. Not when the rover is already on the line
        (within ``waypoint_tol_cm``) or the point is off the server's free ground.
        """
        assert self._nudge is not None and self._anchor is not None
        p = self.map_pose
        bx, by, bh = self._anchor
        h = math.radians(bh)
        nx, ny = -math.sin(h), math.cos(h)
        lateral = (p.x - bx) * nx + (p.y - by) * ny
        move = self._nudge_off - lateral
        side = (p.x + move * nx, p.y + move * ny)
        if abs(move) <= self.o.waypoint_tol_cm or not self._fits(*side):
            return pts
        return [side, *pts]

    def _fits(self, x: float, y: float) -> bool:
        """(x, y) [cm] is on free ground of the server's map. Not more: the offset must
        also make up for a heading error the rover cannot see, so the point may lie
        closer to a wall than the body could stand."""
        return self.map is not None and passable_at(self.map, x, y, 0.0, 0.0)

    def _nudged_plan(self) -> bool:
        """Plan again on the server's map, the route shifted sideways near the block.

        Called when the obstacles learned from blocks cut every route: the
        block was then most likely the rover's own dead-reckoning error
        making it miss a narrow passage (a gap only ~20 cm wider than the body
        is missed by a heading drift of a few degrees over a few metres), not
        an obstacle the map does not show. The search tries lateral offsets
        of the waypoints near the block point, alternating sides and growing
        by ``nudge_step_cm`` (+4, -4, +8, -8 ... [cm]), one per block
        (offsets whose points do not fit are skipped), at most ``MAX_NUDGES``
        per route and bounded by ``REPLAN_LIMIT`` blocks.
        """
        if self.map is None or self._last_block is None:
            return False
        if self._anchor is None:  # the first block of the series: later ones come from nudges
            self._anchor = self._last_block
        bx, by, bh = self._anchor
        h = math.radians(bh)
        self.work_map = self.map
        if self._nudges == 0:  # a new series: first toward the side that helped last
            self._nudge_first = 1.0 if self._nudge_off >= 0 else -1.0
        first = self._nudge_first
        step = min(NUDGE_STEP_MAX_CM, max(self.o.nudge_step_cm, self.drift_cm / 3.0))
        while self._nudges < MAX_NUDGES:
            k = self._nudges
            self._nudges += 1
            off = step * (k // 2 + 1) * (first if k % 2 == 0 else -first)
            self._nudge = (-math.sin(h) * off, math.cos(h) * off, bx, by)
            self._nudge_off = off
            if self._plan():
                self.counters["nudges"] += 1
                return True
        self._nudge = None
        return False

    async def _blocked_route(self, why: str) -> None:
        self.replans += 1
        if await self.on_blocked():
            return
        if self.replans > REPLAN_LIMIT:
            await self._give_up(f"{why} {self.replans} times")
            return
        assert self.work_map is not None
        p = self.map_pose
        if why == "blocked" and self._backoff_turned():
            # a tread stalled: backing off again only spins the rover where it stands
            # (ten blocks in 12 s of a 16 s stall); wait for it
            self.counters["stall_holds"] += 1
            self._replan = True
            self._blocked, self._done = False, 0.0
            self._hold_until = trio.current_time() + self.o.tread_hold_s
            await self.status(self.state, f"a tread stalls; holding {self.o.tread_hold_s:.0f} s")
            return
        start = self._backoff_start()
        if why == "blocked" and start is not None and \
                math.dist((p.x, p.y), (start.x, start.y)) < 1.0:
            # a back-off that did not move: wedged behind; reversing again cannot help
            self._replan = True
            await self.after_motion(False, 0.0)
            return
        ahead = self.radius_cm + 8.0
        h = math.radians(p.heading_deg)
        back = self.o.backoff_cm
        if why == "blocked" and self._contact_fix():
            pass  # a mapped wall stopped it: the pose is corrected, nothing to learn
        elif why == "blocked" and (self._in_passage() or self._nudging_here()):
            # a mapped wall on one side or the other: drift, nothing to learn; probe sideways
            self._last_block = (p.x, p.y, p.heading_deg)
            self._probe = True
        elif why == "blocked":
            # a second block near the first: something the map does not show is there
            # (one block alone may be a restarted motor cutting its command short)
            last, self._last_block = self._last_block, (p.x, p.y, p.heading_deg)
            if last is not None and math.dist(last[:2], (p.x, p.y)) <= 30.0:
                self.work_map = with_obstacle(self.work_map, p.x + ahead * math.cos(h),
                                              p.y + ahead * math.sin(h), 8.0)
                back = BACKOFF_REPEAT_CM
        self._replan = True
        await self.command(Motion("move", -back))

    def _backoff_start(self) -> Pose | None:
        """Where the last motion started, if it was a reverse (a back-off); else None."""
        m, start = self.last_motion, self.motion_from
        if m is None or m.kind != "move" or m.amount >= 0:
            return None
        return start

    def _backoff_turned(self) -> bool:
        """The last motion, a reverse (a back-off), ended blocked having turned the rover
        more than ``STALL_TURN_DEG``: one tread drives, the other does not. Backing away
        from a wall is free ground, so a turn there is no wall's doing."""
        start = self._backoff_start()
        if start is None:
            return False
        turned = abs(angle_diff_deg(self.map_pose.heading_deg, start.heading_deg))
        return turned > STALL_TURN_DEG

    def _contact_fix(self) -> bool:
        """After a straight move ended blocked: the contact weighs the pose belief
        (`belief_tracking.BeliefTracking.contact_update`); True when the map's walls
        explain the stop and the pose moved, so there is nothing to learn."""
        return self.contact_update()

    def _in_passage(self) -> bool:
        """The last forward move was blocked where the map's walls are close on both sides
        (narrower than ``PROBE_WIDTH_CM`` across the heading), at the body's centre or at
        its nose: a rover stopped at a gap's mouth has only its nose in the gap."""
        m = self.last_motion
        if m is None or m.kind != "move" or m.amount <= 0 or self.map is None:
            return False
        p = self.map_pose
        h = math.radians(p.heading_deg)
        nose = 0.5 * self.length_cm
        for x, y in ((p.x, p.y), (p.x + nose * math.cos(h), p.y + nose * math.sin(h))):
            w = passage_width(self.map, x, y, p.heading_deg, max_cm=PROBE_WIDTH_CM)
            if w is not None and w < PROBE_WIDTH_CM:
                return True
        return False

    def _wall_within_drift(self) -> bool:
        """A mapped wall lies within the body's radius plus ``drift_cm`` of the believed
        position: the rover may be touching it, though it believes itself clear.

        Why: both treads counting short in a move read the same whether both encoders
        slip (the rover goes 2-3 times what counts: hold) or the rover slides along a
        wall it met at an angle (counting about 0.3 of its travel: a hider 45 cm from
        where it believed after a 7 m leg; holding for it leaves the hider far from
        its spot). Only the
        map and the doubt about the pose tell them apart: slipping on open floor far
        from any wall, a slide only where a wall can be. Occupied cells' centres.
        """
        if self.map is None:
            return False
        reach = self.radius_cm + self.drift_cm
        near = occupied_near(self.map, self.map_pose, reach)
        if near is None:
            return False
        px, py, _, _ = near
        return float(np.min(np.hypot(px, py))) <= reach

    def _nudging_here(self) -> bool:
        """A nudge series is on and this block is within ``NUDGE_REACH_CM`` of its anchor:
        the nudged route met a wall again at the passage it looks for.

        Why: blocked short of the mouth by dead reckoning (the nose a few cm before
        it, or on the face beside it), the block was taken for an obstacle the map
        does not show; learned inside a mapped wall it changed nothing, and the same
        offset was driven again and again (the same offset four times, 2 cm short of
        passing, until the replan limit).
        The next offset is the search's next step."""
        if self._nudge is None or self._anchor is None:
            return False
        p = self.map_pose
        return math.dist((p.x, p.y), self._anchor[:2]) <= NUDGE_REACH_CM

    def _probe_plan(self) -> bool:
        """Plan after a block in a narrow passage: the route shifted sideways at once.

        Dead reckoning cannot tell which wall the rover scraped (its heading
        error is invisible to it), so it tries the nudge series (`_nudged_plan`)
        without first learning an obstacle, which in a passage would only close
        it. Once a probe made progress (the next block is ``PROBE_PROGRESS_CM``
        on), a new series starts on the side that helped.
        """
        p = self.map_pose
        if self._anchor is None or self._progress(p) > PROBE_PROGRESS_CM:
            self._anchor, self._nudge, self._nudges = self._last_block, None, 0
        self._sidestep = True
        try:
            return self._nudged_plan()
        finally:
            self._sidestep = False

    def _progress(self, p: Pose) -> float:
        """How far ``p`` lies beyond the series' anchor along the anchor's heading [cm].

        Along, not straight-line: a nudge moves the block point across the heading
        by its own offset (up to 3 x ``NUDGE_STEP_MAX_CM``), and a contact fix
        moves it a few cm more; counting that as progress restarted the series
        around the nudged point, 25 cm to the wrong side, and the offset that would
        have passed was never tried."""
        assert self._anchor is not None
        bx, by, bh = self._anchor
        h = math.radians(bh)
        return (p.x - bx) * math.cos(h) + (p.y - by) * math.sin(h)
