"""What the three navigation actors share: pose tracking, the ADP loop, the server, frames.

Navigation is the seed's "Navigation thread" of each rover. It never touches
hardware: it commands Motor Control (Command A), reads the dead-reckoned pose
Motor Control publishes, and talks to the server only through its WiFly actor.

The ADP loop (seed: "Command A, wait for distance travelled, update position")
    One small motion at a time: `PathFollower.next_motion` turns the current
    pose and the remaining waypoints into one `Motion` (a turn toward the next
    waypoint when off by more than ``align_tol_deg``, else a straight move of at
    most ``step_cm``); navigation sends it as MOTOR_TURN / MOTOR_MOVE, waits for
    NAV_MOTION_DONE or NAV_MOTION_BLOCKED, asks Motor Control for the pose
    (MOTOR_GET_POSE, so the decision uses the pose at rest, not one published
    mid-motion) and decides again. Every wait is bounded: a motion that reports
    nothing within its timeout is stopped and counts as blocked.

Frames
    Each rover's dead reckoning starts at (0, 0) @ 0 [deg] (its own frame). The
    map frame is the mapper's start frame; the server sends each rover its
    ``origin`` (start pose in the map frame), so ``map = compose(origin, own)``.
    Maps, destinations and reports are in the map frame; motions are relative,
    so they need no conversion.

Restart (why state survives honestly)
    A new incarnation knows nothing but what it can ask: ``on_start`` stops the
    motor (a motion commanded by the dead incarnation has nobody waiting for it),
    asks Motor Control for the pose (MOTOR_GET_POSE), and tells the server with
    a ``status`` of state ``restarted``, so the server can resend what this
    rover must still do. Role specifics (the mapper's map) are in the subclasses.

Units: positions [cm], headings [deg] counter-clockwise from +x.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import trio

from actors import Actor, BufferPool, Message, PoolExhausted, ValueType
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.contact import locate_contact, stalled_side
from actors.firmware.localisation.odometry import ORIGIN, Pose, angle_diff_deg, compose, inverse
from actors.firmware.mapping.occupancy import OCCUPIED, GridMap
from actors.firmware.planning.clearance import occupied_near, passage_width, turning_radius_cm
from actors.firmware.planning.planner import Plan, plan_path, traversable
from server.protocol import Frame, FrameError, make_frame, read_data

__all__ = [
    "NavOptions",
    "NavMemory",
    "Motion",
    "PathFollower",
    "NavBase",
    "plan_route",
    "route_points",
    "shorten",
    "with_obstacle",
    "passable_at",
    "RouteNav",
]


@dataclass(frozen=True, slots=True)
class NavOptions:
    """Tunables of navigation; defaults suit the 20 x 15 cm rovers of the game."""

    tick_s: float = 0.25
    """Period of navigation's own timer (NAV_TIMER) [s]."""
    pose_period_s: float = 0.75
    """Period of ``pose`` telemetry to the server [s] (about 1.3 Hz)."""
    step_cm: float = 20.0
    """Longest straight move of one ADP step [cm]."""
    waypoint_tol_cm: float = 5.0
    """An intermediate waypoint counts as reached this close [cm]."""
    goal_tol_cm: float = 2.0
    """The final waypoint counts as reached this close [cm]."""
    align_tol_deg: float = 3.0
    """Turn toward the next waypoint first when off by more than this [deg]."""
    heading_tol_deg: float = 2.0
    """Final heading counts as reached this close [deg]."""
    max_corrections: int = 6
    """Extra ADP steps allowed beyond the plan's length before giving up on a route."""
    motion_timeout_s: float = 4.0
    """A motion reporting nothing after this plus its nominal duration is stopped [s]."""
    pose_wait_s: float = 0.3
    """How long to wait for the pose at rest after a motion [s]."""
    send_timeout_s: float = 1.0
    """Longest wait for room in a neighbour's mailbox [s]."""
    speed_cm_s: float = 20.0
    """Assumed travel speed for motion timeouts [cm/s]."""
    robot_radius_cm: float | None = None
    """Turning radius for planning [cm]; None: the half-diagonal from the hardware spec."""
    plan_margin_cm: float = 3.0
    """Clearance kept from obstacles when planning [cm]."""
    spot_margin_cm: float = 5.0
    """Clearance all round a hiding spot, for turning [cm]."""
    spot_shift_cm: float = 30.0
    """A hiding spot that does not fit on the hider's map is moved to the nearest place
    within this that does (`nav_hiding`); 0 refuses it at once [cm]."""
    hide_near_cm: float = 30.0
    """A hider that cannot reach its spot but stands this close to it, in the open in
    sight of it on its map, hides where it stands (`nav_hiding`); 0 never [cm]."""
    narrow_margin_cm: float = 2.0
    """Clearance beyond half the body width in the last planning tier (narrow passages) [cm]."""
    replan_limit: int = 10
    """Replans after being blocked before a route is given up."""
    nudge_step_cm: float = 4.0
    """Lateral step of the search for a narrow passage missed by dead reckoning [cm]; it
    grows with the drift (`NavBase.drift_cm`) to at most ``nudge_step_max_cm``."""
    nudge_step_max_cm: float = 12.0
    """Largest lateral step of that search [cm]: below the free width a 35 cm gap leaves
    a 15 cm wide body (20 cm), so the offsets tried leave no hole between them. 12, not
    8: the seeker reached the gap 21-36 cm off in campaign games 1:23, 1:111, 1:191
    (measured with a truth log), beyond the +-24 cm six steps of 8 reach."""
    drift_per_cm: float = 0.04
    """How far dead reckoning may be off sideways per cm driven since the pose was last
    known (start, or a contact correction) [cm/cm]: measured 10-20 cm after 3-6 m of
    hiding or seeking in the gap room (turns are resolved to about 2 deg)."""
    max_nudges: int = 6
    """Sideways offsets tried per route, at most."""
    nudge_reach_cm: float = 50.0
    """Waypoints this close to the block point are shifted by a nudge [cm]."""
    tread_hold_s: float = 12.0
    """A tread fault (``NAV_TREAD_FAULT``) stops the motion and holds this long [s],
    doubled for a repeat within a minute: a slipping encoder or a weak motor lasts a
    few seconds to 20 s, and the small turns driven meanwhile may not be reported
    (a tread must travel about 5 cm for a short count to show) yet each turns the
    rover tens of degrees more than it believes (campaign game 1:24)."""
    tread_holds: int = 2
    """Holds in a row (each report within a minute of the last), at most; a further
    report ends the motion as blocked: a tread stalled against a wall looks the same
    as one that does not count, and holding would not free it."""
    tread_fault_deg: float = 10.0
    """How far one tread fault may have turned the heading unseen [deg]: the fault is
    reported after about 5 cm of a tread's travel, counted at most 0.65 of it."""
    tread_both_deg: float = 40.0
    """How far a turn that Motor Control ended with both treads silent (``NAV_TREAD_FAULT``
    value 4) may have turned unseen [deg]: it stops such a turn once its model says a
    tread went 3 cm without an Int E (26 deg on the 13 cm track), and the rover coasts
    on while it stops; 25-40 deg in the truth log of overlapping game 2:27 (both of the
    seeker's encoders stuck). Not corrected in the turn's direction: a rover jammed
    against a wall ends the same way having hardly turned."""
    tread_turn_fix_deg: float = 12.0
    """A single tread silent during a turn (``NAV_TREAD_FAULT`` 0 or 1): the heading is
    turned this much further in the turn's direction [deg]. A stuck encoder is not
    counted while the tread drives on (the rover turned 16.5 deg more than it believed
    in campaign game 1:11 with the encoder suffix, 28 deg in 2:27, truth logs); a
    stalled motor reports the same having turned as counted. 12, about half the
    first: the error left either way is under 12-16 deg, not 0 or 28."""
    tread_contact_s: float = 15.0
    """A short count in a move this soon after a block ends it as blocked, not held [s]."""
    tread_stop_s: float = 1.0
    """A tread fault that ends its motion as blocked waits this long before deciding [s]."""
    map_retry_s: float = 20.0
    """Waiting for the map this long asks the server again, the wait doubling each time
    up to ``map_retry_max_s`` [s]. A map lost on the way (a chunk corrupted on the link
    is refused and the map never completes: held-out campaign game 3:184 waited 550 s)
    or refused ("no map yet", "outbox full; request the map later") comes again; the
    doubling lets a slow transfer finish before it is asked for once more."""
    map_retry_max_s: float = 160.0
    """See ``map_retry_s``."""
    contact_fixes: int = 4
    """Pose corrections from contacts with mapped walls per route, at most (see `contact`)."""
    contact_max_shift_cm: float = 14.0
    """Largest sideways correction one contact, and all of a route's together, may make [cm]."""
    contact_max_turn_deg: float = 8.0
    """Largest heading correction one contact may make [deg]."""
    contact_max_along_cm: float = 15.0
    """A contact is searched along the heading as far as the drift, up to this [cm]
    (6 when the drift is smaller). With 6 alone, a block on a wall's flat face 9 cm
    further on was taken for the wall's end, and the fix cut the sideways doubt from
    29 to 3 cm while the rover was 24 cm off (campaign 1:31, truth log)."""
    probe_width_cm: float = 40.0
    """A block where the map's passage across the heading is narrower than this probes
    sideways at once (see `RouteNav._probe_plan`) [cm]."""
    probe_sidestep: bool = True
    """A probe's nudged route begins with a sidestep across the heading of the block
    (`RouteNav._with_sidestep`)."""
    probe_progress_cm: float = 25.0
    """A block this far from the last one starts a new sideways probe [cm]."""
    backoff_cm: float = 6.0
    """Reverse this far after being blocked [cm]."""
    backoff_repeat_cm: float = 20.0
    """Reverse this far after a second block at one place: room to come back sideways [cm]."""
    stall_turn_deg: float = 8.0
    """A back-off that ends blocked having turned more than this holds ``tread_hold_s``
    before the route goes on: a tread stalled (see `RouteNav._backoff_turned`) [deg]."""
    settle_s: float = 1.0
    """After (re)start, no motion is commanded before this [s]: the end of a motion
    the previous incarnation commanded arrives meanwhile and is ignored."""
    outbox: int = 16
    """Reports waiting for room in the pool or WiFly's mailbox, at most."""


@dataclass(slots=True)
class NavMemory:
    """What the server told navigation, in a retained RAM section (made by the rover tree).

    Like Motor Control's `PoseMemory`: C firmware keeps statics across a task
    restart, not across a rover reset. Only the server's small instructions
    live here (whether the game started, the origin, the destination being
    worked on); everything else a restarted navigation asks its neighbours for
    (pose, map) or the server (the map, again).
    """

    started: bool = False
    origin: tuple[float, float, float] | None = None
    goal: tuple[float, float, float | None] | None = None
    """The destination not yet answered (arrived / invalid_spot / found / not_found)."""
    within: float | None = None
    """The destination's ``within`` [cm]: how far round it a seeker searches (None: its
    IR range)."""


@dataclass(frozen=True, slots=True)
class Motion:
    """One Command A: ``kind`` is ``"turn"`` ([deg], CCW positive) or ``"move"`` ([cm])."""

    kind: str
    amount: float


class PathFollower:
    """The ADP loop's decision: from a pose to the next `Motion` along waypoints.

    Pure (no I/O, no clock): give it the pose after each motion.

    Args:
        waypoints: points to pass through (x, y) [cm], the last being the goal.
        heading_deg: heading to turn to at the goal, or None for any [deg].
        options: tolerances and step length.
    """

    def __init__(self, waypoints: list[tuple[float, float]] | tuple[tuple[float, float], ...],
                 heading_deg: float | None, options: NavOptions) -> None:
        if not waypoints:
            raise ValueError("waypoints must not be empty")
        self.waypoints = [(float(x), float(y)) for x, y in waypoints]
        self.heading_deg = heading_deg
        self.o = options
        self.index = 0
        """Index of the waypoint being driven to."""
        self.steps = 0
        """Motions handed out so far."""
        self._turned_from: float | None = None  # heading when the last motion, a turn, began

    @property
    def goal(self) -> tuple[float, float]:
        """The last waypoint [cm]."""
        return self.waypoints[-1]

    def remaining_cm(self, pose: Pose) -> float:
        """Distance along the remaining waypoints from ``pose`` [cm]."""
        pts = [(pose.x, pose.y), *self.waypoints[self.index:]]
        return sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))

    def budget(self, pose: Pose) -> int:
        """Most motions still reasonable: two per step of the remaining route, plus slack."""
        return 2 * math.ceil(self.remaining_cm(pose) / self.o.step_cm) + len(self.waypoints) \
            + self.o.max_corrections

    def next_motion(self, pose: Pose) -> Motion | None:
        """The next motion from ``pose``, or None when at the goal (and heading).

        A turn that changed nothing (smaller than Motor Control can resolve: one
        Int E is 0.5 cm of tread, about 2 [deg] on a 13 cm track) is not asked
        again: the leg is driven as it is, or the final heading accepted.
        """
        futile = self._turned_from is not None and abs(
            angle_diff_deg(pose.heading_deg, self._turned_from)) < 0.5
        self._turned_from = None
        last = len(self.waypoints) - 1
        while self.index <= last:
            tol = self.o.goal_tol_cm if self.index == last else self.o.waypoint_tol_cm
            if math.dist((pose.x, pose.y), self.waypoints[self.index]) <= tol:
                self.index += 1
            else:
                break
        if self.index > last:
            if self.heading_deg is None:
                return None
            err = angle_diff_deg(self.heading_deg, pose.heading_deg)
            if abs(err) <= self.o.heading_tol_deg or futile:
                return None
            self.steps += 1
            self._turned_from = pose.heading_deg
            return Motion("turn", err)
        tx, ty = self.waypoints[self.index]
        dist = math.hypot(tx - pose.x, ty - pose.y)
        bearing = math.degrees(math.atan2(ty - pose.y, tx - pose.x))
        err = angle_diff_deg(bearing, pose.heading_deg)
        # the tolerance shrinks with distance: at most ~1 cm lateral error per step
        tol = max(self.o.align_tol_deg,
                  math.degrees(math.atan2(1.0, max(min(dist, self.o.step_cm), 1e-6))))
        self.steps += 1
        if abs(err) > tol and not futile:
            self._turned_from = pose.heading_deg
            return Motion("turn", err)
        return Motion("move", min(dist, self.o.step_cm))


def plan_route(grid: GridMap, start: tuple[float, float], goal: tuple[float, float], *,
               radius_cm: float, margin_cm: float, unknown: str = "blocked",
               snap_radius_cm: float = 30.0) -> Plan | None:
    """A* from ``start`` to ``goal`` [cm] on the known part of ``grid`` (cropped: cheaper).

    Returns:
        The plan, or None when there is none (see `planner.plan_path`).
    """
    if grid.known_bounds() is None:
        return None
    k = math.ceil((radius_cm + margin_cm + snap_radius_cm) / grid.resolution_cm) + 2
    sub = grid.crop_known(margin_cells=k)
    return plan_path(sub, start, goal, robot_radius_cm=radius_cm, margin_cm=margin_cm,
                     unknown=unknown, snap_radius_cm=snap_radius_cm)  # type: ignore[arg-type]


def route_points(plan: Plan, start: tuple[float, float]) -> list[tuple[float, float]]:
    """The waypoints to drive: the plan's, without its first point when that is ``start``.

    (A start snapped out of an inflated obstacle keeps its first point: the
    rover must drive there first.)
    """
    pts = list(plan.waypoints_cm)
    if len(pts) > 1 and math.dist(pts[0], start) < 1.0:
        pts = pts[1:]
    return pts


def shorten(points: list[tuple[float, float]], start: tuple[float, float],
            cut_cm: float) -> list[tuple[float, float]]:
    """The polyline ``start`` -> ``points`` ending ``cut_cm`` before its end, along it [cm].

    Returns:
        The waypoints after ``start`` (the last one moved back along its leg);
        empty when the whole polyline is shorter than ``cut_cm``.
    """
    pts = [start, *points]
    remaining = sum(math.dist(a, b) for a, b in zip(pts, pts[1:], strict=False)) - cut_cm
    if remaining <= 0:
        return []
    out: list[tuple[float, float]] = []
    for a, b in zip(pts, pts[1:], strict=False):
        leg = math.dist(a, b)
        if leg >= remaining:
            t = remaining / leg if leg > 0 else 0.0
            out.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
            return out
        out.append(b)
        remaining -= leg
    return out


def with_obstacle(grid: GridMap, x: float, y: float, radius_cm: float) -> GridMap:
    """A copy of ``grid`` with a disc of occupied cells at (x, y) [cm].

    Used after NAV_MOTION_BLOCKED: something the map does not show (another
    rover) stands ahead, so the next plan must go round it.
    """
    cells = np.array(grid.cells, dtype=np.int8)
    ny, nx = cells.shape
    rows, cols = np.mgrid[0:ny, 0:nx]
    ox, oy = grid.origin_cm
    res = grid.resolution_cm
    d = np.hypot(ox + (cols + 0.5) * res - x, oy + (rows + 0.5) * res - y)
    cells[d <= radius_cm] = OCCUPIED
    return GridMap(cells, res, grid.origin_cm)


def passable_at(grid: GridMap, x: float, y: float, radius_cm: float, margin_cm: float) -> bool:
    """Whether the rover's centre may stand at (x, y) [cm] on ``grid``."""
    r, c = grid.world_to_cell(x, y)
    if not grid.contains(r, c):
        return False
    k = math.ceil((radius_cm + margin_cm) / grid.resolution_cm) + 2
    ny, nx = grid.shape
    r0, r1, c0, c1 = max(0, r - k), min(ny, r + k + 1), max(0, c - k), min(nx, c + k + 1)
    sub = grid.crop(r0, r1, c0, c1)
    ok = traversable(sub, radius_cm, margin_cm, "blocked")
    sr, sc = sub.world_to_cell(x, y)
    return bool(ok[sr, sc])


class NavBase(Actor):
    """Navigation common to every role: messages in, Command A and frames out.

    Subclasses implement the hooks (``on_start_cmd``, ``on_stop_cmd``,
    ``after_motion`` ...); this class owns the pose, the motion in flight, the
    telemetry and the path to the server.

    Args:
        role: ``mapper``, ``hider`` or ``seeker``.
        pool: the rover's buffer pool (bulk data by handle).
        spec: the rover's calibration constants (body size for clearance).
        options: tunables.
        memory: the retained record of the server's instructions; a fresh one
            (nothing survives a restart) when None.
    """

    role = ""

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec | None = None,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 addresses: Addresses | None = None) -> None:
        self.pool = pool
        self._addresses = addresses
        self.memory = memory if memory is not None else NavMemory()
        """Retained across restarts when the rover tree passes one (see `NavMemory`)."""
        self.spec = spec
        self.o = options or NavOptions()
        length = spec.length_cm if spec else 20.0
        width = spec.width_cm if spec else 15.0
        self.length_cm, self.width_cm = length, width
        self.radius_cm = (self.o.robot_radius_cm if self.o.robot_radius_cm is not None
                          else turning_radius_cm(length, width))
        self.pose: Pose = ORIGIN
        """Dead-reckoned pose, own frame (from Motor Control)."""
        self.pose_known = False
        """True once Motor Control published a pose to this incarnation."""
        self.origin: Pose | None = ORIGIN if self.role == "mapper" else None
        """Own start pose in the map frame (from the server's ``origin``)."""
        self.started = False
        """The server said ``start`` (and not ``stop`` since)."""
        self.state = "idle"
        """What navigation is doing (also the ``status`` state sent to the server)."""
        self.counters: dict[str, int] = {"dropped": 0, "bad_frames": 0, "blocked": 0,
                                         "timeouts": 0, "motions": 0, "nudges": 0,
                                         "contacts": 0, "stall_holds": 0}
        self.driven_cm = 0.0
        """Distance driven since the pose was last known (start, origin, correction) [cm]."""
        self.heading_err_deg = 0.0
        """Heading error that tread faults may have left unseen [deg] (see `on_tread_fault`)."""
        self._fault_base_cm = 0.0  # fault_drift_cm when the heading doubt last grew
        self._fault_from: tuple[float, float] | None = None  # own-frame xy at that moment
        self.tread_faults = 0
        """``NAV_TREAD_FAULT`` reports acted on."""
        self._hold_until = math.inf  # holding still after a tread fault until then
        self._tread_strikes = 0
        self._tread_last = -math.inf
        self._blocked_t = -math.inf  # when a motion last ended blocked [s]
        self._xy_mm: tuple[int, int] | None = None
        self._motion: Motion | None = None
        self.last_motion: Motion | None = None
        """The last motion commanded."""
        self.motion_from: Pose | None = None
        """The map-frame pose the last motion was commanded from."""
        self._motion_deadline = math.inf
        self._blocked = False
        self._done = 0.0
        self._pose_deadline = math.inf  # waiting for the pose at rest until then
        self._next_pose_report = 0.0
        self._settled_at = math.inf
        self._outbox: deque[tuple[int, Any]] = deque()

    # ------------------------------------------------------------------ names
    def _names(self) -> None:
        self.names = self._addresses or Addresses.beside(self.ctx.name, self.role)
        """The rover's actor names."""
        self.motor = self.names.motor
        self.wifly = self.names.wifly

    # ------------------------------------------------------------------ lifecycle
    async def on_start(self) -> None:
        self._names()
        self._settled_at = trio.current_time() + self.o.settle_s
        self.ctx.start_timer(self.o.tick_s, Message.uint(Cmd.NAV_TIMER, 0),
                             interval=self.o.tick_s)
        await self.post(self.motor, Message.uint(Cmd.MOTOR_STOP, 0))
        await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))
        cell = self.ctx.system.whereis(self.ctx.name)
        self.restarted = cell is not None and cell.last_exit is not None
        """True when this incarnation replaces one that exited (crash, hang)."""
        if self.memory.origin is not None:
            self.origin = Pose(*self.memory.origin)
        await self.status("restarted" if self.restarted else "idle")
        await self.on_restart()

    @property
    def can_move(self) -> bool:
        """The pose is known and the start has settled (see ``NavOptions.settle_s``)."""
        return self.pose_known and trio.current_time() >= self._settled_at

    async def on_restart(self) -> None:
        """Role-specific recovery at every start (ask neighbours for what was lost)."""

    # ------------------------------------------------------------------ dispatch
    async def handle(self, message: Any) -> Any:
        if not isinstance(message, Message):
            return None
        cmd = message.command
        if cmd == Cmd.NAV_POSE_XY:
            self._xy_mm = message.as_pair()
        elif cmd == Cmd.NAV_POSE_HEADING:
            await self._on_pose(float(message.value))
        elif cmd == Cmd.NAV_MOTION_DONE or cmd == Cmd.NAV_MOTION_BLOCKED:
            await self._on_motion_end(cmd == Cmd.NAV_MOTION_BLOCKED, float(message.value))
        elif cmd == Cmd.NAV_TIMER:
            await self._on_tick()
        elif cmd == Cmd.NAV_TREAD_FAULT:
            await self.on_tread_fault(TreadFault(int(message.value)))
        elif cmd == Cmd.NAV_NET:
            frame = self._take(message)
            if isinstance(frame, Frame):
                await self._on_frame(frame)
        elif cmd == Cmd.NAV_MAP_DOWNLOAD:
            grid = self._take(message)
            if isinstance(grid, GridMap):
                await self.on_map_download(grid)
        elif cmd == Cmd.NAV_MAP_UPDATE:
            grid = self._take(message)
            if isinstance(grid, GridMap):
                await self.on_map_update(grid)
        elif cmd == Cmd.NAV_SCAN_COUNT:
            await self.on_scan_count(int(message.value))
        elif cmd == Cmd.NAV_IR:
            await self.on_ir(int(message.value) != 0)
        elif cmd == Cmd.NAV_LINK:
            await self.on_link(int(message.value) != 0)
        elif cmd == Cmd.NAV_MAP_LOST:
            await self.on_map_lost()
        return None

    def _take(self, message: Message) -> Any:
        if message.type != ValueType.HANDLE:
            self.counters["bad_frames"] += 1
            return None
        try:
            return self.pool.take(int(message.value))
        except KeyError:
            self.counters["bad_frames"] += 1
            return None

    # ------------------------------------------------------------------ pose
    @property
    def map_pose(self) -> Pose:
        """The pose in the map frame (own frame while no origin is known)."""
        return compose(self.origin, self.pose) if self.origin is not None else self.pose

    async def _on_pose(self, heading: float) -> None:
        if self._xy_mm is not None:
            x, y = self._xy_mm
            self.pose = Pose(x / 10.0, y / 10.0, heading)
        else:
            self.pose = Pose(self.pose.x, self.pose.y, heading)
        self._xy_mm = None
        self.pose_known = True
        if self._pose_deadline < math.inf and self._motion is None and self._hold_until == math.inf:
            self._pose_deadline = math.inf
            await self.after_motion(self._blocked, self._done)

    # ------------------------------------------------------------------ motion
    @property
    def moving(self) -> bool:
        """A motion is in flight, or its pose at rest is awaited."""
        return self._motion is not None or self._pose_deadline < math.inf or \
            self._hold_until < math.inf

    async def command(self, motion: Motion) -> None:
        """Send one Command A and wait (by events) for its end; `after_motion` follows."""
        code = Cmd.MOTOR_TURN if motion.kind == "turn" else Cmd.MOTOR_MOVE
        self._motion = motion
        self.last_motion = motion
        self.motion_from = self.map_pose
        self.counters["motions"] += 1
        if motion.kind == "move":
            self.driven_cm += abs(motion.amount)
        nominal = abs(motion.amount) / self.o.speed_cm_s if motion.kind == "move" \
            else abs(motion.amount) / 90.0
        self._motion_deadline = trio.current_time() + self.o.motion_timeout_s + nominal
        if not await self.post(self.motor, Message.float(code, float(motion.amount))):
            self._motion_deadline = trio.current_time()  # the tick treats it as blocked

    async def stop_motor(self) -> None:
        """MOTOR_STOP, and forget the motion in flight (its end is ignored)."""
        self._motion = None
        self._motion_deadline = math.inf
        self._pose_deadline = math.inf
        self._hold_until = math.inf
        await self.post(self.motor, Message.uint(Cmd.MOTOR_STOP, 0))

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control saw a driven tread that does not count, or counts short
        (``NAV_TREAD_FAULT``, a `TreadFault`): dead reckoning
        is turning the heading where the rover does not, or the other way round.
        `TreadFault.BOTH_SILENT` (sent only for a turn that ended blocked without an Int E)
        is held for like any turn, and doubts the heading by ``tread_both_deg``, not
        ``tread_fault_deg``: nothing counted, so the whole unseen turn is error.
        One tread silent in a turn also turns the believed heading by
        ``tread_turn_fix_deg`` in the turn's direction (a stuck encoder's unseen turn).

        Why stop and hold: Motor Control ends a motion by the counts, so each
        motion driven on a faulty encoder turns the rover further off the
        heading it believes (campaign game 1:24: 90-100 deg after an 8.8 s
        slip). Stopping at the report keeps what one motion costs to about
        ``tread_fault_deg``; the hold (``tread_hold_s``, doubled for a repeat
        within a minute, at most ``tread_holds`` in a row, then a report ends
        the motion as blocked) waits for a passing fault to clear, as nothing
        can tell that while standing still. Only turns are held for: in a
        straight move a tread scraping along a wall stalls and reports the
        same (healthy hall 3: 36 s held for nothing), so a move ends as
        blocked and the route's block handling (contact fix, back-off) follows.
        Both treads short in a move where a mapped wall may touch the body
        (`_wall_within_drift`) are a slide along it: nothing is stopped or held.
        The error already made is not seen:
        ``heading_err_deg`` grows by ``tread_fault_deg``, so `drift_cm` grows
        with every cm driven afterwards (the seeker's search ring widens, the
        nudges step wider). After the hold, `after_motion` decides again from
        the pose, as after a motion that ended.
        """
        if self._motion is None:
            return  # standing (or holding) already: the report is of a motion given up
        now = trio.current_time()
        if fault == TreadFault.BOTH_SHORT and self._motion.kind == "move" \
                and now - self._blocked_t > self.o.tread_contact_s and self._wall_within_drift():
            return  # a slide along a wall the rover may touch: the move goes on (hall 5)
        self._tread_strikes = self._tread_strikes + 1 if now - self._tread_last <= 60.0 else 1
        self._tread_last = now
        both = fault.both
        self.tread_faults += 1
        turning = self._motion.kind == "turn"
        if turning or not both:  # both alike in a straight move turn nothing unseen
            self._fault_base_cm, self._fault_from = self.fault_drift_cm, (self.pose.x, self.pose.y)
            self.heading_err_deg += self.o.tread_both_deg if both else self.o.tread_fault_deg
        if turning and not (both or fault.counts_short):
            # one tread silent in a turn (see tread_turn_fix_deg)
            p = self.map_pose
            fix = math.copysign(self.o.tread_turn_fix_deg, self._motion.amount)
            self.correct_pose(Pose(p.x, p.y, p.heading_deg + fix), sideways_known=False)
        await self.stop_motor()
        # a short count in a move holds, unless the rover was blocked just before: in
        # contact with a wall, scraping along it counts short as well (campaign 1:23)
        held_move = fault.counts_short and now - self._blocked_t > self.o.tread_contact_s
        if (not turning and not held_move) or self._tread_strikes > self.o.tread_holds:
            # a short hold all the same: the stopped motion's last pose and end arrive
            # meanwhile and are ignored, and the decision uses the pose at rest
            self._blocked, self._done = True, 0.0
            self.counters["blocked"] += 1
            self._hold_until = now + self.o.tread_stop_s
            return
        hold = self.o.tread_hold_s * 2.0 ** (self._tread_strikes - 1)
        self._blocked, self._done = False, 0.0
        self._hold_until = now + hold
        side = "both treads" if both else f"the {fault.side} tread"
        if fault.counts_short:
            kind = "count short" if both else "counts short"
        else:
            kind = "do not count" if both else "does not count"
        await self.status(self.state, f"{side} {kind}; holding {hold:.0f} s")

    def _wall_within_drift(self) -> bool:
        """Hook: a mapped wall may touch the body (see `RouteNav._wall_within_drift`).
        Without the server's map (the mapper) there is none to know of."""
        return False

    async def _on_motion_end(self, blocked: bool, done: float) -> None:
        if self._motion is None:
            return  # the end of a motion nobody waits for (stopped, or a dead incarnation's)
        self._motion = None
        self._motion_deadline = math.inf
        self._blocked, self._done = blocked, done
        if blocked:
            self.counters["blocked"] += 1
            self._blocked_t = trio.current_time()
        self._pose_deadline = trio.current_time() + self.o.pose_wait_s
        await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))

    async def after_motion(self, blocked: bool, done: float) -> None:
        """Hook: the motion ended (``blocked`` when the motor gave up) and the pose is fresh."""

    @property
    def fault_drift_cm(self) -> float:
        """Sideways error the doubted heading (``heading_err_deg``) may have made since
        the pose was last known [cm].

        A heading off by e turns everything driven after it about the point where
        it arose, so the position is off by at most e [rad] times the straight
        distance from that point, however the rover got there. Not the distance
        driven: a rover probing a gap goes back and forth at one place, and
        summing each move's length times sin(e) grew the doubt by about 7 cm a
        probe without end (campaign 1:127: one 10 deg report, 292 cm of believed
        drift 2 m of probing later; 1:183 in session 5: 235 cm). The pose is
        Motor Control's own-frame one, which a correction of the origin leaves
        continuous.
        """
        if self._fault_from is None:
            return self._fault_base_cm
        moved = math.dist(self._fault_from, (self.pose.x, self.pose.y))
        return self._fault_base_cm + moved * math.radians(min(90.0, self.heading_err_deg))

    def _forget_fault_drift(self) -> None:
        """The pose is known again: the doubted heading's sideways error starts from here."""
        self._fault_base_cm, self._fault_from = 0.0, (self.pose.x, self.pose.y)

    @property
    def drift_cm(self) -> float:
        """How far the dead-reckoned pose may be off sideways now [cm] (at least 3)."""
        return max(3.0, self.o.drift_per_cm * self.driven_cm + self.fault_drift_cm)

    # ------------------------------------------------------------------ timer
    async def _on_tick(self) -> None:
        now = trio.current_time()
        if self._hold_until < math.inf:
            if now >= self._hold_until:  # the hold is over: decide again from the pose at rest
                self._hold_until = math.inf
                self._pose_deadline = now + self.o.pose_wait_s
                await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))
        elif self._motion is not None and now >= self._motion_deadline:
            self.counters["timeouts"] += 1
            await self.post(self.motor, Message.uint(Cmd.MOTOR_STOP, 0))
            self._motion = None
            self._motion_deadline = math.inf
            self._blocked, self._done = True, 0.0
            self._pose_deadline = now + self.o.pose_wait_s
            await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))
        elif self._motion is None and now >= self._pose_deadline:
            self._pose_deadline = math.inf  # no fresh pose: decide with the last one
            await self.after_motion(self._blocked, self._done)
        if self._outbox:
            await self._flush_outbox()
        if now >= self._next_pose_report and self.pose_known and (
                self.origin is not None or self.role == "mapper"):
            self._next_pose_report = now + self.o.pose_period_s
            p = self.map_pose
            await self.send_frame(make_frame("pose", {"x": round(p.x, 1), "y": round(p.y, 1),
                                                      "heading": round(p.heading_deg, 1)}),
                                  reliable=False)
        await self.on_tick(now)

    async def on_tick(self, now: float) -> None:
        """Hook: navigation's periodic tick [s of trio time]."""

    # ------------------------------------------------------------------ server
    async def _on_frame(self, frame: Frame) -> None:
        try:
            data = read_data(frame)
        except FrameError:
            self.counters["bad_frames"] += 1
            return
        cmd = frame.cmd
        if cmd == "start":
            self.started = self.memory.started = True
            await self.on_start_cmd()
        elif cmd == "stop":
            self.started = self.memory.started = False
            self.memory.goal = None
            await self.on_stop_cmd()
        elif cmd == "origin":
            self.origin = Pose(data.x, data.y, data.heading)
            self.memory.origin = (data.x, data.y, data.heading)
            self.driven_cm = 0.0
            self._forget_fault_drift()
        elif cmd == "destination":
            await self.on_destination(data.x, data.y, data.heading, data.within)

    async def on_start_cmd(self) -> None:
        """Hook: the server said ``start``."""

    async def on_stop_cmd(self) -> None:
        """Hook: the server said ``stop``; the default stops the motor and goes idle."""
        await self.stop_motor()
        await self.set_state("idle", "stopped by the server")

    async def on_destination(self, x: float, y: float, heading: float | None,
                             within: float | None = None) -> None:
        """Hook: a ``destination`` in the map frame [cm, deg] (``within`` [cm]: see
        `NavMemory.within`)."""

    async def on_map_download(self, grid: GridMap) -> None:
        """Hook: the server's map arrived (map frame)."""

    async def on_map_update(self, grid: GridMap) -> None:
        """Hook: Map Management published a snapshot (mapper)."""

    async def on_scan_count(self, count: int) -> None:
        """Hook: Map Management integrated ``count`` scan batches so far (mapper)."""

    async def on_ir(self, in_range: bool) -> None:
        """Hook: the IR decision (seeker)."""

    async def on_link(self, up: bool) -> None:
        """Hook: the WiFly link went up or down."""

    async def on_map_lost(self) -> None:
        """Hook: Map Management restarted empty (mapper)."""

    async def set_state(self, state: str, detail: str | None = None, **extra: Any) -> None:
        """Change phase and report it with a ``status`` frame."""
        self.state = state
        await self.status(state, detail, **extra)

    async def status(self, state: str, detail: str | None = None, **extra: Any) -> None:
        """Send a ``status`` frame (unreliable telemetry)."""
        data: dict[str, Any] = {"state": state[:32]}
        if detail:
            data["detail"] = detail[:200]
        data.update(extra)
        await self.send_frame(make_frame("status", data), reliable=False)

    async def report(self, cmd: str, data: Any = None) -> None:
        """Send a reliable frame (a game report or request) through WiFly."""
        await self.send_frame(make_frame(cmd, data), reliable=True)

    async def send_frame(self, frame: Frame, *, reliable: bool) -> bool:
        """Hand ``frame`` to WiFly by handle; reliable ones wait in a bounded outbox on failure."""
        code = Cmd.WIFLY_SEND if reliable else Cmd.WIFLY_SEND_UNRELIABLE
        if self._outbox and reliable:
            return self._queue(code, frame)
        if await self.put_and_post(self.wifly, code, frame):
            return True
        return self._queue(code, frame) if reliable else False

    async def send_map(self, grid: GridMap) -> bool:
        """WIFLY_SEND_MAP: upload ``grid`` in chunks, reliably (queued on failure)."""
        if self._outbox:
            return self._queue(Cmd.WIFLY_SEND_MAP, grid)
        if await self.put_and_post(self.wifly, Cmd.WIFLY_SEND_MAP, grid):
            return True
        return self._queue(Cmd.WIFLY_SEND_MAP, grid)

    def _queue(self, code: int, obj: Any) -> bool:
        if len(self._outbox) >= self.o.outbox:
            self.counters["dropped"] += 1
            return False
        self._outbox.append((code, obj))
        return True

    async def _flush_outbox(self) -> None:
        while self._outbox:
            code, obj = self._outbox[0]
            if not await self.put_and_post(self.wifly, code, obj):
                return
            self._outbox.popleft()

    async def put_and_post(self, name: str, code: int, obj: Any) -> bool:
        """Put ``obj`` in the pool and post its handle; False (slot freed) on failure."""
        try:
            handle = self.pool.put(obj)
        except PoolExhausted:
            self.counters["dropped"] += 1
            return False
        if await self.post(name, Message.handle(code, handle)):
            return True
        self.pool.take(handle)
        return False

    async def post(self, name: str, message: Message) -> bool:
        """Send to a neighbour, waiting at most ``send_timeout_s`` for room; False if not sent."""
        with trio.move_on_after(self.o.send_timeout_s):
            if await self.ctx.cast(name, message):
                return True
        self.counters["dropped"] += 1
        return False


class RouteNav(NavBase):
    """Navigation on a map downloaded from the server: the hider's and the seeker's base.

    Flow: ``start`` -> ``map_request`` -> NAV_MAP_DOWNLOAD; ``origin`` and
    ``destination`` frames are kept as they come (the server sends origin,
    start and destination together, before the map has arrived); once map,
    origin and a destination are all known, `on_goal` runs. `goto` plans with
    A* on the map (obstacles inflated by the rover's radius) and follows the
    route with the ADP loop. When the motor reports blocked, something the map
    does not show is ahead (another rover): it is added to a working copy of the
    map, the rover backs off and replans, at most ``replan_limit`` times.
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
        self.stop_short_cm = 0.0
        """The current route ends this far before its goal [cm] (see `goto`)."""
        self.tier: tuple[float, float] | None = None
        """(radius, margin) [cm] of the planning tier the current route used (`plan_tiers`)."""
        self._replan = False  # replan after the backoff in flight
        self._last_block: tuple[float, float, float] | None = None  # (x, y, heading) of a block
        self._nudge: tuple[float, float, float, float] | None = None  # (dx, dy, cx, cy) [cm]
        self._anchor: tuple[float, float, float] | None = None  # the block nudges start from
        self._nudges = 0  # nudges tried on this route
        self._contact_fixes = 0  # pose corrections from contacts on this route
        self._contact_shift = 0.0  # their sideways sum [cm]
        self._probe = False  # the block in flight was in a narrow passage: probe sideways
        self._nudge_off = 0.0  # the last sideways offset tried [cm], signed (left +)
        self._nudge_first = 1.0  # the side a series of nudges tries first
        self._sidestep = False  # the nudge in flight starts with a sidestep (`_nudged`)
        self.map_requests = 0
        """``map_request`` frames sent (see ``NavOptions.map_retry_s``)."""
        self._map_wait = 0.0  # the wait before the next request [s]
        self._map_again = math.inf  # ask again at this time, if still waiting

    # ------------------------------------------------------------------ server
    async def on_start_cmd(self) -> None:
        if self.map is None:
            await self._request_map(self.o.map_retry_s)
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
            await self._request_map(min(2.0 * self._map_wait, self.o.map_retry_max_s))
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
        self.replans = 0
        self._last_block, self._nudge, self._nudges, self._anchor = None, None, 0, None
        self._contact_fixes, self._contact_shift = 0, 0.0
        self._probe, self._nudge_off = False, 0.0
        if not self._plan():
            return False
        await self.set_state("driving", f"to ({goal[0]:.0f}, {goal[1]:.0f})")
        await self._step()
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
        if self._anchor is not None and math.dist(self._anchor[:2], (p.x, p.y)) > \
                2.0 * self.o.nudge_reach_cm:
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

    def _nudged(self, pts: list[tuple[float, float]]) -> list[tuple[float, float]] | None:
        """``pts`` with the nudge applied: waypoints near the block point shifted sideways;
        when none is near (a long corridor), a shifted waypoint ``nudge_reach_cm`` ahead of
        the block point is driven to first. None when a shifted point is not on free
        ground of the server's map: the search went wider than the passage."""
        assert self._nudge is not None and self._anchor is not None
        dx, dy, cx, cy = self._nudge
        reach = self.o.nudge_reach_cm
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
        face, which the encoders do not see (campaign game 1:111: from 26 to 60 cm off
        within a few probes). A sidestep moves the rover across first, square to the
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
        (offsets whose points do not fit are skipped), at most ``max_nudges``
        per route and bounded by ``replan_limit`` blocks.
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
        step = min(self.o.nudge_step_max_cm, max(self.o.nudge_step_cm, self.drift_cm / 3.0))
        while self._nudges < self.o.max_nudges:
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
        if self.replans > self.o.replan_limit:
            await self._give_up(f"{why} {self.replans} times")
            return
        assert self.work_map is not None
        p = self.map_pose
        if why == "blocked" and self._backoff_turned():
            # a tread stalled: backing off again only spins the rover where it stands
            # (campaign game 1:131: ten blocks in 12 s of a 16 s stall); wait for it
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
                back = self.o.backoff_repeat_cm
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
        more than ``stall_turn_deg``: one tread drives, the other does not. Backing away
        from a wall is free ground, so a turn there is no wall's doing."""
        start = self._backoff_start()
        if start is None:
            return False
        turned = abs(angle_diff_deg(self.map_pose.heading_deg, start.heading_deg))
        return turned > self.o.stall_turn_deg

    def _contact_fix(self) -> bool:
        """After a straight move ended blocked: correct the pose to where the body
        touches a wall of the server's map (`contact.locate_contact`).

        Returns:
            True when the pose was corrected. False when the dead-reckoned pose
            already explains the block, when no pose within reach does (an
            obstacle the map does not show), when the contact is ambiguous
            (left or right alike), or when ``contact_fixes`` corrections were
            made on this route already.
        """
        m, start = self.last_motion, self.motion_from
        if (m is None or m.kind != "move" or m.amount == 0 or start is None or self.map is None
                or self._contact_fixes >= self.o.contact_fixes):
            return False
        p = self.map_pose
        direction = 1 if m.amount > 0 else -1
        side = stalled_side(angle_diff_deg(p.heading_deg, start.heading_deg), direction)
        drift = min(self.drift_cm, 3.0 * self.o.contact_max_shift_cm)
        c = locate_contact(self.map, p, length_cm=self.length_cm, width_cm=self.width_cm,
                           direction=direction, side=side,
                           max_shift_cm=self.o.contact_max_shift_cm,
                           max_turn_deg=self.o.contact_max_turn_deg,
                           max_along_cm=max(6.0, min(drift, self.o.contact_max_along_cm)),
                           ambiguity_cm=drift,
                           other_shift_cm=self.o.contact_max_shift_cm + drift)
        if c is None or c.ambiguous or not c.needed or \
                self._contact_shift + abs(c.shift_cm) > self.o.contact_max_shift_cm:
            return False
        self._contact_shift += abs(c.shift_cm)
        self.correct_pose(c.pose, sideways_known=not c.sideways_free)
        self._contact_fixes += 1
        self.counters["contacts"] += 1
        return True

    def _in_passage(self) -> bool:
        """The last forward move was blocked where the map's walls are close on both sides
        (narrower than ``probe_width_cm`` across the heading), at the body's centre or at
        its nose: a rover stopped at a gap's mouth has only its nose in the gap."""
        m = self.last_motion
        if m is None or m.kind != "move" or m.amount <= 0 or self.map is None:
            return False
        p = self.map_pose
        h = math.radians(p.heading_deg)
        nose = 0.5 * self.length_cm
        for x, y in ((p.x, p.y), (p.x + nose * math.cos(h), p.y + nose * math.sin(h))):
            w = passage_width(self.map, x, y, p.heading_deg, max_cm=self.o.probe_width_cm)
            if w is not None and w < self.o.probe_width_cm:
                return True
        return False

    def _wall_within_drift(self) -> bool:
        """A mapped wall lies within the body's radius plus ``drift_cm`` of the believed
        position: the rover may be touching it, though it believes itself clear.

        Why: both treads counting short in a move read the same whether both encoders
        slip (the rover goes 2-3 times what counts, campaign 1:49: held for) or the
        rover slides along a wall it met at an angle (healthy hall 5: the hider 45 cm
        from where it believed after a 7 m leg, sliding along the stage's face at 0.29;
        three holds and a block left it 62 cm from its spot, not found). Only the
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
        """A nudge series is on and this block is within ``nudge_reach_cm`` of its anchor:
        the nudged route met a wall again at the passage it looks for.

        Why: blocked short of the mouth by dead reckoning (the nose a few cm before
        it, or on the face beside it), the block was taken for an obstacle the map
        does not show; learned inside a mapped wall it changed nothing, and the same
        offset was driven again and again (overlapping campaign 2:19, truth log: the
        +24 cm offset four times, 2 cm short of passing, until the replan limit).
        The next offset is the search's next step."""
        if self._nudge is None or self._anchor is None:
            return False
        p = self.map_pose
        return math.dist((p.x, p.y), self._anchor[:2]) <= self.o.nudge_reach_cm

    def _probe_plan(self) -> bool:
        """Plan after a block in a narrow passage: the route shifted sideways at once.

        Dead reckoning cannot tell which wall the rover scraped (its heading
        error is invisible to it), so it tries the nudge series (`_nudged_plan`)
        without first learning an obstacle, which in a passage would only close
        it. Once a probe made progress (the next block is ``probe_progress_cm``
        on), a new series starts on the side that helped.
        """
        p = self.map_pose
        if self._anchor is None or self._progress(p) > self.o.probe_progress_cm:
            self._anchor, self._nudge, self._nudges = self._last_block, None, 0
        self._sidestep = self.o.probe_sidestep
        try:
            return self._nudged_plan()
        finally:
            self._sidestep = False

    def _progress(self, p: Pose) -> float:
        """How far ``p`` lies beyond the series' anchor along the anchor's heading [cm].

        Along, not straight-line: a nudge moves the block point across the heading
        by its own offset (up to 3 x ``nudge_step_max_cm``), and a contact fix
        moves it a few cm more; counting that as progress restarted the series
        around the nudged point, 25 cm to the wrong side (campaign 1:39, truth
        log: the -25 cm offset that would have passed was never tried)."""
        assert self._anchor is not None
        bx, by, bh = self._anchor
        h = math.radians(bh)
        return (p.x - bx) * math.cos(h) + (p.y - by) * math.sin(h)

    def correct_pose(self, target: Pose, *, sideways_known: bool = True) -> None:
        """Make the map-frame pose ``target`` by moving the origin (own frame -> map frame).

        Motor Control's dead reckoning is left as it is: its pose stays
        continuous, and every later pose is read through the corrected
        origin. The retained memory keeps it across a restart. ``sideways_known``
        False (a contact that measured only the distance along the heading) keeps
        the sideways uncertainty (`drift_cm`) as it was.
        """
        origin = compose(target, inverse(self.pose))
        self.origin = origin
        if sideways_known:
            self.driven_cm = 0.0
            self._forget_fault_drift()
        self.memory.origin = (origin.x, origin.y, origin.heading_deg)

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
