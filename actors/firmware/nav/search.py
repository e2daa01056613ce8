"""The seeker's search when the scans at the place saw nothing: rings of scan
points round the place, then a sweep by touch.

Why the ring (`Search.plan`): the seeker stands where dead
reckoning says; after metres of driving that may be tens of cm from the
place, and a hider within IR range of the place may then be beyond what the
scan from it sees. The ring is sized by the seeker's drift estimate
(`NavBase.drift_cm`) so that its scans see everything within IR range of the
place plus that drift.

A destination with ``within`` W (the operator's wider search after a guess
failed) searches rings round (x, y) out to W plus the seeker's drift: the ring
above first, then wider ones (`search_rings`), innermost first. When the rings
saw nothing, the pose itself is in doubt (a heading lost in a turn no tread
report showed), and what is left of ``wide_search_s`` goes
to a sweep by touch (`Search.sweep`): straight legs from wall to wall,
stopping every ``sweep_step_cm`` to scan all round, turning ``SWEEP_TURN_DEG``
where blocked; no map, no pose.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np
import trio

from actors.firmware.nav.route import Motion, passable_at
from server.protocol.grid_map import FREE, GridMap
from server.protocol.pose import angle_diff_deg

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav
    from actors.firmware.nav.seeker import SeekingOptions

__all__ = ["Next", "Search", "ring_outer_cm", "ring_reach_cm", "search_ring", "search_rings",
           "unseen_free", "SEARCH_IR_WAIT_S", "SEARCH_SCAN_DEG"]

# Bounds and fixed geometry of the search. Each bounds the cost of one search (drives and
# scans of about 15 s a point), or is geometry that follows from what the scan from the
# place already covers; none is a property of the rover.
RING_POINTS = 6
"""Points of the search ring round the place, at most (fewer when they see far enough:
`search_ring`)."""
RING_MAX_CM = 60.0
"""Largest radius of the search ring [cm] (with 6 points it covers 115 cm); a ring wider
than the scan's reach would leave holes next to its points (`ring_reach_cm`)."""
WIDE_MAX_RINGS = 6
"""Rings of a wider search, at most (the first included)."""
WIDE_MAX_POINTS = 72
"""Points of a wider search, at most (each costs a drive and a scan of about 15 s)."""
SEARCH_SCAN_DEG = 100.0
"""From a ring point, scan outward from the place +- this [deg]: the inside is covered by
the scan from the place itself."""
SEARCH_IR_WAIT_S = 0.8
"""Longest wait for "in range" at one heading of a search or sweep scan [s]: the IR
decision comes within about 0.1 s (3 samples at 50 Hz); the scans from the place keep
``SeekingOptions.ir_wait_s``."""
SWEEP_TURN_DEG = 137.5
"""Turn between legs of the sweep [deg]: the golden angle, so the legs' headings spread
evenly round the circle, without a random generator."""
SWEEP_MAX_STEPS = 6
"""Steps of one sweep leg, at most (a leg ends earlier at whatever blocks it)."""


def ring_outer_cm(ring_cm: float, reach_cm: float, points: int) -> float:
    """The outer edge of the band a ring of ``points`` scan points of radius ``ring_cm``
    sees all round, each seeing ``reach_cm`` round itself [cm] (the worst direction is
    midway between two points); 0 when neighbouring points are too far apart to meet."""
    half = math.pi / points
    inner = reach_cm ** 2 - (ring_cm * math.sin(half)) ** 2
    if inner <= 0:
        return 0.0
    return ring_cm * math.cos(half) + math.sqrt(inner)


def ring_reach_cm(ring_cm: float, reach_cm: float, points: int) -> float:
    """How far from the centre a ring of ``points`` scan points of radius ``ring_cm`` sees
    everything [cm], with the scan from the centre (`ring_outer_cm`); 0 when the ring has
    holes next to its points or is too wide to meet what the centre sees."""
    return 0.0 if ring_cm > reach_cm else ring_outer_cm(ring_cm, reach_cm, points)


def search_ring(need_cm: float, reach_cm: float, max_points: int,
                max_cm: float) -> tuple[int, float] | None:
    """The cheapest ring that, with the place itself, sees everything within ``need_cm``
    of the place: the fewest points (3 .. ``max_points``), then the smallest radius
    (20 cm and up in 5 cm steps, at most ``max_cm``) [cm]. None when the scan from the
    place alone sees that far; the widest ring (``max_points``, ``max_cm``) when none
    does."""
    if need_cm <= reach_cm:
        return None
    for n in range(3, max_points + 1):
        r = 20.0  # a smaller ring sees hardly more than the place itself, at the same cost
        while r <= max_cm:
            if ring_reach_cm(r, reach_cm, n) >= need_cm:
                return n, r
            r += 5.0
    return max_points, max_cm


def search_rings(need_cm: float, reach_cm: float, max_points: int, max_cm: float,
                 spacing_cm: float, max_rings: int) -> list[tuple[int, float]]:
    """Rings (points, radius [cm]) that, with the place itself, see everything within
    ``need_cm`` of the place, innermost first: `search_ring`'s ring, then rings whose
    neighbouring points are ``spacing_cm`` apart, each laid 10 cm inside what the rings
    before it see (its points scan outward, so it sees from about its own radius out),
    at most ``max_rings``. Empty when the place alone sees that far."""
    first = search_ring(need_cm, reach_cm, max_points, max_cm)
    if first is None:
        return []
    rings = [first]
    covered = ring_reach_cm(first[1], reach_cm, first[0])
    while covered < need_cm and len(rings) < max_rings:
        r = covered - 10.0
        n = max(3, math.ceil(2.0 * math.pi * r / spacing_cm))
        outer = ring_outer_cm(r, reach_cm, n)
        if outer <= covered:  # spacing too wide for the reach: no ring adds anything
            break
        rings.append((n, r))
        covered = outer
    return rings


class Next(Enum):
    """What the seeker does after `Search.next_point`."""

    ROUTE = "route"
    """A route to a ring point is under way (`on_arrived` then looks outward)."""
    SWEEP = "sweep"
    """The rings are over and a wider search has time left: a step of the sweep by touch
    (`Search.sweep`)."""
    OVER = "over"
    """The search is over without the hider: ``not_found`` (`Search.over_reason`)."""


def unseen_free(grid: GridMap, place: tuple[float, float], q: tuple[float, float],
                reach_cm: float, seen_cm: float, need_cm: float) -> bool:
    """Whether a free cell of ``grid`` lies within ``reach_cm`` of ``q``, farther than
    ``seen_cm`` from ``place`` and within ``need_cm`` of it [cm]."""
    px, py = place
    reach = reach_cm
    res = grid.resolution_cm
    r0, c0 = grid.world_to_cell(q[0] - reach, q[1] - reach)
    r1, c1 = grid.world_to_cell(q[0] + reach, q[1] + reach)
    ny, nx = grid.shape
    r0, c0, r1, c1 = max(0, r0), max(0, c0), min(ny, r1 + 1), min(nx, c1 + 1)
    if r0 >= r1 or c0 >= c1:
        return False
    cells = np.asarray(grid.cells)[r0:r1, c0:c1]
    ox, oy = grid.origin_cm
    ys = oy + (np.arange(r0, r1) + 0.5) * res
    xs = ox + (np.arange(c0, c1) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)
    dp = np.hypot(X - px, Y - py)
    mask = (cells == FREE) & (np.hypot(X - q[0], Y - q[1]) <= reach) & \
        (dp > seen_cm) & (dp <= need_cm)
    return bool(mask.any())


class Search:
    """Rings round the place and the sweep by touch: a part the seeker's role behaviour
    (`seeker.Seek`) owns and calls. It plans the rings (`plan`), drives to their points
    (`next_point`, which says what comes next) and steps the sweep (`sweep`,
    `motion_ended`); the looking, and the answer, stay the seeker's.

    Args:
        nav: the navigation actor it drives (its public names: ``map``, ``map_pose``,
            ``drift_cm``, ``memory``, ``goto_as``, ``set_state``, ``command``).
        seeking: the seeker's quantities (``range_cm``, ``wide_search_s``,
            ``sweep_step_cm``).
        reach_cm: how far from the seeker's centre an all-round scan sees a hider's
            centre [cm] (`seeker.SeekingOptions.reach_cm`); also the spacing of a wider
            search's ring points.
    """

    def __init__(self, nav: RouteNav, seeking: SeekingOptions, reach_cm: float) -> None:
        self.nav = nav
        self.s = seeking
        self.reach_cm = reach_cm
        self.points: list[tuple[float, float]] = []
        """Ring points still to look from (map frame [cm])."""
        self.ring_cm = 0.0
        """Radius of the (outermost) search ring planned [cm]."""
        self.until = math.inf
        """When the search in progress gives up [s] (a wider search only)."""
        self.sweep_turned = False  # the sweep's step in progress has turned, and drives
        self.sweep_blocked = False  # the sweep's last step was blocked: the next leg turns
        self.sweep_steps = 0  # steps of the sweep's leg in progress
        self.leg_heading = 0.0  # the sweep's leg heading (map frame, as believed) [deg]

    def plan(self, place: tuple[float, float]) -> bool:
        """After the scan from ``place`` saw nothing: choose the ring(s) to look from;
        True when there are points to look from (`points`).

        A guess within IR range has the hider's centre within ``range_cm`` of
        it (a destination's ``within``, when given, replaces that); the seeker's
        own dead reckoning may be ``drift_cm`` off, so what must be seen is
        everything within ``range_cm + drift_cm`` of the place as the seeker
        believes it. The scan from the place sees ``reach_cm``; beyond that,
        points on a ring (`search_ring`) do, and with ``within`` wider rings
        after it (`search_rings`).
        Points that are not passable are pulled in toward the place; points
        from which no free cell beyond what was seen before is within reach
        (walls, the map's edge) are left out (`unseen_free`).
        """
        s = self.s
        grid = self.nav.map
        if grid is None:
            return False
        drift = self.nav.drift_cm
        within = self.nav.memory.within
        self.until = math.inf
        if within is not None:
            self.until = trio.current_time() + s.wide_search_s
        need = (s.range_cm if within is None else within) + drift
        rings = search_rings(need, self.reach_cm, RING_POINTS, RING_MAX_CM,
                             self.reach_cm, 1 if within is None else WIDE_MAX_RINGS)
        if not rings:
            return False
        px, py = place
        p = self.nav.map_pose
        if math.dist((p.x, p.y), place) > 2.0 * self.nav.o.goal_tol_cm:
            first = math.atan2(p.y - py, p.x - px)  # nearest the seeker first
        else:
            first = math.radians(p.heading_deg)  # on the place: the one it faces
        seen = max(0.0, self.reach_cm - drift)
        points: list[tuple[float, float]] = []
        for i, (n, ring) in enumerate(rings):
            # a point that does not fit is pulled in: the first ring toward the place,
            # wider rings by less, or they would repeat the ring inside them
            pulls = (ring, 0.75 * ring, 0.5 * ring) if i == 0 else (ring, ring - 20.0, ring - 40.0)
            for k in range(n):
                a = first + 2.0 * math.pi * k / n
                for r in pulls:
                    q = (px + r * math.cos(a), py + r * math.sin(a))
                    # it turns there
                    if passable_at(grid, q[0], q[1], self.nav.radius_cm, 0.0):
                        if unseen_free(grid, place, q, self.reach_cm, seen, need):
                            points.append(q)
                        break
            if points:  # the next ring starts beside where this one ends
                first = math.atan2(points[-1][1] - py, points[-1][0] - px)
            seen = max(0.0, ring_outer_cm(ring, self.reach_cm, n) - drift)
        points = points[:WIDE_MAX_POINTS]
        if not points:
            return False
        self.ring_cm = rings[-1][1]
        self.points = points
        return True

    async def next_point(self) -> Next:
        """Drive to the next ring point that a route reaches (`Next.ROUTE`); at the end of
        the rings, the sweep when a wider search has time left (`Next.SWEEP`), else
        `Next.OVER` (a wider search's time over ends the rings too)."""
        now = trio.current_time()
        if now >= self.until:
            self.points = []  # out of time: answer while the operator still listens
        while self.points:
            q = self.points.pop(0)
            if await self.nav.goto_as(q, None, "searching",
                                      f"round the place, ring {self.ring_cm:.0f} cm"):
                return Next.ROUTE
        if self.nav.memory.within is not None and now < self.until < math.inf:
            return Next.SWEEP
        return Next.OVER

    def over_reason(self, swept: bool) -> str:
        """Why the search found nothing (``swept``: the sweep by touch ran too)."""
        rings = "a ring of" if self.nav.memory.within is None else "rings out to"
        sweep = ", nor sweeping the room by touch" if swept else ""
        return (f"the IR sensor saw nothing there, nor on {rings} "
                f"{self.ring_cm:.0f} cm round it{sweep}")

    async def sweep(self, first: bool) -> None:
        """One step of the sweep by touch (``first``: the sweep's first): face the leg's
        heading, drive ``sweep_step_cm`` (or until blocked; `motion_ended`), then the
        seeker scans all round. A leg goes straight step after step until a step is
        blocked (or ``SWEEP_MAX_STEPS``); the next leg turns ``SWEEP_TURN_DEG`` from it.

        Why: the rings are planned on the map from the pose; when they saw nothing the
        pose may be far off (a heading lost unseen), and a rover that trusts it drives
        into walls it thinks are metres away. Straight legs from wall to wall, turning
        by the golden angle, cross the whole room like a billiard ball whatever the pose
        says; short legs in random directions would wander about where they began.
        """
        if first or self.sweep_blocked or self.sweep_steps >= SWEEP_MAX_STEPS:
            base = self.nav.map_pose.heading_deg if first else self.leg_heading
            self.leg_heading = base + SWEEP_TURN_DEG
            self.sweep_steps = 0
        self.sweep_turned = False
        left = self.until - trio.current_time()
        await self.nav.set_state("sweeping", f"by touch, the pose in doubt ({left:.0f} s left)")
        turn = angle_diff_deg(self.leg_heading, self.nav.map_pose.heading_deg)
        if abs(turn) <= self.nav.o.heading_tol_deg:
            await self.motion_ended(False)
        else:
            await self.nav.command(Motion("turn", turn))

    async def motion_ended(self, blocked: bool) -> bool:
        """A motion of the sweep's step ended (``blocked``: stopped by contact): after its
        turn, drive the step (False); after the drive, count the step: True, the scan from
        here is next."""
        if not self.sweep_turned:
            self.sweep_turned = True
            await self.nav.command(Motion("move", self.s.sweep_step_cm))
            return False
        self.sweep_blocked = blocked
        self.sweep_steps += 1
        return True
