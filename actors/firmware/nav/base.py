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
    Each rover's dead reckoning starts at (0, 0) @ 0 [deg] (its own frame), and
    Motor Control publishes it in that frame. The map frame is the mapper's start
    frame; navigation holds the map -> own frame transform, its ``origin``, so
    ``map = compose(origin, own)``: the hider and seeker start from the server's
    ``origin`` (their start pose in the map frame) and move it by their pose
    belief; the mapper starts from the identity and takes Map Management's scan
    matching correction (``NAV_MAP_ORIGIN_*``). The origin is kept in the retained
    `NavMemory`. Maps, destinations and reports are in the map frame; motions are
    relative, so they need no conversion.

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
from typing import Any

import trio

from actors import Actor, BufferPool, Message, PoolExhausted, ValueType
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.ir import IR_IN, IR_PINNED
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import MAPPER, HardwareSpec
from actors.firmware.nav.controller import Controller, MotionEnd, Tick
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route import Motion
from actors.firmware.origin_wire import MM, PoseHalves, xy_half
from actors.firmware.planning.clearance import turning_radius_cm
from server.protocol import Frame, FrameError, make_frame, read_data
from server.protocol.grid_map import GridMap
from server.protocol.pose import ZERO_POSE, Pose, compose

__all__ = ["NavBase", "POSE_REPORT_TICKS", "SEND_TIMEOUT_S", "OUTBOX"]

# Fixed timings and bounds of the ADP loop's messaging: what the firmware's queues and
# links need, not properties of the rover.
POSE_REPORT_TICKS = 3
"""``pose`` telemetry to the server goes every this many ticks (``NavOptions.tick_s``):
every 0.75 s, about 1.3 Hz."""
SEND_TIMEOUT_S = 1.0
"""Longest wait for room in a neighbour's mailbox [s]."""
OUTBOX = 16
"""Reports waiting for room in the pool or WiFly's mailbox, at most."""


class NavBase(Actor):
    """Navigation common to every role: messages in, Command A and frames out.

    Subclasses implement the hooks (``on_start_cmd``, ``on_stop_cmd``,
    ``after_motion`` ...); this class owns the pose, the motion in flight (its
    `controller.Controller`), the telemetry and the path to the server.

    Args:
        role: ``mapper``, ``hider`` or ``seeker``.
        pool: the rover's buffer pool (bulk data by handle).
        spec: the rover's calibration constants (body size for clearance).
        options: tunables.
        memory: the retained record of the server's instructions; a fresh one
            (nothing survives a restart) when None.
    """

    role = ""
    origin_from_server = True
    """Whether the server's ``origin`` sets the origin (not on the mapper: see `mapper`)."""

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 addresses: Addresses | None = None) -> None:
        self.pool = pool
        self._addresses = addresses
        self.memory = memory if memory is not None else NavMemory()
        """Retained across restarts when the rover tree passes one (see `NavMemory`)."""
        self.spec = spec
        self.o = options or NavOptions()
        self.length_cm, self.width_cm = spec.length_cm, spec.width_cm
        self.radius_cm = turning_radius_cm(spec.length_cm, spec.width_cm)
        """Turning radius for planning [cm]: the body's half-diagonal."""
        self.pose: Pose = ZERO_POSE
        """Dead-reckoned pose, own frame (from Motor Control)."""
        self.pose_known = False
        """True once Motor Control published a pose to this incarnation."""
        self.origin: Pose | None = ZERO_POSE if self.role == MAPPER else None
        """The map -> own frame transform: the own frame's (0, 0) @ 0 in the map frame
        (see Frames in the module docstring)."""
        self.started = False
        """The server said ``start`` (and not ``stop`` since)."""
        self.state = "idle"
        """What navigation is doing (also the ``status`` state sent to the server)."""
        self.counters: dict[str, int] = {"dropped": 0, "bad_frames": 0, "blocked": 0,
                                         "timeouts": 0, "motions": 0, "nudges": 0,
                                         "contacts": 0, "stall_holds": 0}
        self.tread_faults = 0
        """``NAV_TREAD_FAULT`` reports acted on."""
        self.controller = Controller(self.o.speed_cm_s)
        """The motion in flight, its watchdog and holds (the ADP loop's state)."""
        self._pose_halves = PoseHalves(MM)  # NAV_POSE_XY waiting for its heading
        self.last_motion: Motion | None = None
        """The last motion commanded."""
        self.motion_from: Pose | None = None
        """The map-frame pose the last motion was commanded from."""
        self.odometry_from: Pose | None = None
        """Motor Control's own-frame pose when the last motion was commanded: what its
        counts moved from (the map-frame ``motion_from`` also moves with the origin)."""
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
            self._pose_halves.take_xy(message)
        elif cmd == Cmd.NAV_POSE_HEADING:
            pose = self._pose_halves.take_heading(message, unchanged=self.pose)
            if pose is not None:
                await self._on_pose(pose)
        elif cmd == Cmd.NAV_MOTION_DONE or cmd == Cmd.NAV_MOTION_BLOCKED:
            await self._on_motion_end(cmd == Cmd.NAV_MOTION_BLOCKED, float(message.value))
        elif cmd == Cmd.NAV_TIMER:
            await self._on_tick()
        elif cmd == Cmd.NAV_TREAD_FAULT:
            await self.on_tread_fault(TreadFault(int(message.value)))
        elif cmd == Cmd.NAV_TREAD_DRIVEN:
            self.note_tread_driven(*xy_half(message, MM))
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
            value = int(message.value)
            await self.on_ir(value == IR_IN, pinned=value == IR_PINNED)
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

    def set_origin(self, origin: Pose) -> None:
        """Make ``origin`` the map -> own frame transform, and retain it (`NavMemory`)."""
        self.origin = origin
        self.memory.origin = (origin.x, origin.y, origin.heading_deg)

    async def _on_pose(self, pose: Pose) -> None:
        self.pose = pose
        self.pose_known = True
        if self.controller.in_flight is None:
            self.on_pose_at_rest()
        if self.controller.at_rest():
            end = self.controller.end
            await self.after_motion(end.blocked, end.done)

    # ------------------------------------------------------------------ motion
    @property
    def moving(self) -> bool:
        """A motion is in flight, or its pose at rest is awaited, or a hold is on."""
        return self.controller.busy

    async def command(self, motion: Motion) -> None:
        """Send one Command A and wait (by events) for its end; `after_motion` follows."""
        code = Cmd.MOTOR_TURN if motion.kind == "turn" else Cmd.MOTOR_MOVE
        self.last_motion = motion
        self.motion_from = self.map_pose
        self.odometry_from = self.pose
        self.counters["motions"] += 1
        self.controller.begin(motion, trio.current_time())
        if not await self.post(self.motor, Message.float(code, float(motion.amount))):
            self.controller.not_sent(trio.current_time())

    async def stop_motor(self) -> None:
        """MOTOR_STOP, and forget the motion in flight (its end is ignored)."""
        self.controller.forget()
        await self.post(self.motor, Message.uint(Cmd.MOTOR_STOP, 0))

    async def hold_still(self, until: float, detail: str) -> None:
        """Hold still until ``until`` [s] and say ``detail``: the motion that ends meanwhile
        counts as not blocked, and the decision after the hold uses the pose at rest."""
        self.controller.hold(until)
        await self.status(self.state, detail)

    def stop_blocked(self, wait_s: float) -> None:
        """The motion was stopped (`stop_motor`) for a tread report: it counts as blocked,
        decided ``wait_s`` [s] from now with the pose at rest."""
        self.counters["blocked"] += 1
        self.controller.stop_blocked(trio.current_time(), wait_s)

    async def _on_motion_end(self, blocked: bool, done: float) -> None:
        if not self.controller.ended(blocked, done, trio.current_time()):
            return  # the end of a motion nobody waits for (stopped, or a dead incarnation's)
        if blocked:
            self.counters["blocked"] += 1
        await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Hook: Motor Control reported a tread during the motion in flight
        (``NAV_TREAD_FAULT``)."""

    def note_tread_driven(self, left_cm: float, right_cm: float) -> None:
        """Hook: Motor Control's drive model says how far each tread went [cm] in the
        motion that is ending (``NAV_TREAD_DRIVEN``: after a tread report, or a turn
        that ended blocked)."""

    async def after_motion(self, blocked: bool, done: float) -> None:
        """Hook: the motion ended (``blocked`` when the motor gave up) and the pose is fresh."""

    # ------------------------------------------------------------------ timer
    async def _on_tick(self) -> None:
        now = trio.current_time()
        due = self.controller.tick(now)
        if due == Tick.HOLD_OVER:  # decide again from the pose at rest
            await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))
        elif due == Tick.TIMED_OUT:
            self.counters["timeouts"] += 1
            await self.post(self.motor, Message.uint(Cmd.MOTOR_STOP, 0))
            await self.post(self.motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))
        elif due == Tick.POSE_LATE:  # no fresh pose: decide with the last one
            end: MotionEnd = self.controller.end
            await self.after_motion(end.blocked, end.done)
        if self._outbox:
            await self._flush_outbox()
        if now >= self._next_pose_report and self.pose_known and (
                self.origin is not None or self.role == MAPPER):
            self._next_pose_report = now + POSE_REPORT_TICKS * self.o.tick_s
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
            if self.origin_from_server:
                self.set_origin(Pose(data.x, data.y, data.heading))
            await self.on_origin()
        elif cmd == "destination":
            await self.on_destination(data.x, data.y, data.heading, data.within)

    async def on_origin(self) -> None:
        """Hook: the server gave the start pose in the map frame (``origin``)."""

    def on_pose_at_rest(self) -> None:
        """Hook: Motor Control's pose arrived with no motion in flight."""

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

    async def on_ir(self, in_range: bool, *, pinned: bool = False) -> None:
        """Hook: the IR decision (seeker); ``pinned``: the sensor sits on an ADC rail and
        decides nothing (``in_range`` is then False)."""

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
        if len(self._outbox) >= OUTBOX:
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
        """Send to a neighbour, waiting at most ``SEND_TIMEOUT_S`` for room; False if not sent.

        The timeout's cancel scope is entered only when the neighbour's mailbox is full
        (`ActorSystem.cast_nowait`): with room the message is queued without waiting.
        """
        sent = self.ctx.cast_nowait(name, message)
        if sent is None:
            with trio.move_on_after(SEND_TIMEOUT_S):
                sent = await self.ctx.cast(name, message)
        if sent:
            return True
        self.counters["dropped"] += 1
        return False
