"""Recovery behaviours of a route that is blocked, tried in order.

Nav2's split: each behaviour is a small class with one entry point, `decide`,
which gets a narrow view of the block (`BlockView`) and returns an action (or
None: not this behaviour's case); the navigation actor
(`route_nav.RouteNav`) carries the action out. `RECOVERIES` is the order:

1. `WaitOutStall`: a back-off stopped by the rover's own treads holds and is not
   counted (``STALL_HOLDS`` times per route);
2. `GiveUp`: more than ``REPLAN_LIMIT`` blocks at one place end the route, with
   the reason;
3. `ReplanWedged`: a back-off that did not move replans from where it stands;
4. `NudgeSideways`: a narrow passage met with the pose unchanged (or its mouth met
   again) starts the sideways probes (`nudge_series`);
5. `Relocalise`: a contact that moved the pose belief replans from the corrected
   pose;
6. `BackOff`: back off and replan, learning an obstacle at a second block near
   the first.

The view's answers are read lazily and each once, in the order the behaviours
ask: the contact update (`BlockView.contact_moved`) weighs the pose belief, so
what is asked after it sees the corrected pose. The doubt the behaviours size
themselves by (`drift_cm`) is the pose belief's 95 % radius.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from actors.firmware.nav.nudge import Block, at_mouth, in_passage
from actors.firmware.nav.place import SAME_PLACE_CM
from server.protocol.pose import Pose

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["BlockView", "Hold", "GiveUpRoute", "Replan", "BackOffAndReplan", "Action",
           "WaitOutStall", "GiveUp", "ReplanWedged", "NudgeSideways",
           "Relocalise", "BackOff", "RECOVERIES", "REPLAN_LIMIT", "STALL_HOLDS"]

# The bounds of the recovery behaviours: how long a route may try before it is given up,
# and how a back-off reads a stalled tread. The geometry of the sideways search is in
# `nudge`.
REPLAN_LIMIT = 10
"""Blocks without progress before a route is given up: a block that comes after the
route got ``place.SAME_PLACE_CM`` nearer its goal than at the last block counted afresh
(`route_nav.RouteNav.count_block`)."""
STALL_HOLDS = 3
"""Holds for a stalled tread or motor per route that do not count toward
``REPLAN_LIMIT`` (12 s, 24 s, 48 s: longer than a transient stall); later ones count."""


# ---------------------------------------------------------------------- actions
@dataclass(frozen=True, slots=True)
class Hold:
    """Hold still ``seconds`` for a stalled tread or motor, then replan; ``uncount``
    blocks are taken back from the count toward ``REPLAN_LIMIT``. Each counts among the
    route's ``STALL_HOLDS`` holds."""

    seconds: float
    uncount: int


@dataclass(frozen=True, slots=True)
class GiveUpRoute:
    """Give the route up, saying ``reason``."""

    reason: str


@dataclass(frozen=True, slots=True)
class Replan:
    """Replan from where the rover stands, without moving."""


@dataclass(frozen=True, slots=True)
class BackOffAndReplan:
    """Reverse ``cm`` [cm] and replan; what the block teaches goes with it."""

    cm: float
    probe: bool = False
    """Probe sideways after the back-off (a narrow passage)."""
    mouth: bool = False
    """The block was at a passage's mouth."""
    anchor: bool = False
    """The block anchors a probe series (a contact at a mouth)."""
    mark: bool = False
    """The block is remembered as the last one (a block nothing explained)."""
    obstacle: tuple[float, float, float] | None = None
    """(x, y, radius) [cm] of an obstacle to add to the working map."""


Action = Hold | GiveUpRoute | Replan | BackOffAndReplan


# ---------------------------------------------------------------------- the view
class BlockView:
    """What the recovery behaviours may know of a block: each answer read once, when
    first asked (see the module docstring).

    Args:
        nav: the navigation actor whose route was blocked.
        why: ``blocked`` (the motor stopped) or ``no progress`` (the route's step budget).
    """

    def __init__(self, nav: RouteNav, why: str) -> None:
        self._nav = nav
        self.why = why
        """``blocked`` or ``no progress``."""
        self.blocked = why == "blocked"
        """The motor stopped the last motion."""
        self.replans = nav.replans
        """Blocks counted toward ``REPLAN_LIMIT`` on this route, this one included."""
        self.stall_holds = nav.stall_holds
        """Uncounted stall holds on this route so far."""
        self.tread_hold_s = nav.o.tread_hold_s
        """The hold after a tread report [s] (`NavOptions.tread_hold_s`)."""
        self.backoff_cm = nav.o.backoff_cm
        """The back-off after a block [cm] (`NavOptions.backoff_cm`)."""
        self.here: Block = nav.nudges.here()
        """Where the rover stands, own frame."""
        self.last_block = nav.nudges.last_block
        """The last block remembered (own frame), if any."""
        self.anchored = nav.nudges.anchor is not None
        """A probe series is anchored."""
        self.length_cm = nav.length_cm
        """The body's length [cm]."""
        self.obstacle_cm = 0.5 * nav.width_cm
        """Radius of an obstacle met head-on [cm]: the contact lies anywhere across the
        body's front, so the obstacle is as wide as it."""
        p = nav.map_pose
        ahead = nav.radius_cm + self.obstacle_cm  # just beyond the turning circle
        h = math.radians(p.heading_deg)
        self.ahead = (p.x + ahead * math.cos(h), p.y + ahead * math.sin(h))
        """Where an obstacle met head-on would be (map frame [cm])."""
        self._memo: dict[str, bool] = {}

    def _once(self, key: str, read: Callable[[], bool]) -> bool:
        if key not in self._memo:
            self._memo[key] = bool(read())
        return self._memo[key]

    def _backoff_start(self) -> Pose | None:
        m, start = self._nav.last_motion, self._nav.motion_from
        if m is None or m.kind != "move" or m.amount >= 0:
            return None
        return start

    def backoff_stuck(self) -> bool:
        """The last motion, a back-off, did not move (under 1 cm)."""
        start = self._backoff_start()
        p = self._nav.map_pose
        return start is not None and math.dist((p.x, p.y), (start.x, start.y)) < 1.0

    def stalled(self) -> bool:
        """The last motion, a back-off, ended blocked for the rover's own treads, not for
        a wall: it reported a tread silent, or did not move with no mapped wall within
        the body's radius plus the drift.

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
        report = self._nav.treads.reported_in(self._nav.last_motion)
        if report is not None and not report.counts_short:
            return True
        p = self._nav.map_pose
        return math.dist((p.x, p.y), (start.x, start.y)) < 1.0 and \
            not self._nav.wall_within_drift()

    def _forward(self) -> bool:
        m = self._nav.last_motion
        return m is not None and m.kind == "move" and m.amount > 0 and \
            self._nav.map is not None

    def contact_moved(self) -> bool:
        """A straight move stopped by a mapped wall moved the pose belief (the contact
        update is made here, once)."""
        return self._once("moved", lambda: self.blocked and
                          self._nav.localiser.contact_update())

    def in_passage(self) -> bool:
        """Blocked moving forward in a narrow passage (`nudge.in_passage`), or near the
        anchor of a nudge series on (`NudgeSeries.nudging_here`)."""
        nav = self._nav
        return self._once("passage", lambda: self.blocked and (
            (self._forward() and in_passage(nav.map, nav.map_pose, 0.5 * nav.length_cm))
            or nav.nudges.nudging_here()))

    def at_mouth(self) -> bool:
        """In a passage (`in_passage`) and at its mouth, the centre not yet in it
        (`nudge.at_mouth`)."""
        nav = self._nav
        return self._once("mouth", lambda: self.in_passage() and self._forward() and
                          at_mouth(nav.map, nav.map_pose, 0.5 * nav.length_cm))


# ---------------------------------------------------------------------- behaviours
class WaitOutStall:
    """A back-off stopped by the rover's own treads: the motor, not a wall. Neither this
    block nor the one backed off from is a place tried again, so neither counts; hold
    ``tread_hold_s`` doubled for each earlier such hold on the route."""

    def decide(self, v: BlockView) -> Action | None:
        """Hold when the back-off stalled, at most ``STALL_HOLDS`` times a route."""
        if v.blocked and v.stall_holds < STALL_HOLDS and v.stalled():
            return Hold(v.tread_hold_s * 2.0 ** v.stall_holds, uncount=2)
        return None


class GiveUp:
    """More than ``REPLAN_LIMIT`` blocks at one place: the route is given up."""

    def decide(self, v: BlockView) -> Action | None:
        """Give up, saying why and how often."""
        if v.replans > REPLAN_LIMIT:
            return GiveUpRoute(f"{v.why} {v.replans} times")
        return None


class ReplanWedged:
    """A back-off that did not move (beside a mapped wall, or after the stall holds):
    wedged behind; reversing again cannot help."""

    def decide(self, v: BlockView) -> Action | None:
        """Replan from where the rover stands."""
        if v.blocked and v.backoff_stuck():
            return Replan()
        return None


class NudgeSideways:
    """A passage met with the pose unchanged, or its mouth met again after a contact fix:
    drift, nothing to learn (an obstacle would close the passage); probe sideways (at a
    mouth, round the place of the series' first block)."""

    def decide(self, v: BlockView) -> Action | None:
        """Back off and probe."""
        moved = v.contact_moved()
        if v.in_passage() and (not moved or (v.at_mouth() and v.anchored)):
            return BackOffAndReplan(v.backoff_cm, probe=True, mouth=v.at_mouth())
        return None


class Relocalise:
    """A mapped wall stopped the rover: the pose is corrected, nothing to learn; at a
    passage's mouth the corrected route is tried first, and a probe series round this
    place follows if the mouth is missed again."""

    def decide(self, v: BlockView) -> Action | None:
        """Back off and replan from the corrected pose."""
        if v.contact_moved():
            return BackOffAndReplan(v.backoff_cm, anchor=v.at_mouth())
        return None


class BackOff:
    """Anything else: back off and replan. A second block near the first means something
    the map does not show is there (one block alone may be a restarted motor cutting its
    command short): an obstacle as wide as the body's front is learned just beyond its
    turning circle (`BlockView.ahead`), and the back-off is a body length: the body
    clears the place it met by its own length, room to turn and come back on another
    line."""

    def decide(self, v: BlockView) -> Action | None:
        """Back off, learning an obstacle at a repeated block."""
        if not v.blocked:
            return BackOffAndReplan(v.backoff_cm)
        last = v.last_block
        if last is not None and math.dist(last[:2], v.here[:2]) <= SAME_PLACE_CM:
            return BackOffAndReplan(v.length_cm, mark=True,
                                    obstacle=(*v.ahead, v.obstacle_cm))
        return BackOffAndReplan(v.backoff_cm, mark=True)


RECOVERIES = (WaitOutStall(), GiveUp(), ReplanWedged(), NudgeSideways(), Relocalise(),
              BackOff())
"""The recovery behaviours in the order they are tried."""
