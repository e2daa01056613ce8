"""The mapper's exploration: where to go next, and the route there.

Choosing where to go
    `viewpoint.viewpoints` on the latest NAV_MAP_UPDATE: poses the rover may stand on
    from which the LIDAR sees the frontier steeply enough, best gain (unknown area
    revealed) per unit of travel first; none worth a trip ends exploring.
    `route.plan_route` for the path, trying tiers of clearance from the turning
    radius plus a margin down to half the body width (a 30 cm corridor maps 25 cm
    wide on a 5 cm grid); reachability uses the narrowest tier. A viewpoint that
    cannot be planned to, which blocks the rover twice, which takes more ADP steps
    than its route deserves, or which is chosen again after being reached, is
    blacklisted (by its point [cm], which survives map growth). Face cells seen
    from where the rover stands at ``SIGHTINGS`` decisions and still unknown leave
    the face for good: looking does not reveal them.

Obstacles ahead
    Before each straight move, `clearance.obstacle_ahead` looks ``move +
    stop_cm`` ahead on the map for an occupied cell the body would sweep (its
    centre ahead of the nose and within half the body's width of the line
    driven: the planner's narrowest tier, measured to where a mapped face lies
    on average). The move is shortened to stop ``stop_cm`` (20 cm: inside the
    seed's 15-30 cm) before the obstacle, and when that leaves nothing to drive
    the rover turns away from it and chooses again; after ``OBSTACLE_TURNS``
    such turns toward one target without a move between, the target is
    blacklisted (the map changed under the route and keeps refusing it).

Blocked motions
    A motion that ended blocked backs off (or turns, when a back-off was blocked too)
    and counts toward the target's blacklisting; one blocked in the open (nothing
    mapped in its way: both encoders stuck, most likely) holds for odometry instead
    (`sensor_watch`), exploring or going home.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from actors.firmware.nav.place import SAME_PLACE_CM
from actors.firmware.nav.route import Motion, PathFollower, plan_route, plan_tiers, route_points
from actors.firmware.planning.clearance import obstacle_ahead
from actors.firmware.planning.viewpoint import (
    FaceField,
    Viewpoint,
    face_field,
    seen_face,
    viewpoints,
)
from server.protocol.grid_map import UNKNOWN

if TYPE_CHECKING:
    from actors.firmware.nav.mapper import MappingNav

__all__ = ["Exploration", "ExplorationState", "futile", "least_gain", "min_gain",
           "MIN_FACE_CELLS", "MAX_INCIDENCE_DEG",
           "RECHOOSE_STEPS", "OBSTACLE_TURNS", "MAX_CHOICES", "KEEP_SHARE",
           "BLACKLIST", "SIGHTINGS", "UNSEEABLE",
           "FUTILE_TRIPS", "MIN_GAIN_CELLS", "MIN_GAIN_SHARE"]

# Counts, bounds and shares of frontier exploration and of the futile-trip rule: how the
# algorithm chooses and when it stops looking, fixed here beside it; the distances a rover
# keeps are `MappingOptions`.
MIN_FACE_CELLS = 2
"""A viewpoint must see at least this many face cells [cells]: one alone is a hole a cell
wide, deep from anywhere and seldom revealed (a pocket 20 cm wide shows two)."""
MAX_INCIDENCE_DEG = 70.0
"""Steepest angle between a ray and the frontier's normal that still reveals what lies
behind it [deg]: a ray meeting a surface at 20 deg or less stops clearing 1.5 cells
before it (the occupancy model's grazing margin), and a degree of heading error moves
it a cell at 3 m."""
RECHOOSE_STEPS = 3
"""Re-choose the frontier after this many ADP steps (the map grew meanwhile)."""
OBSTACLE_TURNS = 3
"""Turns away from an obstacle toward one target with no move between them before the
target is blacklisted (the route passes where the rover will not drive)."""
MAX_CHOICES = 8
"""Frontiers tried per decision before waiting for the map to change."""
KEEP_SHARE = 0.5
"""The route to the current target (a viewpoint within ``place.SAME_PLACE_CM`` of it is
that target) is kept while its score is at least this share of the best (a new best
must be clearly better to turn the rover round)."""
BLACKLIST = 256
"""Most blacklisted points kept."""
SIGHTINGS = 3
"""A face cell seen from the rover's pose at this many decisions and still unknown cannot be
revealed by looking (a decision comes every ADP step, a second or two)."""
UNSEEABLE = 2048
"""Most unseeable face cells kept (and most cells counted toward it)."""
FUTILE_TRIPS = 4
"""After this many trips in a row (each until its target was reached or given up) that
revealed fewer than the least gain (`MIN_GAIN_CELLS`, `MIN_GAIN_SHARE`) each on average,
the frontiers left are not worth visiting (pockets behind furniture, noise at edges):
exploration treats them as not useful, and completion may follow."""
MIN_GAIN_CELLS = 30
"""A viewpoint that would reveal less is not worth a trip, and a trip that made fewer
cells known than this was futile [cells]..."""
MIN_GAIN_SHARE = 0.003
"""...or fewer than this share of the cells already known (a big hall's ragged far edges
give a few dozen cells per visit for ever). Counted per visit, not per minute: crossing a
big hall to a far frontier reveals nothing for a while."""


def min_gain(known: int) -> float:
    """The least a trip must make known, and a viewpoint reveal, to count [cells]:
    ``MIN_GAIN_CELLS``, or ``MIN_GAIN_SHARE`` of the ``known`` cells when that is more."""
    return max(MIN_GAIN_CELLS, MIN_GAIN_SHARE * known)


def futile(gains: Sequence[int], known: int) -> bool:
    """Whether the last ``FUTILE_TRIPS`` trips, which made ``gains`` cells known each
    (oldest first), together revealed too little to go on, ``known`` cells being known.

    Judged on their sum (a running window), not on each: one visit just above the
    limit among small ones would start the count over, and mapping would go on for
    trips gaining 21, 7, 4 and 34 cells (limit 32)."""
    if len(gains) < FUTILE_TRIPS:
        return False
    return sum(gains[-FUTILE_TRIPS:]) < min_gain(known) * FUTILE_TRIPS


def least_gain(gains: Sequence[int], known: int) -> float:
    """The least a viewpoint must reveal to be worth a trip [cells]: `min_gain`, and after
    futile trips (`futile`) as much as the futile window together should have shown (what
    an obstacle hid in a big room still counts; each is blacklisted once reached, so
    this ends)."""
    least = min_gain(known)
    return least * FUTILE_TRIPS if futile(gains, known) else least


@dataclass
class ExplorationState:
    """Exploration state of one incarnation."""

    follower: PathFollower | None = None
    target: tuple[float, float] | None = None
    steps: int = 0  # ADP steps toward the current target
    budget: int = 0  # most steps it deserves
    blocks: int = 0  # blocked motions toward the current target
    blacklist: list[tuple[float, float]] = field(default_factory=list)
    reached: list[tuple[float, float]] = field(default_factory=list)  # targets arrived at
    no_frontier: bool = False  # the last decision found nothing useful to explore
    trip_known: int | None = None  # known cells when the current trip began
    gains: list[int] = field(default_factory=list)  # cells each recent trip made known
    turned_away: int = 0  # turns away from an obstacle toward this target, no move between
    turned_target: tuple[float, float] | None = None  # the target they were toward
    sightings: dict[tuple[float, float], int] = field(default_factory=dict)  # face cell
    # [cm] -> decisions it was seen at, still unknown
    unseeable: list[tuple[float, float]] = field(default_factory=list)  # face cells [cm]
    # seen ``SIGHTINGS`` times and not revealed
    view_field: FaceField | None = None  # the face field of...
    view_key: tuple | None = None  # ...this map and unseeable list


class Exploration:
    """Frontier exploration: the mapper's role behaviour (see the module docstring).

    Args:
        nav: the mapper's navigation actor, whose map, pose and state it reads and
            whose motions it commands.
    """

    def __init__(self, nav: MappingNav) -> None:
        self.nav = nav



    async def after_motion(self, blocked: bool, done: float) -> None:
        if blocked and self.nav.state in ("exploring", "homing") and not self.nav.holding and (
                await self.nav.watch.hold_if_blocked_in_the_open(done)):
            return  # odometry in doubt: the hold's end plans again (`sensor_watch`)
        if self.nav.state == "homing":
            if not self.nav.holding:
                await self.nav.homing.after_home_motion(blocked)
            return
        if self.nav.state != "exploring" or self.nav.holding:
            return
        if blocked:
            self.nav.ex.blocks += 1
            if self.nav.ex.blocks >= 2 and self.nav.ex.target is not None:
                self.blacklist(self.nav.ex.target)
            self.nav.ex.follower = None
            last = self.nav.last_motion
            if last is not None and last.kind == "move" and last.amount < 0:
                await self.nav.command(Motion("turn", 90.0))  # cannot back off either: turn
            else:
                await self.nav.command(Motion("move", -self.nav.o.backoff_cm))
            return
        await self.decide()

    async def decide(self) -> None:
        """One ADP decision: keep or choose a frontier, then command one motion."""
        nav = self.nav
        if nav.state != "exploring" or nav.moving or nav.grid is None or nav.holding:
            return
        if not self.nav.can_move:
            self.nav.wait_map = True  # the tick tries again
            return
        ex = self.nav.ex
        pose = self.nav.map_pose
        self.judge_sightings()
        if ex.follower is not None and ex.steps >= ex.budget:
            self.blacklist(ex.target)  # no progress worth the route
            ex.follower = None
        if ex.follower is None or ex.steps % RECHOOSE_STEPS == 0:
            if not self.choose(keep=ex.follower is not None):
                return
        assert ex.follower is not None
        motion = ex.follower.next_motion(pose)
        if motion is None or (ex.target is not None
                              and math.dist((pose.x, pose.y), ex.target) <= self.nav.m.reach_cm):
            if ex.target is not None:
                ex.reached.append(ex.target)
                self._end_trip()
            ex.follower = None
            self.nav.wait_map = True  # look again once the map shows what is seen from here
            return
        if motion.kind == "move":
            motion = self.mind_the_obstacle(motion)
            if motion.kind == "turn":
                ex.follower = None
                if self.turned_away():
                    return
            else:
                ex.turned_away = 0
        ex.steps += 1
        await self.nav.command(motion)

    def turned_away(self) -> bool:
        """Count a turn away from an obstacle; True (target blacklisted, decide again
        at the next tick) after ``OBSTACLE_TURNS`` toward one target without a move.

        Why: a route planned on one map can pass where the obstacle check, on a
        newer one, refuses to drive; the rover would then turn toward the route, be
        refused, turn away and plan the same route again, minutes on end by one wall,
        and turning in place by a wall is where scan matching drifts. A bound."""
        ex = self.nav.ex
        if ex.target is None:
            return False
        if ex.turned_target is not None and math.dist(ex.target, ex.turned_target) <= 40.0:
            ex.turned_away += 1
        else:
            ex.turned_away, ex.turned_target = 1, ex.target
        if ex.turned_away < OBSTACLE_TURNS:
            return False
        ex.turned_away, ex.turned_target = 0, None
        self.blacklist(ex.target)
        self.nav.wait_map = True
        return True

    def mind_the_obstacle(self, motion: Motion) -> Motion:
        """Shorten a move to stop ``stop_cm`` before an obstacle, or turn away from it.

        An obstacle is an occupied cell the body would sweep: its centre ahead of the
        nose and within half the body's width of the line driven. The centre is where
        a mapped face lies on average (the face is somewhere in its cell), so the test
        is the planner's narrowest tier (half the body width from the cells' squares)
        with the cell's half width given back: a 25-30 cm passage, mapped as four free
        cells with the route on one of the middle two, is driven, not refused."""
        assert self.nav.grid is not None
        look = motion.amount + self.nav.m.stop_cm
        ob = obstacle_ahead(self.nav.grid, self.nav.map_pose, look, half_angle_deg=0.0,
                            half_width_cm=0.5 * self.nav.width_cm,
                            beyond_cm=0.5 * self.nav.length_cm)
        if ob is None:
            return motion
        room = ob.forward_cm - self.nav.m.stop_cm
        if room >= 2.0:
            return Motion("move", min(motion.amount, room))
        # turn away: to the side opposite the obstacle's bearing
        return Motion("turn", -90.0 if ob.bearing_deg >= 0 else 90.0)

    def choose(self, *, keep: bool) -> bool:
        """Choose a viewpoint and a route to it; False (and ``no_frontier``) when no
        reachable pose sees enough of the unknown."""
        assert self.nav.grid is not None
        ex = self.nav.ex
        # after futile visits only viewpoints revealing much still count (`least_gain`)
        least = least_gain(ex.gains, self._known())
        views = [v for v in self._viewpoints() if v.gain_cells >= least and not any(
            math.dist(v.point_cm, b) <= SAME_PLACE_CM for b in ex.blacklist)]
        if not views:
            ex.no_frontier = True
            ex.follower = None
            return False
        ex.no_frontier = False
        if keep and ex.target is not None:
            current = [v for v in views if math.dist(v.point_cm, ex.target) <= SAME_PLACE_CM]
            if current and current[0].score >= KEEP_SHARE * views[0].score:
                return True  # the target still sees about as much: keep the route
        for v in views[:MAX_CHOICES]:
            if any(math.dist(v.point_cm, r) <= self.nav.m.reach_cm * 2 for r in ex.reached):
                self.blacklist(v.point_cm)  # reached, and still not seen from there
                continue
            if self._route_to(v.point_cm):
                return True
            self.blacklist(v.point_cm)
        ex.follower = None
        self.nav.wait_map = True
        return False

    def _viewpoints(self) -> list[Viewpoint]:
        """The viewpoints of the current map from the current pose (`viewpoint.viewpoints`),
        with the current target among the candidates; reachability with the narrowest
        tier the rover can drive (a corridor barely wider than the body), the route
        itself tries the roomier tiers first."""
        assert self.nav.grid is not None
        pose = self.nav.map_pose
        radius, margin = self.tiers()[-1]
        also = [self.nav.ex.target] if self.nav.ex.target is not None else []
        return viewpoints(self._field(), (pose.x, pose.y), robot_radius_cm=radius,
                          margin_cm=margin, stand_radius_cm=self.nav.radius_cm,
                          max_incidence_deg=MAX_INCIDENCE_DEG, also_cm=also,
                          min_face_cells=MIN_FACE_CELLS)

    def _field(self) -> FaceField:
        """The current map's `FaceField`, made again only when the map or the unseeable
        cells changed (a decision judges sightings and may choose on the same map)."""
        assert self.nav.grid is not None
        ex = self.nav.ex
        key = (self.nav.grid, len(ex.unseeable), ex.unseeable[-1] if ex.unseeable else None)
        if ex.view_field is None or ex.view_key is None or ex.view_key[0] is not key[0] \
                or ex.view_key[1:] != key[1:]:
            ex.view_field = face_field(self.nav.grid, range_cm=self.nav.m.view_range_cm,
                                       unseeable_cm=ex.unseeable)
            ex.view_key = key
        return ex.view_field

    def judge_sightings(self) -> None:
        """Count, per face cell the rover sees from where it stands (within the view range,
        steeply enough: `viewpoint.seen_face`), the decisions it was seen at; one
        seen at ``SIGHTINGS`` decisions and still unknown cannot be revealed by looking
        (an obstacle's inside behind a gap in its mapped surface, a pocket only grazing
        rays enter), so it leaves the face for good. What no pose sees then ends
        exploration instead of more drives that reveal nothing."""
        ex = self.nav.ex
        assert self.nav.grid is not None
        pose = self.nav.map_pose
        for cell in seen_face(self._field(), (pose.x, pose.y),
                              max_incidence_deg=MAX_INCIDENCE_DEG):
            n = ex.sightings.get(cell, 0) + 1
            if n >= SIGHTINGS:
                ex.unseeable.append(cell)
                ex.sightings.pop(cell, None)
            else:
                ex.sightings[cell] = n
        del ex.unseeable[:-UNSEEABLE]
        while len(ex.sightings) > UNSEEABLE:
            del ex.sightings[next(iter(ex.sightings))]

    def tiers(self) -> tuple[tuple[float, float], ...]:
        """(radius, margin) pairs to plan with, most cautious first [cm]: the tiers of
        hiding and seeking (`route.plan_tiers`); reachability uses the last, half the body
        width alone: on a 5 cm grid a 30 cm corridor whose walls lie on cell edges maps
        25 cm wide, and only that tier still finds the way through it (a scrape on the
        way is a blocked motion, and the route is replanned)."""
        nav = self.nav
        return plan_tiers(nav.radius_cm, nav.width_cm, nav.o.plan_margin_cm,
                          nav.o.narrow_margin_cm)

    def _known(self) -> int:
        assert self.nav.grid is not None
        return int(np.count_nonzero(self.nav.grid.cells != UNKNOWN))

    def _route_to(self, target: tuple[float, float]) -> bool:
        assert self.nav.grid is not None
        pose = self.nav.map_pose
        plan = None
        for radius, margin in self.tiers():
            plan = plan_route(self.nav.grid, (pose.x, pose.y), target, radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                break
        if plan is None:
            return False
        ex = self.nav.ex
        if ex.trip_known is None:  # a trip runs until a target is reached or given up
            ex.trip_known = self._known()
        ex.follower = PathFollower(route_points(plan, (pose.x, pose.y)), None, self.nav.o)
        ex.target = target
        ex.steps = 0
        ex.blocks = 0
        ex.budget = ex.follower.budget(pose)
        return True

    def _end_trip(self) -> None:
        """A target was reached or given up: record what the trip made known.

        Switching to another frontier on the way (the map grew) does not end a trip,
        so a trip's gain is that of a whole visit, not of a few steps."""
        ex = self.nav.ex
        if ex.trip_known is not None and self.nav.grid is not None:
            ex.gains.append(self._known() - ex.trip_known)
            del ex.gains[:-FUTILE_TRIPS]
        ex.trip_known = None

    def blacklist(self, point: tuple[float, float] | None) -> None:
        if point is None:
            return
        if point == self.nav.ex.target:
            self._end_trip()
        bl = self.nav.ex.blacklist
        bl.append(point)
        if len(bl) > BLACKLIST:
            del bl[0]

