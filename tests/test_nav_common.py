"""Navigation's shared parts: the ADP decision, routes, pose tracking, telemetry, restarts.

Also home of the fake neighbours the other ``test_nav_*`` files use: a motor
that moves a shared body exactly (stopping at walls of a truth grid), a WiFly
that records what navigation hands it, and a LIDAR + Map Management pair that
ray-casts the truth grid into an `OccupancyGrid`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
import trio

from actors import Actor, BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.localisation.belief import PoseBelief
from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route import Motion, PathFollower, plan_route, shorten, with_obstacle
from server.protocol import Frame, make_frame
from server.protocol.grid_map import FREE, OCCUPIED, GridMap
from server.protocol.pose import Pose
from supervisors import ChildSpec, SupervisorSpec

# ============================================================================ fakes


class Truth:
    """A room as a boolean grid in the rover's own frame (True = solid)."""

    def __init__(self, x0: float, y0: float, x1: float, y1: float, res: float = 5.0,
                 boxes: tuple[tuple[float, float, float, float], ...] = ()) -> None:
        self.res = res
        self.origin = (x0 - 20.0, y0 - 20.0)
        nx = round((x1 - x0 + 40) / res)
        ny = round((y1 - y0 + 40) / res)
        cx = self.origin[0] + (np.arange(nx) + 0.5) * res
        cy = self.origin[1] + (np.arange(ny) + 0.5) * res
        X, Y = np.meshgrid(cx, cy)
        solid = (X < x0) | (X > x1) | (Y < y0) | (Y > y1)
        for bx, by, bw, bh in boxes:
            solid |= (X >= bx) & (X <= bx + bw) & (Y >= by) & (Y <= by + bh)
        self.solid = solid

    def at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        r = np.floor((np.asarray(y) - self.origin[1]) / self.res).astype(int)
        c = np.floor((np.asarray(x) - self.origin[0]) / self.res).astype(int)
        ny, nx = self.solid.shape
        inside = (r >= 0) & (r < ny) & (c >= 0) & (c < nx)
        out = np.ones(np.shape(r), dtype=bool)
        out[inside] = self.solid[r[inside], c[inside]]
        return out

    def clear(self, x: float, y: float, radius: float) -> bool:
        a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        return not self.at(x + radius * np.cos(a), y + radius * np.sin(a)).any() and \
            not self.at(np.array([x]), np.array([y])).any()

    def ranges(self, pose: Pose, n: int = 120, max_cm: float = 600.0) -> tuple[np.ndarray, ...]:
        angles = np.arange(n) * (360.0 / n)
        t = np.radians(pose.heading_deg + angles)
        d = np.arange(1.0, max_cm, 1.0)
        xs = pose.x + np.cos(t)[:, None] * d[None, :]
        ys = pose.y + np.sin(t)[:, None] * d[None, :]
        hit = self.at(xs, ys)
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        rng = np.where(first >= 0, d[np.maximum(first, 0)], 0.0)
        return angles, rng


@dataclass
class Body:
    """The fake rover: its exact pose, and what the fakes recorded."""

    pose: Pose = field(default_factory=Pose)
    truth: Truth | None = None
    radius: float = 10.0
    speed: float = 30.0  # [cm/s]
    motor_log: list = field(default_factory=list)
    sent: list = field(default_factory=list)  # (code, object) handed to WiFly
    lidar_log: list = field(default_factory=list)
    lidar_on: bool = False
    blocked_moves: int = 0  # block the next N moves (a rover in the way)
    map_msgs: list = field(default_factory=list)
    ir_in_range: Any = None  # callable(pose) -> bool for the seeker's IR
    script: Any = None  # callable(pose, cm) -> (done cm, yaw deg[, tread report]) | None: a
    # move's scripted end (a report is sent as NAV_TREAD_FAULT before the end)
    turn_script: Any = None  # callable(pose, deg) -> done deg | (done deg, tread report) |
    # None: a turn's blocked end (a report is sent as NAV_TREAD_FAULT before the end)
    motor_at: list = field(default_factory=list)  # the time of each motor_log entry [s]
    published: list = field(default_factory=list)  # (time, pose) Motor Control reported

    def frames(self, cmd: str | None = None) -> list[Frame]:
        return [o for c, o in self.sent if isinstance(o, Frame) and (cmd is None or o.cmd == cmd)]


class FakeMotor(Actor):
    """Executes Command A exactly (at ``speed``), stops at walls, publishes the pose."""

    def __init__(self, body: Body) -> None:
        self.body = body

    async def on_start(self) -> None:
        self.nav = self.ctx.name.rsplit("/", 1)[0] + "/nav"

    def _publish(self) -> None:
        p = self.body.pose
        self.body.published.append((trio.current_time(), p))
        self.ctx.send_nowait(self.nav, Message.pair(Cmd.NAV_POSE_XY, round(p.x * 10),
                                                    round(p.y * 10)))
        self.ctx.send_nowait(self.nav, Message.float(Cmd.NAV_POSE_HEADING, p.heading_deg))

    async def handle(self, message: Message) -> None:
        b = self.body
        cmd = message.command
        b.motor_log.append((Cmd(cmd).name, float(message.value)))
        b.motor_at.append(trio.current_time())
        if cmd == Cmd.MOTOR_GET_POSE:
            self._publish()
        elif cmd == Cmd.MOTOR_TURN:
            await trio.sleep(abs(message.value) / 90.0)
            stop = b.turn_script(b.pose, float(message.value)) if b.turn_script else None
            if isinstance(stop, tuple):  # Motor Control's tread report during the turn
                stop, report = stop
                self.ctx.send_nowait(self.nav, Message.uint(Cmd.NAV_TREAD_FAULT, int(report)))
            done = float(message.value) if stop is None else stop
            b.pose = Pose(b.pose.x, b.pose.y, b.pose.heading_deg + done)
            self._publish()
            code = Cmd.NAV_MOTION_DONE if stop is None else Cmd.NAV_MOTION_BLOCKED
            self.ctx.send_nowait(self.nav, Message.float(code, done))
        elif cmd == Cmd.MOTOR_MOVE:
            d = float(message.value)
            await trio.sleep(abs(d) / b.speed)
            h = b.pose.heading_rad
            done, blocked = 0.0, False
            scripted = b.script(b.pose, d) if b.script is not None else None
            if scripted is not None:  # ends blocked after ``done`` cm, turned by ``yaw``
                done, yaw = scripted[:2]
                if len(scripted) > 2:  # Motor Control's tread report during the move
                    self.ctx.send_nowait(self.nav, Message.uint(Cmd.NAV_TREAD_FAULT,
                                                                int(scripted[2])))
                b.pose = Pose(b.pose.x, b.pose.y, b.pose.heading_deg + yaw)
                blocked = True
            elif b.blocked_moves > 0 and d > 0:
                b.blocked_moves -= 1
                blocked = True
            else:
                for s in np.linspace(0, d, max(2, int(abs(d)) + 1))[1:]:
                    x, y = b.pose.x + s * math.cos(h), b.pose.y + s * math.sin(h)
                    if b.truth is not None and not b.truth.clear(x, y, b.radius):
                        blocked = True
                        break
                    done = float(s)
            b.pose = Pose(b.pose.x + done * math.cos(h), b.pose.y + done * math.sin(h),
                          b.pose.heading_deg)
            self._publish()
            code = Cmd.NAV_MOTION_BLOCKED if blocked else Cmd.NAV_MOTION_DONE
            self.ctx.send_nowait(self.nav, Message.float(code, done))


class FakeWifly(Actor):
    """Takes every handle navigation posts and records (code, object)."""

    def __init__(self, body: Body, pool: BufferPool) -> None:
        self.body, self.pool = body, pool

    async def handle(self, message: Message) -> None:
        self.body.sent.append((Cmd(message.command).name, self.pool.take(int(message.value))))


class FakeLidar(Actor):
    """Records Command B; the map fake scans while it is on."""

    def __init__(self, body: Body) -> None:
        self.body = body

    async def handle(self, message: Message) -> None:
        self.body.lidar_log.append(Cmd(message.command).name)
        self.body.lidar_on = message.command == Cmd.LIDAR_START


class FakeMap(Actor):
    """Map Management stand-in: every 0.2 s a ray-cast scan of the truth while the LIDAR is on."""

    def __init__(self, body: Body, pool: BufferPool) -> None:
        self.body, self.pool = body, pool
        self.grid = OccupancyGrid(800.0, 800.0, 5.0)
        self.scans = 0

    async def on_start(self) -> None:
        self.nav = self.ctx.name.rsplit("/", 1)[0] + "/nav"
        self.ctx.start_timer(0.2, Message.uint(Cmd.NAV_TIMER, 0), interval=0.2)

    def _publish(self) -> None:
        h = self.pool.put(self.grid.snapshot())
        self.ctx.send_nowait(self.nav, Message.handle(Cmd.NAV_MAP_UPDATE, h))
        self.ctx.send_nowait(self.nav, Message.uint(Cmd.NAV_SCAN_COUNT, self.scans))

    async def handle(self, message: Message) -> None:
        self.body.map_msgs.append(Cmd(message.command).name)
        if message.command == Cmd.MAP_GET:
            self._publish()
        elif message.command == Cmd.MAP_RESTORE:
            self.pool.take(int(message.value))
        elif message.command == Cmd.NAV_TIMER and self.body.lidar_on:
            assert self.body.truth is not None
            angles, ranges = self.body.truth.ranges(self.body.pose)
            self.grid.integrate(self.body.pose, angles, ranges)
            self.scans += 1
            self._publish()


class FakeIr(Actor):
    """Sends NAV_IR every 0.1 s from ``body.ir_in_range(pose)`` (a bool, or a ``NAV_IR`` value
    of `drivers.ir` such as ``IR_PINNED``)."""

    def __init__(self, body: Body) -> None:
        self.body = body

    async def on_start(self) -> None:
        self.nav = self.ctx.name.rsplit("/", 1)[0] + "/nav"
        self.ctx.start_timer(0.1, Message.uint(Cmd.NAV_TIMER, 0), interval=0.1)

    async def handle(self, message: Message) -> None:
        v = int(self.body.ir_in_range(self.body.pose)) if self.body.ir_in_range else 0
        self.ctx.send_nowait(self.nav, Message.int(Cmd.NAV_IR, v))


def rover_spec(role: str, body: Body, pool: BufferPool, *, memory: NavMemory | None = None,
               options: NavOptions | None = None, **kw: Any) -> SupervisorSpec:
    """A rover tree of fakes plus the real navigation actor."""
    children = [ChildSpec("motor", lambda: FakeMotor(body), mailbox=64),
                ChildSpec("wifly", lambda: FakeWifly(body, pool), mailbox=64)]
    if role == "mapper":
        children += [ChildSpec("lidar", lambda: FakeLidar(body), mailbox=16),
                     ChildSpec("map", lambda: FakeMap(body, pool), mailbox=64)]
    if role == "seeker":
        children.append(ChildSpec("ir", lambda: FakeIr(body), mailbox=16))
    children.append(ChildSpec("nav", lambda: make_nav(role, pool=pool, memory=memory,
                                                      options=options, **kw), mailbox=256))
    return SupervisorSpec(children, intensity=20, period=1.0)


async def net(system: Any, pool: BufferPool, rover: str, cmd: str, data: Any = None) -> None:
    """Deliver a server frame to ``rover``'s navigation as WiFly would."""
    await system.send(f"{rover}/nav", Message.handle(Cmd.NAV_NET, pool.put(make_frame(cmd, data))))


async def download(system: Any, pool: BufferPool, rover: str, grid: GridMap) -> None:
    """Deliver a downloaded map as WiFly would."""
    await system.send(f"{rover}/nav", Message.handle(Cmd.NAV_MAP_DOWNLOAD, pool.put(grid)))


async def send_orders(system: Any, pool: BufferPool, rover: str, origin: Any,
                      dest: Any) -> None:
    """What the server sends for ``hide`` / ``seek`` at once: origin, start, destination."""
    await net(system, pool, rover, "origin", origin)
    await net(system, pool, rover, "start")
    await net(system, pool, rover, "destination", dest)


async def send_route(system: Any, pool: BufferPool, rover: str, origin: Any, dest: Any,
                     grid: GridMap) -> None:
    """`send_orders`; then, once navigation asked for it, the map."""
    await send_orders(system, pool, rover, origin, dest)
    await trio.sleep(0.5)
    await download(system, pool, rover, grid)


def room_map(truth: Truth) -> GridMap:
    """The truth as a fully known map (what the mapper would have uploaded)."""
    return GridMap(np.where(truth.solid, OCCUPIED, FREE).astype(np.int8), truth.res, truth.origin)


async def wait_for(pred: Any, timeout: float, step: float = 0.1) -> bool:
    """Poll ``pred`` in virtual time; True once it holds, False after ``timeout`` [s]."""
    with trio.move_on_after(timeout):
        while not pred():
            await trio.sleep(step)
        return True
    return False


# ============================================================================ pure parts

OPT = NavOptions()


def drive(follower: PathFollower, pose: Pose, limit: int = 200) -> tuple[Pose, int]:
    """Apply the follower's motions exactly until it says done."""
    for n in range(limit):
        m = follower.next_motion(pose)
        if m is None:
            return pose, n
        if m.kind == "turn":
            pose = Pose(pose.x, pose.y, pose.heading_deg + m.amount)
        else:
            h = pose.heading_rad
            pose = Pose(pose.x + m.amount * math.cos(h), pose.y + m.amount * math.sin(h),
                        pose.heading_deg)
    raise AssertionError("the follower never finished")


def test_follower_reaches_goal_and_heading() -> None:
    """Exact motions end within the goal and heading tolerances."""
    f = PathFollower([(50.0, 0.0), (50.0, 80.0)], -90.0, OPT)
    budget = f.budget(Pose(0, 0, 0))
    pose, n = drive(f, Pose(0, 0, 0))
    assert math.dist((pose.x, pose.y), (50, 80)) <= OPT.goal_tol_cm
    assert abs(pose.heading_deg - (-90.0)) <= OPT.heading_tol_deg
    assert n <= budget


def test_follower_turns_before_moving_and_steps_are_bounded() -> None:
    """Off the bearing it turns first; straight moves never exceed step_cm."""
    f = PathFollower([(0.0, 100.0)], None, OPT)
    assert f.next_motion(Pose(0, 0, 0)) == Motion("turn", 90.0)
    m = f.next_motion(Pose(0, 0, 90))
    assert m == Motion("move", OPT.step_cm)


def test_follower_with_no_heading_stops_at_the_goal() -> None:
    """At the goal with no heading wanted there is nothing left to do."""
    f = PathFollower([(10.0, 0.0)], None, OPT)
    assert f.next_motion(Pose(9.0, 0.5, 33.0)) is None


def test_follower_rejects_an_empty_route() -> None:
    with pytest.raises(ValueError, match="waypoints must not be empty"):
        PathFollower([], None, OPT)


def test_plan_route_goes_round_a_wall_and_with_obstacle_blocks_it() -> None:
    """A route avoids the box; a learned obstacle in a doorway makes it impossible."""
    truth = Truth(0, 0, 300, 200, boxes=((140, 0, 20, 150),))
    grid = room_map(truth)
    plan = plan_route(grid, (50, 50), (250, 50), radius_cm=12.5, margin_cm=3.0)
    assert plan is not None and plan.length_cm > 250  # round the wall's end, not through
    blocked = with_obstacle(grid, 150, 175, 30.0)
    assert plan_route(blocked, (50, 50), (250, 50), radius_cm=12.5, margin_cm=3.0) is None


# ============================================================================ actor behaviour


@pytest.mark.trio
async def test_pose_telemetry_in_map_frame_after_origin(autojump_clock) -> None:
    """No ``pose`` before the origin; afterwards poses are composed with it, about 1.3 Hz."""
    body = Body(pose=Pose(10.0, 0.0, 0.0))
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await trio.sleep(2.0)
        assert body.frames("pose") == []
        await net(system, pool, "hider", "origin", {"x": 100.0, "y": 50.0, "heading": 90.0})
        await trio.sleep(3.0)
        poses = body.frames("pose")
        assert 3 <= len(poses) <= 5
        assert poses[-1].data == {"x": 100.0, "y": 60.0, "heading": 90.0}
        assert all(c == "WIFLY_SEND_UNRELIABLE" for c, o in body.sent if o.cmd == "pose")


@pytest.mark.trio
async def test_start_stops_motor_and_asks_pose_and_reports_status(autojump_clock) -> None:
    """On start navigation stops the motor, asks the pose, and says it is idle."""
    body = Body()
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await trio.sleep(0.5)
        assert [c for c, _ in body.motor_log[:2]] == ["MOTOR_STOP", "MOTOR_GET_POSE"]
        assert body.frames("status")[0].data["state"] == "idle"


@pytest.mark.trio
async def test_bad_handles_are_counted_not_fatal(autojump_clock) -> None:
    """A stale handle or a non-handle NAV_NET is counted; the actor keeps running."""
    body = Body()
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await system.send("hider/nav", Message.handle(Cmd.NAV_NET, 12345))
        await system.send("hider/nav", Message.int(Cmd.NAV_NET, 1))
        await trio.sleep(0.5)
        nav = system.whereis("hider/nav").actor
        assert nav.counters["bad_frames"] == 2
        assert system.whereis("hider/nav").last_exit is None


@pytest.mark.trio
async def test_restart_reports_restarted_and_keeps_the_origin_in_memory(autojump_clock) -> None:
    """A crashed navigation comes back, says ``restarted`` and still knows its origin."""
    body = Body(pose=Pose(0.0, 0.0, 0.0))
    pool = BufferPool(64)
    memory = NavMemory()
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=memory), "hider")
        await net(system, pool, "hider", "origin", {"x": 40.0, "y": 0.0, "heading": 0.0})
        await trio.sleep(1.0)
        system.inject_crash("hider/nav")
        await trio.sleep(2.0)
        assert "restarted" in [f.data["state"] for f in body.frames("status")]
        assert body.frames("pose")[-1].data["x"] == 40.0


def test_shorten_cuts_the_route_back_along_its_legs() -> None:
    """A 100 + 50 cm route cut by 70 cm ends 20 cm before the corner, on the first leg."""
    assert shorten([(100.0, 0.0), (100.0, 50.0)], (0.0, 0.0), 70.0) == [(80.0, 0.0)]
    assert shorten([(100.0, 0.0), (100.0, 50.0)], (0.0, 0.0), 20.0) == [(100.0, 0.0),
                                                                         (100.0, 30.0)]
    assert shorten([(100.0, 0.0)], (0.0, 0.0), 150.0) == []


def test_follower_does_not_repeat_a_turn_the_motor_could_not_resolve() -> None:
    """A motor that ignores turns under 4 deg: the follower drives on instead of asking
    the same small turn forever, and accepts the final heading it cannot refine."""
    f = PathFollower([(100.0, 5.0)], 3.5, OPT)
    pose = Pose(0.0, 0.0, 0.0)
    for _ in range(40):
        m = f.next_motion(pose)
        if m is None:
            break
        if m.kind == "turn" and abs(m.amount) >= 4.0:
            pose = Pose(pose.x, pose.y, pose.heading_deg + m.amount)
        elif m.kind == "move":
            h = pose.heading_rad
            pose = Pose(pose.x + m.amount * math.cos(h), pose.y + m.amount * math.sin(h),
                        pose.heading_deg)
    else:
        raise AssertionError("the follower kept asking")
    assert math.dist((pose.x, pose.y), (100.0, 5.0)) <= OPT.goal_tol_cm
    assert f.steps < 20


def test_plan_tiers_go_from_room_to_turn_to_the_body_width() -> None:
    """Turning radius + margin, radius, half width + 2 cm, half width: most cautious first."""
    nav = make_nav("hider", pool=BufferPool(4))
    assert nav.plan_tiers() == ((12.5, 3.0), (12.5, 0.0), (7.5, 2.0), (7.5, 0.0))


def test_a_corridor_mapped_20_cm_wide_is_planned_at_the_body_width() -> None:
    """A 30 cm corridor whose walls map a cell thick on each side leaves 20 cm of free
    cells: only the last tier (half the body width, no margin) finds the way through."""
    m = room_map(Truth(0, 0, 600, 300, boxes=((200, 0, 200, 140), (200, 160, 200, 140))))
    tiers = make_nav("hider", pool=BufferPool(4)).plan_tiers()
    found = [plan_route(m, (100, 150), (500, 150), radius_cm=r, margin_cm=g) is not None
             for r, g in tiers]
    assert found == [False, False, False, True]


def believe(nav: Any, sigma_cm: float, sigma_deg: float = 2.0) -> Any:
    """Give ``nav`` (a hider or seeker navigation) a pose belief ``sigma_cm`` and
    ``sigma_deg`` wide round its map pose, as after some driving; returns ``nav``."""
    nav.pose_known = True
    nav.localiser.adopt(PoseBelief.around(nav.map_pose, np.random.default_rng(0),
                                          sigma_cm=sigma_cm, sigma_deg=sigma_deg))
    return nav
