"""The state of a route's sideways search: the series of nudges and probes round a block.

`NudgeSeries` keeps where the series started (its anchor, in the rover's own
frame: `here`), which offset is being driven and how many were tried, and turns
the route's waypoints into the nudged or probing route (`nudged`). The geometry
is the pure functions of `nudge`; when a series starts and what it is for is
`recovery` and [navigation.md](../../../docs/navigation.md) "Blocked".
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from actors.firmware.nav.nudge import (
    MAX_NUDGES,
    NUDGE_REACH_CM,
    Block,
    Nudge,
    near_block,
    nudge_step,
    nudged_route,
    probe_route,
    probe_step,
    progress,
    series_offset,
    through_distance,
)
from actors.firmware.nav.place import SAME_PLACE_CM
from server.protocol.pose import Pose, compose

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["NudgeSeries"]

Points = list[tuple[float, float]]


class NudgeSeries:
    """One route's sideways search (see the module docstring).

    Args:
        nav: the navigation actor whose pose, origin, map and doubt the probes are
            drawn from.
    """

    def __init__(self, nav: RouteNav) -> None:
        self.nav = nav
        self.last_block: Block | None = None
        """The last block that started or fed the series (own frame: `here`)."""
        self.nudge: Nudge | None = None
        """The offset of the series being driven."""
        self.anchor: Block | None = None
        """The block the series' offsets are drawn from (own frame)."""
        self.tried = 0
        """Offsets tried in this series (at most ``MAX_NUDGES``)."""
        self.mouth = False
        """The probe series is at a passage's mouth (`nudge.at_mouth`)."""
        self._off = 0.0  # the last sideways offset tried [cm], signed (left +)
        self._first = 1.0  # the side a series tries first
        self._sidestep = False  # the nudge being planned starts with a sidestep
        self._probe_step: float | None = None  # the probe series' step (`nudge.probe_step`)

    def new_route(self) -> None:
        """A new route: no series is on (the side that helped last is kept)."""
        self.last_block, self.nudge, self.tried, self.anchor = None, None, 0, None
        self._off, self.mouth = 0.0, False

    def here(self) -> Block:
        """Where the rover stands in its own frame (Motor Control's dead reckoning):
        blocks are held there, so a contact that moves the pose belief (and with it the
        map -> own frame origin) does not move them under the rover."""
        q = self.nav.pose
        return (q.x, q.y, q.heading_deg)

    def in_map(self, block: Block) -> Block:
        """An own-frame ``block`` in the map frame, by the current origin."""
        origin = self.nav.origin
        if origin is None:
            return block
        m = compose(origin, Pose(*block))
        return (m.x, m.y, m.heading_deg)

    def nudged(self, pts: Points) -> Points | None:
        """``pts`` with the series' current nudge applied: a probe of a narrow passage
        from a sidestep onto a line drawn from the block (`nudge.probe_route`), any other
        nudge shifting the route's waypoints near the block (`nudge.nudged_route`); the
        route unchanged when no nudge is on, or the rover is past the tight spot."""
        nav = self.nav
        q = nav.pose
        if self.anchor is not None and \
                math.dist(self.anchor[:2], (q.x, q.y)) > 2.0 * NUDGE_REACH_CM:
            self.nudge, self.anchor, self.tried = None, None, 0  # past the tight spot
        if self.nudge is None:
            return pts
        p = nav.map_pose
        nudge = Nudge(self.in_map(self.nudge.block), self.nudge.off, self.nudge.probe)
        if nudge.probe:
            through = NUDGE_REACH_CM if nav.map is None else \
                through_distance(nav.map, nudge, nav.length_cm)
            return probe_route(pts, nudge, nav.map, drift_cm=nav.drift_cm, at=(p.x, p.y),
                               through_cm=through, tol_cm=nav.o.waypoint_tol_cm)
        return nudged_route(pts, nudge, nav.map, drift_cm=nav.drift_cm,
                            sidestep_from=(p.x, p.y) if self._sidestep else None,
                            tol_cm=nav.o.waypoint_tol_cm)

    def plan(self, plan: Callable[[], bool]) -> bool:
        """Plan again on the server's map (``plan``), the route shifted sideways near the
        block; True when an offset gave a route.

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
        nav = self.nav
        if nav.map is None or self.last_block is None:
            return False
        if self.anchor is None:  # the first block of the series: later ones come from nudges
            self.anchor = self.last_block
        nav.work_map = nav.map
        if self.tried == 0:  # a new series: first toward the side that helped last
            self._first = 1.0 if self._off >= 0 else -1.0
        step = nudge_step(nav.o.nudge_step_cm, nav.drift_cm)
        if self._sidestep and self.mouth and self._probe_step is not None:
            step = self._probe_step
        while self.tried < MAX_NUDGES:
            off = series_offset(self.tried, step, self._first)
            self.tried += 1
            self.nudge = Nudge(self.anchor, off, self._sidestep and self.mouth)
            self._off = off
            if plan():
                nav.counters["nudges"] += 1
                return True
        self.nudge = None
        return False

    def probe(self, plan: Callable[[], bool]) -> bool:
        """Plan after a block in a narrow passage: the route shifted sideways at once.

        Dead reckoning cannot tell which wall the rover scraped (its heading
        error is invisible to it), so it tries the nudge series (`plan`)
        without first learning an obstacle, which in a passage would only close
        it. Once a probe made progress (the next block is ``SAME_PLACE_CM`` on,
        `nudge.progress`: another place), a new series starts on the side that helped.
        """
        nav = self.nav
        q = nav.pose
        if self.anchor is None or progress(self.anchor, q.x, q.y) > SAME_PLACE_CM:
            self.anchor, self.nudge, self.tried = self.last_block, None, 0
        if self.tried == 0 and nav.map is not None and self.mouth:  # step by the play
            s = nav.spread
            self._probe_step = probe_step(
                nav.map, nav.map_pose, nav.length_cm, nav.width_cm,
                heading_doubt_deg=0.0 if s is None else s.heading95_deg,
                floor_cm=nav.o.nudge_step_cm)
        self._sidestep = True
        try:
            return self.plan(plan)
        finally:
            self._sidestep = False

    def nudging_here(self) -> bool:
        """A nudge series is on and this block is near its anchor (`nudge.near_block`):
        the block is the search's next step, not an obstacle to learn."""
        if self.nudge is None or self.anchor is None:
            return False
        q = self.nav.pose
        return near_block(self.anchor, q.x, q.y)

