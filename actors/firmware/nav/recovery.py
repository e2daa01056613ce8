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

from actors.firmware.nav.nudge import (
    MAX_NUDGES,
    NUDGE_REACH_CM,
    PROBE_PROGRESS_CM,
    Block,
    Nudge,
    at_mouth,
    in_passage,
    near_block,
    nudge_step,
    nudged_route,
    probe_route,
    probe_step,
    progress,
    series_offset,
    through_distance,
)
from actors.firmware.nav.route import Motion, with_obstacle
from actors.firmware.nav.tread_faults import TREAD_CHECK_CM
from actors.firmware.planning.clearance import occupied_near
from server.protocol.pose import Pose, angle_diff_deg, compose

__all__ = ["RouteRecovery", "REPLAN_LIMIT", "BACKOFF_REPEAT_CM", "STALL_TURN_DEG",
           "STALL_HOLDS"]

# The bounds of the recovery behaviours: how long a route may try before it is given up,
# and how a back-off reads a stalled tread. The geometry of the sideways search is in
# `nudge`.
REPLAN_LIMIT = 10
"""Blocks without progress before a route is given up: a block that comes after the
route got ``PROBE_PROGRESS_CM`` nearer its goal than at the last block counted afresh
(`RouteRecovery._count_block`)."""
BACKOFF_REPEAT_CM = 20.0
"""Reverse this far after a second block at one place: room to come back sideways [cm]."""
STALL_TURN_DEG = 8.0
"""A back-off that ends blocked having turned more than this holds
``NavOptions.tread_hold_s`` before the route goes on: a tread stalled (see
`RouteRecovery._stalled`) [deg]."""
STALL_HOLDS = 3
"""Holds for a stalled tread or motor per route that do not count toward
``REPLAN_LIMIT`` (12 s, 24 s, 48 s: longer than a transient stall); later ones count."""


class RouteRecovery:
    """What a `RouteNav` does when its route is blocked (a mixin; see the module docstring)."""

    def _nudged(self, pts: list[tuple[float, float]]) -> list[tuple[float, float]] | None:
        """``pts`` with the series' current nudge applied: a probe of a narrow passage
        from a sidestep onto a line drawn from the block (`nudge.probe_route`), any other
        nudge shifting the route's waypoints near the block (`nudge.nudged_route`)."""
        assert self._nudge is not None
        p = self.map_pose
        nudge = Nudge(self._in_map(self._nudge.block), self._nudge.off, self._nudge.probe)
        if nudge.probe:
            through = NUDGE_REACH_CM if self.map is None else \
                through_distance(self.map, nudge, self.length_cm)
            return probe_route(pts, nudge, self.map, drift_cm=self.drift_cm, at=(p.x, p.y),
                               through_cm=through, tol_cm=self.o.waypoint_tol_cm)
        return nudged_route(pts, nudge, self.map, drift_cm=self.drift_cm,
                            sidestep_from=(p.x, p.y) if self._sidestep else None,
                            tol_cm=self.o.waypoint_tol_cm)

    def _here(self) -> Block:
        """Where the rover stands in its own frame (Motor Control's dead reckoning):
        blocks are held there, so a contact that moves the pose belief (and with it the
        map -> own frame origin) does not move them under the rover."""
        q = self.pose
        return (q.x, q.y, q.heading_deg)

    def _in_map(self, block: Block) -> Block:
        """An own-frame ``block`` in the map frame, by the current origin."""
        if self.origin is None:
            return block
        m = compose(self.origin, Pose(*block))
        return (m.x, m.y, m.heading_deg)

    def _nudged_plan(self) -> bool:
        """Plan again on the server's map, the route shifted sideways near the block.

        Called when the obstacles learned from blocks cut every route: the
        block was then most likely the rover's own dead-reckoning error
        making it miss a narrow passage (a gap only ~20 cm wider than the body
        is missed by a heading drift of a few degrees over a few metres), not
        an obstacle the map does not show. The search tries lateral offsets
        of the waypoints near the block point, alternating sides and growing
        by the step (`nudge.nudge_step`: +4, -4, +8, -8 ... [cm]), one per block
        (offsets whose points do not fit are skipped), at most ``MAX_NUDGES``
        per route and bounded by ``REPLAN_LIMIT`` blocks.
        """
        if self.map is None or self._last_block is None:
            return False
        if self._anchor is None:  # the first block of the series: later ones come from nudges
            self._anchor = self._last_block
        self.work_map = self.map
        if self._nudges == 0:  # a new series: first toward the side that helped last
            self._nudge_first = 1.0 if self._nudge_off >= 0 else -1.0
        step = nudge_step(self.o.nudge_step_cm, self.drift_cm)
        if self._sidestep and self._mouth and self._probe_step is not None:
            step = self._probe_step
        while self._nudges < MAX_NUDGES:
            off = series_offset(self._nudges, step, self._nudge_first)
            self._nudges += 1
            self._nudge = Nudge(self._anchor, off, self._sidestep and self._mouth)
            self._nudge_off = off
            if self._plan():
                self.counters["nudges"] += 1
                return True
        self._nudge = None
        return False

    def _count_block(self) -> None:
        """Count a block toward ``REPLAN_LIMIT``, afresh when the route made progress.

        Why: a rover with a few degrees of heading doubt scrapes the side walls of a
        long passage every metre or so; each scrape is a block, but one that comes
        after the route got nearer its goal is not the same place tried again. What
        the limit bounds is trying one place: the count starts again once the route's
        remaining length is ``PROBE_PROGRESS_CM`` under what it was at the block that
        last started it. Still bounded: that mark only falls, by that much each time.
        """
        left = self.follower.remaining_cm(self.map_pose) if self.follower is not None \
            else math.inf
        if left < self._progress_mark - PROBE_PROGRESS_CM:
            self.replans = 0
            self._progress_mark = left
        self.replans += 1

    async def _blocked_route(self, why: str) -> None:
        self._count_block()
        if await self.on_blocked():
            return
        if why == "blocked" and self._stall_holds < STALL_HOLDS and self._stalled():
            # the motor, not a wall: neither this block nor the one backed off from is a
            # place tried again, so neither counts; wait the fault out
            hold = self.o.tread_hold_s * 2.0 ** self._stall_holds
            self._stall_holds += 1
            await self._stall_hold(hold, uncount=2)
            return
        if self.replans > REPLAN_LIMIT:
            await self._give_up(f"{why} {self.replans} times")
            return
        assert self.work_map is not None
        p = self.map_pose
        if why == "blocked" and self._backoff_turned():
            # a tread still stalls after the holds above: backing off again only spins
            # the rover where it stands; hold, counted
            await self._stall_hold(self.o.tread_hold_s, uncount=0)
            return
        start = self._backoff_start()
        if why == "blocked" and start is not None and \
                math.dist((p.x, p.y), (start.x, start.y)) < 1.0:
            # a back-off that did not move (beside a mapped wall, or after the stall
            # holds): wedged behind; reversing again cannot help
            self._replan = True
            await self.after_motion(False, 0.0)
            return
        ahead = self.radius_cm + 8.0
        h = math.radians(p.heading_deg)
        back = self.o.backoff_cm
        here = self._here()
        moved = why == "blocked" and self.contact_update()
        passage = why == "blocked" and (self._in_passage() or self._nudging_here())
        mouth = passage and self._at_mouth()
        if passage and (not moved or (mouth and self._anchor is not None)):
            # a passage met with the pose unchanged, or its mouth met again after a
            # contact fix: drift, nothing to learn (an obstacle would close the passage);
            # probe sideways (at a mouth, round the place of the series' first block)
            self._last_block, self._mouth = here, mouth
            self._probe = True
        elif moved:
            # a mapped wall stopped it: the pose is corrected, nothing to learn; at a
            # passage's mouth the corrected route is tried first, and a probe series round
            # this place follows if the mouth is missed again
            if mouth:
                self._last_block = self._anchor = here
        elif why == "blocked":
            # a second block near the first: something the map does not show is there
            # (one block alone may be a restarted motor cutting its command short)
            last, self._last_block = self._last_block, here
            if last is not None and math.dist(last[:2], here[:2]) <= 30.0:
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

    def _stalled(self) -> bool:
        """The last motion, a back-off, ended blocked for the rover's own treads, not for
        a wall: it reported a tread silent (`reported_in`), turned more than
        ``STALL_TURN_DEG`` (`_backoff_turned`), or did not move with no mapped wall
        within the body's radius plus the drift (`_wall_within_drift`).

        Why: a back-off reverses over the ground the rover just came through, so what
        stops it there is seldom a wall. A stalled motor (one tread or both) and stuck
        encoders stop it the same way: one tread silent while the other counts, or
        nothing counting at all. Backing off again spins the rover on its stalled tread
        (tens of degrees in a few blocks, while the belief follows only half of it) and
        uses up ``REPLAN_LIMIT`` within the fault's seconds; holding costs only time.
        Beside a mapped wall a back-off that did not move is the rear against it
        (wedged), not a stall.
        """
        start = self._backoff_start()
        if start is None:
            return False
        report = self.reported_in(self.last_motion)
        if report is not None and not report.counts_short:
            return True
        if self._backoff_turned():
            return True
        p = self.map_pose
        return math.dist((p.x, p.y), (start.x, start.y)) < 1.0 and not self._wall_within_drift()

    async def _stall_hold(self, hold_s: float, *, uncount: int) -> None:
        """Hold still ``hold_s`` for a stalled tread or motor, then replan from the pose
        at rest; ``uncount`` blocks are taken back from the count toward
        ``REPLAN_LIMIT`` (the back-off's and the one it backed off from).

        The first ``STALL_HOLDS`` holds of a route hold ``tread_hold_s`` doubled each
        time (a transient stall lasts up to 20 s: 12 s, then 24 s, then 48 s outlast
        it) and are not counted; after them a stall is what it was before them: a
        counted block (a back-off that turned holds ``tread_hold_s``; one that did not
        move replans at once), so a motor stalled for good still ends the route.
        """
        self.replans = max(0, self.replans - uncount)
        self.counters["stall_holds"] += 1
        self._replan = True
        await self.hold_still(trio.current_time() + hold_s,
                              f"a tread stalls; holding {hold_s:.0f} s")

    def _backoff_turned(self) -> bool:
        """The last motion, a reverse (a back-off), ended blocked having turned the rover
        more than ``STALL_TURN_DEG``: one tread drives, the other does not. Backing away
        from a wall is free ground, so a turn there is no wall's doing."""
        start = self._backoff_start()
        if start is None:
            return False
        turned = abs(angle_diff_deg(self.map_pose.heading_deg, start.heading_deg))
        return turned > STALL_TURN_DEG

    def _in_passage(self) -> bool:
        """The last forward move was blocked in a narrow passage (`nudge.in_passage`)."""
        m = self.last_motion
        if m is None or m.kind != "move" or m.amount <= 0 or self.map is None:
            return False
        return in_passage(self.map, self.map_pose, 0.5 * self.length_cm)

    def _at_mouth(self) -> bool:
        """The last forward move was blocked at a narrow passage's mouth, its centre not
        yet in the passage (`nudge.at_mouth`)."""
        m = self.last_motion
        if m is None or m.kind != "move" or m.amount <= 0 or self.map is None:
            return False
        return at_mouth(self.map, self.map_pose, 0.5 * self.length_cm)

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

    def check_sign(self) -> float:
        """The tread check's direction (`tread_faults.TreadFaults.check_treads`): in
        reverse when the nearest occupied cell of the map within the body's radius plus
        the drift and the check's length lies ahead, else forward. A turn that reported a
        silent tread may have been jammed by that wall; a check into it would end
        blocked with the treads well and hold for nothing."""
        if self.map is None:
            return 1.0
        reach = self.radius_cm + self.drift_cm + TREAD_CHECK_CM
        near = occupied_near(self.map, self.map_pose, reach)
        if near is None:
            return 1.0
        px, py, fwd, _ = near
        return -1.0 if fwd[int(np.argmin(np.hypot(px, py)))] > 0.0 else 1.0

    def _nudging_here(self) -> bool:
        """A nudge series is on and this block is near its anchor (`nudge.near_block`):
        the block is the search's next step, not an obstacle to learn."""
        if self._nudge is None or self._anchor is None:
            return False
        q = self.pose
        return near_block(self._anchor, q.x, q.y)

    def _probe_plan(self) -> bool:
        """Plan after a block in a narrow passage: the route shifted sideways at once.

        Dead reckoning cannot tell which wall the rover scraped (its heading
        error is invisible to it), so it tries the nudge series (`_nudged_plan`)
        without first learning an obstacle, which in a passage would only close
        it. Once a probe made progress (the next block is ``PROBE_PROGRESS_CM``
        on, `nudge.progress`), a new series starts on the side that helped.
        """
        q = self.pose
        if self._anchor is None or progress(self._anchor, q.x, q.y) > PROBE_PROGRESS_CM:
            self._anchor, self._nudge, self._nudges = self._last_block, None, 0
        if self._nudges == 0 and self.map is not None and self._mouth:  # step by the play
            s = self.spread
            self._probe_step = probe_step(
                self.map, self.map_pose, self.length_cm, self.width_cm,
                heading_doubt_deg=0.0 if s is None else s.heading95_deg,
                floor_cm=self.o.nudge_step_cm)
        self._sidestep = True
        try:
            return self._nudged_plan()
        finally:
            self._sidestep = False
