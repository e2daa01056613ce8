"""Seeking navigation: look from near the place, then from the place itself, with the IR sensor.

Flow (see `nav_common.RouteNav` for map, origin and destination handling)::

    ready --destination (x, y)--> driving to a standoff point, facing (x, y)
        --arrived, or blocked within ``near_cm`` of (x, y)--> confirming (standoff scan)
    standoff scan: at each heading (facing, +20, -20, +40, -40 [deg]) wait
        ``settle_s`` and up to ``ir_wait_s`` for NAV_IR in range
        --in range--> found: ``found {pose}``
        --scan over--> approaching the place itself (stopping ``close_cm`` short)
            --arrived, or blocked within ``near_cm`` (the hider, most likely)-->
            confirming (all-round scan: facing, +-20, +-40, then on round
            in ``all_round_step_deg`` steps)
                --in range--> found
                --scan over, own drift small--> ``not_found {reason}``
                --scan over, own drift large--> searching: to each point of a ring
                    round (x, y), scanning outward from it (+-100 deg)
                        --in range--> found
                        --ring over--> ``not_found {reason}``, ready for the next guess

A destination with ``within`` W (the operator's wider search after a guess
failed) searches rings round (x, y) out to W plus the seeker's drift: the ring
above first, then wider ones (`search_rings`), innermost first. When the rings
saw nothing, the pose itself is in doubt (a heading lost in a turn no tread
report showed), and what is left of ``wide_search_s`` goes
to a sweep by touch (`SeekingNav._sweep`): straight legs from wall to wall,
stopping every ``sweep_step_cm`` to scan all round, turning ``sweep_turn_deg``
where blocked; no map, no pose.

Standoff: the hider may stand at (x, y), so the seeker first stops
``standoff_cm`` away (centre to centre), on a passable point of the map
(tried on rings of several radii, nearest to the seeker first), and turns to
face (x, y): the IR sensor sees about 60 cm from the nose within +-20 deg.

Why the second stage: a guess is "within IR range" of the hider when the
hider stands anywhere within that range of (x, y), on any side. From a
standoff point on the near side the far side is out of range; from (x, y)
itself, turning in place, every such spot is seen (the nose is then at most
the range minus half the body length from the hider's centre). Steps of
20 [deg] keep a hider close by inside the +-20 [deg] field of view as seen
from the nose, not just from the centre.

Why the ring (`SeekingNav._plan_search`): the seeker stands where dead
reckoning says; after metres of driving that may be tens of cm from the
place, and a hider within IR range of the place may then be beyond what the
scan from it sees. The ring is sized by the seeker's drift estimate
(`NavBase.drift_cm`) so that its scans see everything within IR range of the
place plus that drift.

IR on demand: while confirming, navigation holds a lease on the IR actor's
sampling (`Cmd.IR_LEASE`, renewed every tick for ``ir_lease_s``) and ends it
when it answers, so the IR timer runs only while the seeker looks.

Frame: destination and reports in the map frame [cm, deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trio

from actors import BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.odometry import angle_diff_deg
from actors.firmware.mapping.grid_map import FREE
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route import Motion, passable_at
from actors.firmware.nav.route_nav import RouteNav

__all__ = ["SeekingOptions", "SeekingNav", "ring_outer_cm", "ring_reach_cm", "search_ring",
           "search_rings"]


@dataclass(frozen=True, slots=True)
class SeekingOptions:
    """Tunables of the approach and of the IR confirmation."""

    standoffs_cm: tuple[float, ...] = (35.0, 45.0, 30.0, 55.0)
    """Standoff radii to try, in order of preference [cm]."""
    ring_step_deg: float = 15.0
    """Angular spacing of candidate points on a ring [deg]."""
    max_plans: int = 8
    """Candidate points planned to, at most, per destination."""
    near_cm: float = 70.0
    """Blocked this close to the place: confirm from here [cm]."""
    settle_s: float = 0.4
    """Wait after each turn before trusting the IR decision [s]."""
    ir_wait_s: float = 1.5
    """Longest wait for "in range" at one heading [s]."""
    scan_deg: tuple[float, ...] = (0.0, 20.0, -20.0, 40.0, -40.0)
    """Headings to check from the standoff, relative to facing the place [deg]."""
    close_cm: float = 5.0
    """The approach to the place itself stops this short of it [cm]."""
    all_round_step_deg: float = 20.0
    """Step of the all-round scan from the place [deg]."""
    ir_lease_s: float = 1.0
    """How long each IR lease keeps the sensor sampling [s]; renewed every navigation tick
    while confirming, so it outlasts a few missed ticks."""
    search: bool = True
    """After the all-round scan saw nothing, search around the place (see `search_ring`)."""
    range_cm: float = 60.0
    """A guess "within IR range" has the hider's centre this close to it [cm]."""
    reach_cm: float = 70.0
    """An all-round scan sees a hider whose centre is this close to the seeker's centre
    [cm]: the nose is 10 cm ahead of it, the sensor sees 60 cm from the nose and the
    hider's body is 7.5-10 cm deep; a few cm are left for the scan's 20 deg steps."""
    search_points: int = 6
    """Points of the search ring around the place, at most (fewer when they see far
    enough: `search_ring`)."""
    search_ring_max_cm: float = 60.0
    """Largest radius of the search ring [cm] (with 6 points it covers 115 cm)."""
    search_ir_wait_s: float = 0.8
    """Longest wait for "in range" at one heading of a search scan [s]: the IR decision
    comes within about 0.1 s (3 samples at 50 Hz); the scans from the place keep
    ``ir_wait_s``."""
    search_scan_deg: float = 100.0
    """From a ring point, scan outward from the place +- this [deg] (the inside is
    covered by the scan from the place itself)."""
    wide_spacing_cm: float = 70.0
    """Spacing of neighbouring points on the rings beyond the first of a wider search
    (a destination's ``within``) [cm]: with ``reach_cm`` 70 each ring then sees about
    60 cm beyond itself."""
    wide_max_rings: int = 6
    """Rings of a wider search, at most (the first included)."""
    wide_scan_step_deg: float = 30.0
    """Step of the outward scans of a wider search [deg]: with the sensor's +-20 deg a
    30 deg step still overlaps, and the scans cost two thirds of 20 deg ones."""
    sweep_step_cm: float = 110.0
    """Leg of the sweep by touch [cm]: a little less than two scans' reach (70 cm), so
    the discs seen from consecutive stops overlap."""
    sweep_turn_deg: float = 137.5
    """Turn between legs of the sweep [deg]: the golden angle, so the legs' headings
    spread evenly round the circle, without a random generator."""
    sweep_max_steps: int = 6
    """Steps of one sweep leg, at most (a leg ends earlier at whatever blocks it)."""
    doubt_rings_share: float = 0.5
    """Share of ``wide_search_s`` the rings get when the seeker's drift exceeds the
    destination's ``within``; the sweep by touch gets the rest."""
    wide_max_points: int = 72
    """Points of a wider search, at most (each costs a drive and a scan of about 15 s)."""
    wide_search_s: float = 800.0
    """A wider search (its rings, then the sweep by touch) ends after this long [s]; the
    operator's budget for the whole guess is longer (`headless.Budget.wider_seeking`)."""

    def all_round_deg(self) -> tuple[float, ...]:
        """The all-round scan's headings relative to facing the place [deg]: the
        standoff scan's first, then on round in one direction (short turns)."""
        first = list(self.scan_deg)
        out = list(first)
        step = self.all_round_step_deg
        a = max(first, default=0.0) + step
        while a < 360.0 + min(first, default=0.0) - step / 2:
            out.append(a)
            a += step
        return tuple(out)

    def outward_deg(self, step: float | None = None) -> tuple[float, ...]:
        """The scan from a search point: headings relative to facing away from the place,
        -``search_scan_deg`` .. +``search_scan_deg`` in ``step`` (default
        ``all_round_step_deg``) steps [deg]."""
        step = step or self.all_round_step_deg
        k = math.floor(self.search_scan_deg / step + 1e-9)
        return tuple(step * i for i in range(-k, k + 1))


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


class SeekingNav(RouteNav):
    """The seeker's navigation actor (registered as ``seeker/nav``)."""

    role = "seeker"

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec | None = None,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 seeking: SeekingOptions | None = None,
                 addresses: Addresses | None = None) -> None:
        super().__init__(pool=pool, spec=spec, options=options, memory=memory,
                         addresses=addresses)
        self.s = seeking or SeekingOptions()
        self.place: tuple[float, float] | None = None
        """Where to look (map frame [cm])."""
        self.ir = False
        """The IR actor's latest decision."""
        self.stage = "standoff"
        """``standoff`` (looking from near the place), ``close`` (from the place itself) or
        ``search`` (from points on a ring round it)."""
        self.search_points: list[tuple[float, float]] = []
        """Ring points still to look from (map frame [cm])."""
        self.ring_cm = 0.0
        """Radius of the search ring in progress [cm]."""
        self.search_until = math.inf
        """When the search in progress gives up [s] (a wider search only)."""
        self.rings_until = math.inf
        """When a wider search's rings give way to the sweep by touch [s]."""
        self._sweep_turned = False  # the sweep's step in progress has turned, and drives
        self._sweep_blocked = False  # the sweep's last step was blocked: the next leg turns
        self._sweep_steps = 0  # steps of the sweep's leg in progress
        self._leg_heading = 0.0  # the sweep's leg heading (map frame, as believed) [deg]
        self._ir_at = -math.inf
        self._scan: tuple[float, ...] = ()  # headings of the scan in progress [deg], map frame
        self._scan_index = 0
        self._check_from = math.inf
        self._check_until = math.inf

    # ------------------------------------------------------------------ approach
    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        self.place = (x, y)
        self.stage = "standoff"
        self.search_points = []
        if self._distance() <= self.s.near_cm:
            await self._confirm()
            return
        for point in self._standoff_points():
            face = math.degrees(math.atan2(y - point[1], x - point[0]))
            if await self.goto(point, face):
                return
        await self._approach()

    def _distance(self) -> float:
        assert self.place is not None
        return math.dist((self.map_pose.x, self.map_pose.y), self.place)

    async def _approach(self) -> None:
        """Second stage: drive to the place itself, then scan all round."""
        assert self.place is not None
        self.stage = "close"
        if self._distance() <= self.s.close_cm + self.o.goal_tol_cm:
            await self._confirm()
            return
        if await self.goto(self.place, None, stop_short_cm=self.s.close_cm):
            await self.set_state("approaching", "to the place itself")
            return
        x, y = self.place
        await self._not_found(f"no reachable point near ({x:.0f}, {y:.0f})")

    def _standoff_points(self) -> list[tuple[float, float]]:
        """Passable points around the place, nearest the seeker first, per radius."""
        assert self.work_map is not None and self.place is not None
        px, py = self.place
        me = (self.map_pose.x, self.map_pose.y)
        out: list[tuple[float, float]] = []
        n = max(4, round(360.0 / self.s.ring_step_deg))
        for r in self.s.standoffs_cm:
            ring = [(px + r * math.cos(2 * math.pi * k / n), py + r * math.sin(2 * math.pi * k / n))
                    for k in range(n)]
            ring = [p for p in ring if passable_at(self.work_map, p[0], p[1], self.radius_cm,
                                                   self.o.plan_margin_cm)]
            ring.sort(key=lambda p: math.dist(p, me))
            out += ring[:3]
        return out[:self.s.max_plans]

    async def on_blocked(self) -> bool:
        if self.place is not None and self._distance() <= self.s.near_cm:
            self.follower = None  # likely the hider itself: look from here
            await self._confirm()
            return True
        return False

    async def on_arrived(self) -> None:
        await self._confirm()

    async def on_route_failed(self, reason: str) -> None:
        if self.stage == "standoff":
            await self._approach()
        elif self.stage == "search":
            await self._next_search_point()
        elif self._plan_search() or self.memory.within is not None:
            await self._next_search_point()  # with ``within``: the sweep, ring or not
        else:
            await self._not_found(f"cannot get near the place: {reason}")

    # ------------------------------------------------------------------ search
    def _plan_search(self) -> bool:
        """After the scan from the place saw nothing: choose the ring(s) to look from.

        A guess within IR range has the hider's centre within ``range_cm`` of
        it (a destination's ``within``, when given, replaces that); the seeker's
        own dead reckoning may be ``drift_cm`` off, so what must be seen is
        everything within ``range_cm + drift_cm`` of the place as the seeker
        believes it. The scan from the place sees ``reach_cm``; beyond that,
        points on a ring (`search_ring`) do, and with ``within`` wider rings
        after it (`search_rings`).
        Points that are not passable are pulled in toward the place; points
        from which no free cell beyond what was seen before is within reach
        (walls, the map's edge) are left out.
        """
        s = self.s
        if not s.search or self.place is None or self.map is None:
            return False
        drift = self.drift_cm
        within = self.memory.within
        self.search_until = self.rings_until = math.inf
        if within is not None:
            now = trio.current_time()
            self.search_until = now + s.wide_search_s
            # a pose in more doubt than the guess: rings planned from it may all be
            # somewhere else, and the sweep by touch gets half the time
            share = s.doubt_rings_share if drift > within else 1.0
            self.rings_until = now + share * s.wide_search_s
        need = (s.range_cm if within is None else within) + drift
        rings = search_rings(need, s.reach_cm, s.search_points, s.search_ring_max_cm,
                             s.wide_spacing_cm, 1 if within is None else s.wide_max_rings)
        if not rings:
            return False
        px, py = self.place
        p = self.map_pose
        if math.dist((p.x, p.y), self.place) > 2.0 * self.o.goal_tol_cm:
            first = math.atan2(p.y - py, p.x - px)  # nearest the seeker first
        else:
            first = math.radians(p.heading_deg)  # on the place: the one it faces
        seen = max(0.0, s.reach_cm - drift)
        points: list[tuple[float, float]] = []
        for i, (n, ring) in enumerate(rings):
            # a point that does not fit is pulled in: the first ring toward the place,
            # wider rings by less, or they would repeat the ring inside them
            pulls = (ring, 0.75 * ring, 0.5 * ring) if i == 0 else (ring, ring - 20.0, ring - 40.0)
            for k in range(n):
                a = first + 2.0 * math.pi * k / n
                for r in pulls:
                    q = (px + r * math.cos(a), py + r * math.sin(a))
                    if passable_at(self.map, q[0], q[1], self.radius_cm, 0.0):  # turns there
                        if self._unseen_free(q, seen, need):
                            points.append(q)
                        break
            if points:  # the next ring starts beside where this one ends
                first = math.atan2(points[-1][1] - py, points[-1][0] - px)
            seen = max(0.0, ring_outer_cm(ring, s.reach_cm, n) - drift)
        points = points[:s.wide_max_points]
        if not points:
            return False
        self.stage = "search"
        self.ring_cm = rings[-1][1]
        self.search_points = points
        return True

    def _unseen_free(self, q: tuple[float, float], seen_cm: float, need_cm: float) -> bool:
        """Whether a free cell of the map lies within ``reach_cm`` of ``q``, farther than
        ``seen_cm`` from the place and within ``need_cm`` of it [cm]."""
        assert self.map is not None and self.place is not None
        g = self.map
        px, py = self.place
        reach = self.s.reach_cm
        res = g.resolution_cm
        r0, c0 = g.world_to_cell(q[0] - reach, q[1] - reach)
        r1, c1 = g.world_to_cell(q[0] + reach, q[1] + reach)
        ny, nx = g.shape
        r0, c0, r1, c1 = max(0, r0), max(0, c0), min(ny, r1 + 1), min(nx, c1 + 1)
        if r0 >= r1 or c0 >= c1:
            return False
        cells = np.asarray(g.cells)[r0:r1, c0:c1]
        ox, oy = g.origin_cm
        ys = oy + (np.arange(r0, r1) + 0.5) * res
        xs = ox + (np.arange(c0, c1) + 0.5) * res
        X, Y = np.meshgrid(xs, ys)
        dp = np.hypot(X - px, Y - py)
        mask = (cells == FREE) & (np.hypot(X - q[0], Y - q[1]) <= reach) & \
            (dp > seen_cm) & (dp <= need_cm)
        return bool(mask.any())

    async def _next_search_point(self) -> None:
        """Drive to the next ring point (then `on_arrived` scans outward); at the end of
        the ring, ``not_found`` -- or, in a wider search with time left, the sweep."""
        now = trio.current_time()
        if now >= self.rings_until:
            self.search_points = []  # out of time: answer while the operator still listens
        while self.search_points:
            q = self.search_points.pop(0)
            if await self.goto(q, None):
                await self.set_state("searching", f"round the place, ring {self.ring_cm:.0f} cm")
                return
        if self.memory.within is not None and now < self.search_until < math.inf:
            await self._sweep()
            return
        rings = "a ring of" if self.memory.within is None else "rings out to"
        swept = ", nor sweeping the room by touch" if self.stage == "sweep" else ""
        await self._not_found(f"the IR sensor saw nothing there, nor on {rings} "
                              f"{self.ring_cm:.0f} cm round it{swept}")

    async def _sweep(self) -> None:
        """One step of the sweep by touch: face the leg's heading, drive ``sweep_step_cm``
        (or until blocked), then scan all round (`_confirm`). A leg goes straight step
        after step until a step is blocked (or ``sweep_max_steps``); the next leg turns
        ``sweep_turn_deg`` from it.

        Why: the rings are planned on the map from the pose; when they saw nothing the
        pose may be far off (a heading lost unseen), and a rover that trusts it drives
        into walls it thinks are metres away. Straight legs from wall to wall, turning
        by the golden angle, cross the whole room like a billiard ball whatever the pose
        says; short legs in random directions would wander about where they began.
        """
        first = self.stage != "sweep"
        self.stage = "sweep"
        if first or self._sweep_blocked or self._sweep_steps >= self.s.sweep_max_steps:
            base = self.map_pose.heading_deg if first else self._leg_heading
            self._leg_heading = base + self.s.sweep_turn_deg
            self._sweep_steps = 0
        self._sweep_turned = False
        left = self.search_until - trio.current_time()
        await self.set_state("sweeping", f"by touch, the pose in doubt ({left:.0f} s left)")
        turn = angle_diff_deg(self._leg_heading, self.map_pose.heading_deg)
        if abs(turn) <= self.o.heading_tol_deg:
            await self.after_other_motion(False, 0.0)
        else:
            await self.command(Motion("turn", turn))

    # ------------------------------------------------------------------ IR confirmation
    async def _confirm(self) -> None:
        assert self.place is not None
        where = {"close": " all round", "search": " from the search ring",
                 "sweep": " all round, sweeping"}.get(self.stage, "")
        await self.set_state("confirming", "looking with the IR sensor" + where)
        await self._ir_lease(self.s.ir_lease_s)
        p = self.map_pose
        if self._distance() > 2.0 * self.o.goal_tol_cm:
            base = math.degrees(math.atan2(self.place[1] - p.y, self.place[0] - p.x))
        else:
            base = p.heading_deg  # standing on the place: no bearing to it
        if self.stage == "sweep":  # all round from the heading it has, the place unknown
            step = self.s.wide_scan_step_deg
            self._scan = tuple(p.heading_deg + step * k for k in range(round(360.0 / step)))
        elif self.stage == "search" and self._distance() > 2.0 * self.o.goal_tol_cm:
            # facing away from the place, swept from the end nearer the heading
            out = math.degrees(math.atan2(p.y - self.place[1], p.x - self.place[0]))
            wider = self.memory.within is not None
            offsets = self.s.outward_deg(self.s.wide_scan_step_deg if wider else None)
            if abs(angle_diff_deg(out + offsets[-1], p.heading_deg)) < \
                    abs(angle_diff_deg(out + offsets[0], p.heading_deg)):
                offsets = offsets[::-1]
            self._scan = tuple(out + o for o in offsets)
        else:
            offsets = self.s.all_round_deg() if self.stage != "standoff" else self.s.scan_deg
            self._scan = tuple(base + o for o in offsets)
        self._scan_index = 0
        await self._face(self._scan[0])

    async def _face(self, heading: float) -> None:
        p = self.map_pose
        turn = angle_diff_deg(heading, p.heading_deg)
        if abs(turn) <= self.o.heading_tol_deg:
            self._start_check()
        else:
            await self.command(Motion("turn", turn))

    async def after_other_motion(self, blocked: bool, done: float) -> None:
        if self.state == "confirming":
            self._start_check()
        elif self.state == "sweeping" and not self._sweep_turned:
            self._sweep_turned = True
            await self.command(Motion("move", self.s.sweep_step_cm))
        elif self.state == "sweeping":
            self._sweep_blocked = blocked
            self._sweep_steps += 1
            await self._confirm()

    def _start_check(self) -> None:
        now = trio.current_time()
        wait = self.s.search_ir_wait_s if self.stage in ("search", "sweep") else self.s.ir_wait_s
        self._check_from = now + self.s.settle_s
        self._check_until = now + self.s.settle_s + wait

    async def on_ir(self, in_range: bool) -> None:
        self.ir = in_range
        self._ir_at = trio.current_time()
        await self._check()

    async def _ir_lease(self, seconds: float) -> None:
        """Ask the IR actor to sample for ``seconds`` [s] (0: stop now); not waiting long."""
        name = self.names.ir
        if self.ctx.system.whereis(name) is not None:  # a tree without IR: nothing to ask
            await self.post(name, Message.float(Cmd.IR_LEASE, seconds))

    async def on_tick(self, now: float) -> None:
        await super().on_tick(now)
        if self.state != "confirming":
            return
        await self._ir_lease(self.s.ir_lease_s)
        if self.moving:
            return
        if await self._check():
            return
        if now >= self._check_until:
            self._check_until = math.inf
            self._scan_index += 1
            if self._scan_index < len(self._scan):
                await self._face(self._scan[self._scan_index])
            elif self.stage == "standoff":
                await self._approach()
            elif self.stage == "close" and (self._plan_search() or self.memory.within is not None):
                await self._next_search_point()  # with ``within``: the sweep, ring or not
            elif self.stage in ("search", "sweep"):
                await self._next_search_point()
            else:
                await self._not_found("the IR sensor saw nothing there")

    async def _check(self) -> bool:
        now = trio.current_time()
        if (self.state == "confirming" and not self.moving and self.ir
                and self._ir_at >= self._check_from and now >= self._check_from):
            self._check_until = math.inf
            self.answered()
            await self._ir_lease(0.0)
            await self.report("found", self.pose_data())
            await self.set_state("found", "the hider is in IR range")
            return True
        return False

    async def _not_found(self, reason: str) -> None:
        self._check_until = math.inf
        self.answered()
        await self._ir_lease(0.0)
        await self.report("not_found", {"reason": reason})
        await self.set_state("ready", reason)
