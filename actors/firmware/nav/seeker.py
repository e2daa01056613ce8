"""Seeking navigation: look from near the place, then from the place itself, with the IR sensor.

Flow (see `route_nav.RouteNav` for map, origin and destination handling; the search
rings and the sweep are in `search`)::

    ready --destination (x, y)--> driving to a standoff point, facing (x, y)
        --arrived, or blocked within ``reach_cm`` of (x, y)--> confirming (standoff scan)
    standoff scan: at each heading (facing, +20, -20, +40, -40 [deg]) wait
        ``settle_s`` and up to ``ir_wait_s`` for NAV_IR in range
        --in range--> found: ``found {pose}``
        --scan over--> approaching the place itself (stopping ``close_cm`` short)
            --arrived, or blocked within ``reach_cm`` (the hider, most likely)-->
            confirming (all-round scan: facing, +-20, +-40, then on round
            in ``ir_half_fov_deg`` steps)
                --in range--> found
                --scan over, own drift small--> ``not_found {reason}``
                --scan over, own drift large--> searching: to each point of a ring
                    round (x, y), scanning outward from it (+-100 deg)
                        --in range--> found
                        --ring over--> ``not_found {reason}``, ready for the next guess

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

A look blocked by something unmapped: a scan's turn that ends blocked where the
map shows free ground round the body (`Seek._touching_unmapped`) backs off
``look_backoff_cm`` the way the seeker came and looks again from there, once per
look point: beside the hider, the turn that would point the nose at it is the one
its body stops.

IR on demand: while confirming, navigation holds a lease on the IR actor's
sampling (`Cmd.IR_LEASE`, renewed every tick for ``IR_LEASE_TICKS`` ticks) and ends it
when it answers, so the IR timer runs only while the seeker looks.

Frame: destination and reports in the map frame [cm, deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import trio

from actors import Message
from actors.firmware.commands import Cmd
from actors.firmware.nav.role import RoleBehaviour
from actors.firmware.nav.route import Motion, passable_at
from actors.firmware.nav.search import SEARCH_IR_WAIT_S, SEARCH_SCAN_DEG, Next, Search
from actors.firmware.planning.clearance import turning_radius_cm
from server.protocol.pose import angle_diff_deg

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["SeekingOptions", "Seek", "IR_LEASE_TICKS", "STANDOFF_RING_STEP_DEG",
           "MAX_STANDOFF_PLANS", "IR_PINNED_WAIT_S"]


IR_LEASE_TICKS = 4
"""An IR lease lasts this many navigation ticks (``NavOptions.tick_s``): renewed every
tick while confirming, it outlasts a few missed ticks and ends soon after the last."""

STANDOFF_RING_STEP_DEG = 15.0
"""Angular spacing of the candidate standoff points on each radius [deg]: the
candidates are a sampling of the ring, three nearest the seeker kept per radius."""

MAX_STANDOFF_PLANS = 8
"""Candidate standoff points planned to per destination, at most (a bound on planning)."""

IR_PINNED_WAIT_S = 30.0
"""How long a look waits for an IR sensor pinned at an ADC rail to read again [s] before
the seeker reports that it cannot tell: a stuck sensor or a loose line often recovers,
and reporting at once would spend the operator's guesses while it cannot see."""


@dataclass(frozen=True, slots=True)
class SeekingOptions:
    """Physical quantities of the approach and of the IR confirmation.

    Derived, not set: the scan's reach (`reach_cm`: ``range_cm`` plus half the body
    length, the IR sensor sits on the nose), the headings of the scans (multiples of
    ``ir_half_fov_deg``) and the wider search's ring spacing (the reach). The bounds
    of the search are constants of `search`.
    """

    standoffs_cm: tuple[float, ...] = (35.0, 45.0, 30.0, 55.0)
    """Standoff radii to try, in order of preference (centre of the place to the
    seeker's centre) [cm]."""
    settle_s: float = 0.4
    """Wait after each turn before trusting the IR decision [s]."""
    ir_wait_s: float = 1.5
    """Longest wait for "in range" at one heading of a scan from the place or a standoff
    [s]."""
    close_cm: float = 5.0
    """The approach to the place itself stops this short of it [cm]."""
    ir_half_fov_deg: float = 20.0
    """Half-angle of the IR sensor's field of view [deg]. Scans turn in steps of it
    (a hider close by stays in view from the nose, not just from the centre); the
    standoff scan looks at 0, +-1 and +-2 steps from facing the place; the outward scans
    of a wider search and the sweep's turn by `wide_scan_step_deg` (about 20 deg for
    the 20 x 15 cm body: no hole in the view even for a hider touching the body)."""
    range_cm: float = 60.0
    """The IR sensor's range from the nose: a guess "within IR range" has the hider's
    centre this close to it [cm]."""
    sweep_step_cm: float = 110.0
    """Leg of the sweep by touch [cm]: a little less than two scans' reach (70 cm), so
    the discs seen from consecutive stops overlap."""
    wide_search_s: float = 800.0
    """A wider search (its rings, then the sweep by touch) ends after this long [s]; the
    operator's budget for the whole guess is longer (`headless.Budget.wider_seeking`)."""

    @property
    def scan_deg(self) -> tuple[float, ...]:
        """Headings to check from the standoff, relative to facing the place: 0, +-1 and
        +-2 steps of ``ir_half_fov_deg`` [deg]."""
        f = self.ir_half_fov_deg
        return (0.0, f, -f, 2.0 * f, -2.0 * f)

    def view_half_deg(self, length_cm: float, distance_cm: float) -> float:
        """Half-width of the headings from which the IR sensor sees a hider whose centre
        is ``distance_cm`` from the seeker's centre [deg]: the sensor sits on the nose,
        half the body ``length_cm`` ahead, and sees centres within ``ir_half_fov_deg`` of
        the heading as seen from there, so near by the window narrows (law of sines in
        the triangle centre, nose, hider: ``fov - asin(nose sin(fov) / distance)``)."""
        f = math.radians(self.ir_half_fov_deg)
        ratio = min(1.0, 0.5 * length_cm * math.sin(f) / max(distance_cm, 1e-9))
        return math.degrees(f - math.asin(ratio))

    def wide_scan_step_deg(self, length_cm: float, width_cm: float) -> float:
        """Step of the outward scans of a wider search and of the sweep [deg]: twice the
        view's half-width (`view_half_deg`) for a hider touching the seeker's side (its
        centre half the width plus the turning radius of a body like the seeker's away),
        so consecutive headings leave no hole even beside it, and the hider is seen
        whatever the heading's error; at most 1.5 ``ir_half_fov_deg``."""
        near = 0.5 * width_cm + turning_radius_cm(length_cm, width_cm)
        return min(1.5 * self.ir_half_fov_deg, 2.0 * self.view_half_deg(length_cm, near))

    def reach_cm(self, length_cm: float) -> float:
        """How far from the seeker's centre an all-round scan sees a hider's centre
        [cm]: ``range_cm`` from the nose, which is half the body ``length_cm`` ahead of
        the centre (the hider's depth and the scan's steps are left as margin)."""
        return self.range_cm + 0.5 * length_cm

    def all_round_deg(self) -> tuple[float, ...]:
        """The all-round scan's headings relative to facing the place [deg]: the
        standoff scan's first, then on round in one direction (short turns) in steps
        of ``ir_half_fov_deg``."""
        first = list(self.scan_deg)
        out = list(first)
        step = self.ir_half_fov_deg
        a = max(first, default=0.0) + step
        while a < 360.0 + min(first, default=0.0) - step / 2:
            out.append(a)
            a += step
        return tuple(out)

    def outward_deg(self, step: float | None = None) -> tuple[float, ...]:
        """The scan from a search point: headings relative to facing away from the place,
        -``SEARCH_SCAN_DEG`` .. +``SEARCH_SCAN_DEG`` in ``step`` (default
        ``ir_half_fov_deg``) steps [deg]."""
        step = step or self.ir_half_fov_deg
        k = math.floor(SEARCH_SCAN_DEG / step + 1e-9)
        return tuple(step * i for i in range(-k, k + 1))


class Seek(RoleBehaviour):
    """The seeker's role behaviour (its actor is registered as ``seeker/nav``): the
    approach and the IR confirmation; the rings and the sweep by touch are its part
    ``search`` (`search.Search`).

    Args:
        nav: the navigation actor it drives.
        seeking: the approach's and the IR confirmation's quantities.
    """

    def __init__(self, nav: RouteNav, seeking: SeekingOptions | None = None) -> None:
        super().__init__(nav)
        self.s = seeking or SeekingOptions()
        self.reach_cm = self.s.reach_cm(nav.length_cm)
        """How far from the centre an all-round scan sees a hider's centre [cm]; also how
        near the place a block confirms from where it stands, and the spacing of a wider
        search's ring points (each ring then sees about 60 cm beyond itself)."""
        self.place: tuple[float, float] | None = None
        """Where to look (map frame [cm])."""
        self.ir = False
        self.ir_pinned = False
        """The IR sensor sits on an ADC rail (it cannot tell; `drivers.ir`)."""
        """The IR actor's latest decision."""
        self.stage = "standoff"
        """``standoff`` (looking from near the place), ``close`` (from the place itself),
        ``search`` (from points on a ring round it) or ``sweep`` (the sweep by touch)."""
        self.search = Search(nav, self.s, self.reach_cm)
        """The rings round the place and the sweep by touch."""
        self._ir_at = -math.inf
        self._scan: tuple[float, ...] = ()  # headings of the scan in progress [deg], map frame
        self._scan_index = 0
        self._check_from = math.inf
        self._check_until = math.inf
        self._pinned_since: float | None = None  # a look held for a pinned sensor, since [s]
        self.look_backoff_cm = 2.0 * nav.radius_cm
        """How far a look blocked by something unmapped backs off before looking again [cm]:
        the diameter of the circle the body sweeps turning in place, so a body of its own
        size that touched it is clear of that circle, whichever side it touched."""
        self._came_heading: float | None = None  # heading of the last forward move [deg], map
        self._looked_again = False  # the look at this point has backed off once already
        self._backing: str | None = None  # the back-off in progress: "turn", then "move"

    # ------------------------------------------------------------------ approach
    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        self.place = (x, y)
        self.stage = "standoff"
        self.search.points = []
        self._backing = None
        if self._distance() <= self.reach_cm:
            await self._confirm()
            return
        for point in self._standoff_points():
            face = math.degrees(math.atan2(y - point[1], x - point[0]))
            if await self.nav.goto(point, face):
                return
        await self._approach()

    def _distance(self) -> float:
        assert self.place is not None
        return math.dist((self.nav.map_pose.x, self.nav.map_pose.y), self.place)

    async def _approach(self) -> None:
        """Second stage: drive to the place itself, then scan all round."""
        assert self.place is not None
        self.stage = "close"
        if self._distance() <= self.s.close_cm + self.nav.o.goal_tol_cm:
            await self._confirm()
            return
        if await self.nav.goto_as(self.place, None, "approaching", "to the place itself",
                              stop_short_cm=self.s.close_cm):
            return
        x, y = self.place
        await self.not_found(f"no reachable point near ({x:.0f}, {y:.0f})")

    def _standoff_points(self) -> list[tuple[float, float]]:
        """Passable points around the place, nearest the seeker first, per radius."""
        assert self.nav.work_map is not None and self.place is not None
        nav = self.nav
        px, py = self.place
        me = (nav.map_pose.x, nav.map_pose.y)
        out: list[tuple[float, float]] = []
        n = max(4, round(360.0 / STANDOFF_RING_STEP_DEG))
        for r in self.s.standoffs_cm:
            ring = [(px + r * math.cos(2 * math.pi * k / n), py + r * math.sin(2 * math.pi * k / n))
                    for k in range(n)]
            ring = [p for p in ring if passable_at(nav.work_map, p[0], p[1], nav.radius_cm,
                                                   nav.o.plan_margin_cm)]
            ring.sort(key=lambda p: math.dist(p, me))
            out += ring[:3]
        return out[:MAX_STANDOFF_PLANS]

    async def on_blocked(self) -> bool:
        if self.place is not None and self._distance() <= self.reach_cm:
            self.nav.follower = None  # likely the hider itself: look from here
            await self._confirm()
            return True
        return False

    async def on_arrived(self) -> None:
        await self._confirm()

    async def on_route_failed(self, reason: str) -> None:
        if self.stage == "standoff":
            await self._approach()
        elif self.stage == "search":
            await self._search_on()
        elif self.plan_search() or self.nav.memory.within is not None:
            await self._search_on()  # with ``within``: the sweep, ring or not
        else:
            await self.not_found(f"cannot get near the place: {reason}")

    # ------------------------------------------------------------------ the search
    def plan_search(self) -> bool:
        """After the scan from the place saw nothing: plan the search's rings
        (`search.Search.plan`); True, and the ``search`` stage, when there are points to
        look from."""
        if self.place is None or not self.search.plan(self.place):
            return False
        self.stage = "search"
        return True

    async def _search_on(self) -> None:
        """Drive to the next ring point; at the end of the rings, the sweep by touch (a
        wider search with time left) or ``not_found``."""
        step = await self.search.next_point()
        if step is Next.SWEEP:
            first = self.stage != "sweep"
            self.stage = "sweep"
            await self.search.sweep(first)
        elif step is Next.OVER:
            await self.not_found(self.search.over_reason(swept=self.stage == "sweep"))

    # ------------------------------------------------------------------ IR confirmation
    async def _confirm(self, again: bool = False) -> None:
        """Look from here (a new look point unless ``again``: the look after a back-off)."""
        assert self.place is not None
        self._looked_again = again
        self._backing = None
        where = {"close": " all round", "search": " from the search ring",
                 "sweep": " all round, sweeping"}.get(self.stage, "")
        await self.nav.set_state("confirming", "looking with the IR sensor" + where)
        await self._ir_lease(IR_LEASE_TICKS * self.nav.o.tick_s)
        p = self.nav.map_pose
        if self._distance() > 2.0 * self.nav.o.goal_tol_cm:
            base = math.degrees(math.atan2(self.place[1] - p.y, self.place[0] - p.x))
        else:
            base = p.heading_deg  # standing on the place: no bearing to it
        if self.stage == "sweep":  # all round from the heading it has, the place unknown
            step = self.s.wide_scan_step_deg(self.nav.length_cm, self.nav.width_cm)
            self._scan = tuple(p.heading_deg + step * k for k in range(round(360.0 / step)))
        elif self.stage == "search" and self._distance() > 2.0 * self.nav.o.goal_tol_cm:
            # facing away from the place, swept from the end nearer the heading
            out = math.degrees(math.atan2(p.y - self.place[1], p.x - self.place[0]))
            wider = self.nav.memory.within is not None
            offsets = self.s.outward_deg(
                self.s.wide_scan_step_deg(self.nav.length_cm, self.nav.width_cm) if wider else None)
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
        p = self.nav.map_pose
        turn = angle_diff_deg(heading, p.heading_deg)
        if abs(turn) <= self.nav.o.heading_tol_deg:
            self._start_check()
        else:
            await self.nav.command(Motion("turn", turn))

    def before_command(self, motion: Motion) -> None:
        if motion.kind == "move" and motion.amount > 0:
            self._came_heading = self.nav.map_pose.heading_deg  # the way back is free ground

    async def after_other_motion(self, blocked: bool, done: float) -> None:
        if self._backing is not None and self.nav.state == "confirming":
            await self._back_off_step()
        elif self.nav.state == "confirming":
            if blocked and self._touching_unmapped():
                await self._back_off()
            else:
                self._start_check()
        elif self.nav.state == "sweeping" and await self.search.motion_ended(blocked):
            await self._confirm()  # the sweep's step drove: look all round

    def _touching_unmapped(self) -> bool:
        """The look's turn ended blocked where the map shows free ground round the body
        (no mapped wall within the turning radius plus ``drift_cm``), and the look at this
        point has not backed off yet.

        Why: something the map does not show touches the body, and while the seeker
        looks for the hider the hider is the likeliest such thing. Beside it, the turn that
        would point the nose (and the IR sensor) at it is the one its body blocks: the
        seeker must step back to see it.
        """
        m = self.nav.last_motion
        return (m is not None and m.kind == "turn" and not self._looked_again
                and self.nav.map is not None and not self.nav.wall_within_drift())

    async def _back_off(self) -> None:
        """Back off ``look_backoff_cm`` the way it came (first turning back to the heading
        of its last forward move, through ground the turn just swept), then look again."""
        self._looked_again = True
        self._check_until = math.inf
        self.nav.counters["look_backoffs"] = self.nav.counters.get("look_backoffs", 0) + 1
        await self.nav.status(self.nav.state, "blocked turning to look: backing off to look again")
        came = self._came_heading
        turn = 0.0 if came is None else angle_diff_deg(came, self.nav.map_pose.heading_deg)
        if abs(turn) > self.nav.o.heading_tol_deg:
            self._backing = "turn"
            await self.nav.command(Motion("turn", turn))
        else:
            self._backing = "move"
            await self.nav.command(Motion("move", -self.look_backoff_cm))

    async def _back_off_step(self) -> None:
        """The back-off's turn ended: reverse; its reverse ended (blocked or not): look
        again from where it stands."""
        if self._backing == "turn":
            self._backing = "move"
            await self.nav.command(Motion("move", -self.look_backoff_cm))
        else:
            await self._confirm(again=True)

    def _start_check(self) -> None:
        now = trio.current_time()
        wait = SEARCH_IR_WAIT_S if self.stage in ("search", "sweep") else self.s.ir_wait_s
        self._check_from = now + self.s.settle_s
        self._check_until = now + self.s.settle_s + wait

    async def on_ir(self, in_range: bool, *, pinned: bool = False) -> None:
        self.ir = in_range
        self.ir_pinned = pinned
        now = trio.current_time()
        if self.nav.state == "confirming" and pinned:
            # a sensor on its rail cannot tell: hold the look (stuck high would otherwise
            # report a hider wherever it looks, stuck low search blind) until it reads again
            if self._pinned_since is None:
                self._pinned_since = now
            self._check_until = math.inf
            return
        if self._pinned_since is not None:  # it reads again: look afresh from here
            self._pinned_since = None
            if self.nav.state == "confirming":
                self._start_check()
        self._ir_at = now
        await self._check()

    async def _ir_lease(self, seconds: float) -> None:
        """Ask the IR actor to sample for ``seconds`` [s] (0: stop now); not waiting long."""
        name = self.nav.names.ir
        if self.nav.ctx.system.whereis(name) is not None:  # a tree without IR: nothing to ask
            await self.nav.post(name, Message.float(Cmd.IR_LEASE, seconds))

    async def on_tick(self, now: float) -> None:
        if self.nav.state != "confirming":
            return
        await self._ir_lease(IR_LEASE_TICKS * self.nav.o.tick_s)
        if self._pinned_since is not None:
            if now - self._pinned_since >= IR_PINNED_WAIT_S:
                await self.not_found("the IR sensor is pinned at an ADC rail: it cannot tell")
            return
        if self.nav.moving:
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
            elif self.stage == "close" and (self.plan_search()
                                            or self.nav.memory.within is not None):
                await self._search_on()  # with ``within``: the sweep, ring or not
            elif self.stage in ("search", "sweep"):
                await self._search_on()
            else:
                await self.not_found("the IR sensor saw nothing there")

    async def _check(self) -> bool:
        now = trio.current_time()
        if (self.nav.state == "confirming" and not self.nav.moving and self.ir
                and self._ir_at >= self._check_from and now >= self._check_from):
            self._check_until = math.inf
            self.nav.answered()
            await self._ir_lease(0.0)
            await self.nav.report("found", self.nav.pose_data())
            await self.nav.set_state("found", "the hider is in IR range")
            return True
        return False

    async def not_found(self, reason: str) -> None:
        self._check_until = math.inf
        self._pinned_since = None
        self.nav.answered()
        await self._ir_lease(0.0)
        await self.nav.report("not_found", {"reason": reason})
        await self.nav.set_state("ready", reason)
