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
    script: Any = None  # callable(pose, cm) -> (done cm, yaw deg) | None: a move's scripted end
    motor_at: list = field(default_factory=list)  # the time of each motor_log entry [s]

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
            b.pose = Pose(b.pose.x, b.pose.y, b.pose.heading_deg + message.value)
            self._publish()
            self.ctx.send_nowait(self.nav, Message.float(Cmd.NAV_MOTION_DONE, message.value))
        elif cmd == Cmd.MOTOR_MOVE:
            d = float(message.value)
            await trio.sleep(abs(d) / b.speed)
            h = b.pose.heading_rad
            done, blocked = 0.0, False
            scripted = b.script(b.pose, d) if b.script is not None else None
            if scripted is not None:  # ends blocked after ``done`` cm, turned by ``yaw``
                done, yaw = scripted
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
    """Sends NAV_IR every 0.1 s from ``body.ir_in_range(pose)``."""

    def __init__(self, body: Body) -> None:
        self.body = body

    async def on_start(self) -> None:
        self.nav = self.ctx.name.rsplit("/", 1)[0] + "/nav"
        self.ctx.start_timer(0.1, Message.uint(Cmd.NAV_TIMER, 0), interval=0.1)

    async def handle(self, message: Message) -> None:
        v = bool(self.body.ir_in_range(self.body.pose)) if self.body.ir_in_range else False
        self.ctx.send_nowait(self.nav, Message.int(Cmd.NAV_IR, int(v)))


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


def nudging_nav(block: tuple[float, float, float], off: float) -> Any:
    """A hider navigation (not started) that was blocked at ``block`` and nudges by ``off``."""
    nav = make_nav("hider", pool=BufferPool(4))
    corridor = Truth(0, 0, 600, 300, boxes=((100, 0, 300, 135), (100, 165, 300, 135)))
    nav.map = room_map(corridor)
    nav._last_block = nav._anchor = block
    h = math.radians(block[2])
    nav._nudge = (-math.sin(h) * off, math.cos(h) * off, block[0], block[1])
    return nav


def test_nudge_shifts_only_waypoints_near_the_block_and_never_the_goal() -> None:
    """Blocked heading +x at (200, 150): the waypoint 30 cm on moves 6 cm sideways (+y)."""
    nav = nudging_nav((200.0, 150.0, 0.0), 6.0)
    pts = [(230.0, 150.0), (420.0, 150.0), (500.0, 60.0)]
    assert nav._nudged(pts) == [(230.0, 156.0), (420.0, 150.0), (500.0, 60.0)]
    assert nav._nudged([(240.0, 150.0)]) == [(240.0, 150.0)]  # the goal itself stays


def test_a_nudge_into_the_corridor_wall_or_backwards_is_refused() -> None:
    """A shift into the corridor's wall (20 cm off its axis) is refused (None); a route
    whose goal lies behind the block is left as it is."""
    pts = [(420.0, 150.0), (500.0, 60.0)]
    assert nudging_nav((250.0, 150.0, 0.0), -6.0)._nudged(pts) == [(300.0, 144.0), *pts]
    assert nudging_nav((250.0, 150.0, 0.0), 20.0)._nudged(pts) is None
    assert nudging_nav((250.0, 150.0, 180.0), 6.0)._nudged(pts) == pts  # ahead is backwards


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


# ---------------------------------------------------------------- blocked in a corridor
# A hider sent from map (50, 50) (its own (0, 0)) to (600, 150) through a 30 cm corridor
# (x 250..450, walls y < 135 and y > 165). The fake motor drives exactly, except where
# the test scripts a block: the move ends blocked where the script says, the rover
# turned by the script's yaw. What navigation does about it is read from what it
# sends: its motor commands and the frames it reports to the server.

CORRIDOR = Truth(0, 0, 700, 300, boxes=((250, 0, 200, 135), (250, 165, 200, 135)))
CORRIDOR_ORIGIN = {"x": 50.0, "y": 50.0, "heading": 0.0}
CORRIDOR_GOAL = {"x": 600.0, "y": 150.0, "heading": None}


class Blocks:
    """The script: forward moves that reach own-frame x ``at`` end there blocked, turned by
    ``yaw``, one entry per block in order; ``reverse`` scripts the end of the back-off
    that follows the last block (``(done cm, yaw deg)``, None: as commanded)."""

    def __init__(self, *blocks: tuple[float, float],
                 reverse: tuple[float, float] | None = None) -> None:
        self.todo = list(blocks)
        self.reverse = reverse
        self.at: list[tuple[float, int, int]] = []  # (time, len(sent), len(motor_log))
        self.body: Body | None = None

    def __call__(self, pose: Pose, cm: float) -> tuple[float, float] | None:
        assert self.body is not None
        if cm < 0 and self.reverse is not None and not self.todo and self.at:
            done, yaw = self.reverse
            self.reverse = None
            return -done, yaw
        if cm > 0 and self.todo and pose.x + cm * math.cos(pose.heading_rad) >= self.todo[0][0]:
            at, yaw = self.todo.pop(0)
            self.at.append((trio.current_time(), len(self.body.sent), len(self.body.motor_log)))
            return max(0.0, (at - pose.x) / math.cos(pose.heading_rad)), yaw
        return None


async def drive_corridor(blocks: Blocks, *, options: NavOptions | None = None,
                         after_s: float = 20.0, crash: bool = False) -> Body:
    """Send the hider through the corridor with ``blocks`` scripted; return its body once
    the last block is ``after_s`` past (navigation crashed and restarted then if ``crash``)."""
    body = Body(script=blocks)
    blocks.body = body
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=NavMemory(),
                                                 options=options), "hider")
        await send_route(system, pool, "hider", CORRIDOR_ORIGIN, CORRIDOR_GOAL,
                         room_map(CORRIDOR))
        n = len(blocks.todo)
        assert await wait_for(lambda: len(blocks.at) == n, 120.0)
        await trio.sleep(after_s)
        if crash:
            system.inject_crash("hider/nav")
            await trio.sleep(3.0)
    return body


def poses_after(body: Body, k: int, blocks: Blocks) -> list[tuple[float, float, float]]:
    """The map-frame poses navigation reported after block ``k`` (x, y, heading)."""
    return [(f.data["x"], f.data["y"], f.data["heading"])
            for f in [o for _, o in body.sent[blocks.at[k][1]:]] if f.cmd == "pose"]


def motions_after(body: Body, k: int, blocks: Blocks) -> list[tuple[float, str, float]]:
    """The turns and moves navigation commanded after block ``k``: (time, command, amount)."""
    start = blocks.at[k][2]
    return [(t, c, v) for t, (c, v) in zip(body.motor_at[start:], body.motor_log[start:],
                                           strict=True) if c in ("MOTOR_TURN", "MOTOR_MOVE")]


@pytest.mark.trio
async def test_a_scrape_moves_the_reported_pose_to_the_wall_on_the_stalled_side(
        autojump_clock) -> None:
    """Blocked mid-corridor having yawed 3 deg left: the left side touches the wall at
    y = 165, so the pose navigation reports moves up to it (from y 149.3); Motor Control
    is told nothing of it (its dead reckoning stays continuous), and a restarted
    navigation reports the corrected pose still (the retained memory keeps it)."""
    blocks = Blocks((250.0, 3.0))
    body = await drive_corridor(blocks, after_s=1.0, crash=True)
    x, y, _ = poses_after(body, 0, blocks)[0]
    assert 154.0 <= y <= 162.0 and x == pytest.approx(300.0 - 6.0, abs=3.0)  # backed off
    assert {c for c, _ in body.motor_log} <= {"MOTOR_STOP", "MOTOR_GET_POSE", "MOTOR_TURN",
                                             "MOTOR_MOVE"}
    assert 154.0 <= poses_after(body, 0, blocks)[-1][1] <= 162.0  # after the restart
    assert "restarted" in [f.data["state"] for f in body.frames("status")]


@pytest.mark.parametrize(("yaw", "options"), [
    (0.0, {}), (3.0, {"contact_fixes": 0}), (3.0, {"contact_max_shift_cm": 3.0})],
    ids=["no-yaw", "no-corrections-left", "shift-budget-too-small"])
@pytest.mark.trio
async def test_no_correction_when_the_side_is_unknown_or_the_budget_is_spent(
        autojump_clock, yaw, options) -> None:
    """No yaw: left and right explain the block alike; with the corrections used up, or the
    sideways budget too small, none either: the reported pose stays where dead reckoning
    put it (y 149.3) as the rover backs off."""
    blocks = Blocks((250.0, yaw))
    body = await drive_corridor(blocks, options=NavOptions(**options), after_s=1.0)
    x, y, _ = poses_after(body, 0, blocks)[0]
    assert y == pytest.approx(149.3, abs=0.5) and x == pytest.approx(294.0, abs=0.5)


@pytest.mark.trio
async def test_a_block_in_a_narrow_passage_probes_sideways_at_once(autojump_clock) -> None:
    """Blocked moving forward mid-corridor (walls both sides within 40 cm): after the
    back-off the route is shifted sideways at once, to the left first (the first turn
    after the back-off is to the left); blocked again at the same place, to the right;
    a later block 50 cm on starts a new series on the side that helped (right again),
    not back at the left."""
    blocks = Blocks((250.0, 0.0), (250.0, 0.0), (300.0, 0.0))
    body = await drive_corridor(blocks, after_s=4.0)

    def first_turn(k: int) -> float:
        motions = motions_after(body, k, blocks)
        assert motions[0][1:] == ("MOTOR_MOVE", -6.0)  # backed off first
        return next(v for _, c, v in motions[1:] if c == "MOTOR_TURN")

    assert [math.copysign(1.0, first_turn(k)) for k in range(3)] == [1.0, -1.0, -1.0]
    assert all(y < 149.0 for x, y, _ in poses_after(body, 2, blocks) if x > 360.0)


@pytest.mark.trio
async def test_a_nudge_mid_corridor_drives_to_a_shifted_point_ahead_first(
        autojump_clock) -> None:
    """Blocked mid-corridor with no waypoint near the block: after the back-off the rover
    drives to the point 50 cm ahead of the block, shifted 4 cm left, and then on to the
    goal along the corridor."""
    blocks = Blocks((250.0, 0.0))
    body = await drive_corridor(blocks, after_s=6.0)
    motions = [(c, v) for _, c, v in motions_after(body, 0, blocks)]
    assert motions[0] == ("MOTOR_MOVE", -6.0) and motions[1][0] == "MOTOR_TURN"
    leg = motions[2:2 + [c for c, _ in motions[2:]].index("MOTOR_TURN")]
    assert sum(v for _, v in leg) == pytest.approx(math.dist((294.0, 149.3), (350.0, 153.4)),
                                                   abs=1.0)  # one straight leg to it
    track = poses_after(body, 0, blocks)
    assert any(abs(x - 350.0) < 1.0 and abs(y - 153.4) < 0.5 for x, y, _ in track)
    assert track[-1][0] > 400.0


@pytest.mark.trio
@pytest.mark.parametrize(("drift_per_cm", "across"), [(0.04, None), (0.08, (7.0, 9.5)),
                                                     (0.2, (11.7, 12.3))])
async def test_the_more_drift_the_wider_the_probe_steps(autojump_clock, drift_per_cm,
                                                         across) -> None:
    """About 3 m driven to the block: with the default drift per cm (12 cm) the first probe
    steps 4 cm (joined at a slant, no sidestep); with twice that drift it steps a third
    of the drift, about 8 cm (a sidestep across); with more, at most
    ``nudge_step_max_cm``, 12 cm."""
    blocks = Blocks((250.0, 0.0))
    body = await drive_corridor(blocks, options=NavOptions(drift_per_cm=drift_per_cm),
                                after_s=4.0)
    motions = [(c, v) for _, c, v in motions_after(body, 0, blocks)]
    assert motions[0] == ("MOTOR_MOVE", -6.0)
    if across is None:
        assert motions[1][0] == "MOTOR_TURN" and 0.0 < motions[1][1] < 45.0
        return
    assert motions[1] == ("MOTOR_TURN", pytest.approx(90.0, abs=5.0))
    assert motions[2][0] == "MOTOR_MOVE" and across[0] < motions[2][1] < across[1]


@pytest.mark.trio
@pytest.mark.parametrize("sidestep", [True, False], ids=["sidestep", "no-sidestep"])
async def test_a_probe_sidesteps_across_before_joining_the_shifted_line(autojump_clock,
                                                                        sidestep) -> None:
    """Blocked a third time at the same place, the probe shifts 8 cm left: the route
    begins with a sidestep square to the heading of the block (a quarter turn left, a
    few cm across, a quarter turn back), then drives on along the shifted line. A shift
    within the waypoint tolerance (the first, 4 cm) needs none, nor a route with
    ``probe_sidestep`` off: it joins the shifted line at a slant."""
    blocks = Blocks((250.0, 0.0), (250.0, 0.0), (250.0, 0.0))
    body = await drive_corridor(blocks, options=NavOptions(probe_sidestep=sidestep),
                                after_s=4.0)
    first = [v for _, c, v in motions_after(body, 0, blocks) if c == "MOTOR_TURN"][0]
    assert 0.0 < first < 45.0
    third = motions_after(body, 2, blocks)
    if not sidestep:
        assert 0.0 < next(v for _, c, v in third if c == "MOTOR_TURN") < 45.0
        return
    (_, c0, back), (_, c1, left), (_, c2, across), (_, c3, right) = third[:4]
    assert (c0, c1, c2, c3) == ("MOTOR_MOVE", "MOTOR_TURN", "MOTOR_MOVE", "MOTOR_TURN")
    assert back < 0 and 80.0 < left < 100.0 and 4.0 < across < 12.0 and -100.0 < right < -80.0
    on_line = [y for x, y, h in poses_after(body, 2, blocks) if x > 300.0]
    assert on_line and max(on_line) - min(on_line) < 1.0 and min(on_line) > 155.0


@pytest.mark.trio
async def test_a_back_off_that_turns_while_blocked_holds_instead_of_backing_off_again(
        autojump_clock) -> None:
    """A back-off ends blocked having turned 25 deg: one tread stalls (backing off again
    only spins the rover on the spot), so navigation says so, commands nothing for
    ``tread_hold_s`` and plans again after it."""
    blocks = Blocks((250.0, 0.0), reverse=(2.0, 25.0))
    body = await drive_corridor(blocks, after_s=20.0)
    assert "a tread stalls; holding 12 s" in [f.data.get("detail")
                                               for f in body.frames("status")]
    motions = motions_after(body, 0, blocks)
    assert motions[0][1:] == ("MOTOR_MOVE", -6.0)  # the back-off the script ends
    t_stall = motions[0][0] + 6.0 / body.speed
    assert motions[1][0] >= t_stall + NavOptions().tread_hold_s - 0.1
    assert not (motions[1][1] == "MOTOR_MOVE" and motions[1][2] < 0)


@pytest.mark.trio
async def test_a_back_off_blocked_without_turning_backs_off_again_at_once(
        autojump_clock) -> None:
    """A back-off that moved 2 cm and ended blocked without turning (the rear against
    something): no stall hold, it backs off again straight away."""
    blocks = Blocks((250.0, 0.0), reverse=(2.0, 0.0))
    body = await drive_corridor(blocks, after_s=3.0)
    motions = motions_after(body, 0, blocks)
    assert motions[1][1] == "MOTOR_MOVE" and motions[1][2] < 0
    assert motions[1][0] - motions[0][0] < 1.0


@pytest.mark.trio
async def test_a_back_off_that_did_not_move_replans_instead_of_reversing_again(
        autojump_clock) -> None:
    """Wedged: a back-off ended blocked without moving (reversing again and again leaves
    the rover stuck diagonally in a gap). The route is planned again from where the
    rover stands and driven on, not reversed once more."""
    blocks = Blocks((250.0, 0.0), reverse=(0.0, 0.0))
    body = await drive_corridor(blocks, after_s=3.0)
    motions = motions_after(body, 0, blocks)
    assert motions[0][1:] == ("MOTOR_MOVE", -6.0)
    after = motions[1:]
    assert after and not any(c == "MOTOR_MOVE" and v < 0 for _, c, v in after[:3])
    assert any(c == "MOTOR_MOVE" and v > 0 for _, c, v in after[:3])


def scraped_nav(yaw_deg: float, **options: Any) -> Any:
    """A hider navigation (not started) mid-corridor by dead reckoning (map (300, 150) @ 0,
    own frame (250, 100) @ 0), whose last forward move ended blocked after yawing
    ``yaw_deg``."""
    nav = make_nav("hider", pool=BufferPool(4), options=NavOptions(**options))
    nav.map = nav.work_map = room_map(
        Truth(0, 0, 700, 300, boxes=((250, 0, 200, 135), (250, 165, 200, 135))))
    nav.origin = Pose(50.0, 50.0, 0.0)
    nav.pose = Pose(250.0, 100.0, yaw_deg)
    nav.last_motion = Motion("move", 20.0)
    nav.motion_from = Pose(280.0, 150.0, 0.0)
    return nav


def test_correct_pose_sets_the_map_pose_exactly() -> None:
    nav = scraped_nav(10.0)
    target = Pose(310.0, 140.0, 5.0)
    nav.correct_pose(target)
    p = nav.map_pose
    assert (p.x, p.y, p.heading_deg) == pytest.approx((310.0, 140.0, 5.0))


def test_a_block_beside_the_anchor_continues_the_probe_series() -> None:
    """A nudged route blocked 25 cm beside the series' anchor (and 6 cm short of it,
    as a contact fix may leave it) is no progress: the series goes on to the next
    offset instead of restarting around the nudged point."""
    nav = scraped_nav(0.0)
    nav._last_block = (300.0, 150.0, 0.0)
    nav.goal, nav.goal_heading = (600.0, 150.0), None
    assert nav._probe_plan() and nav._nudge_off == 4.0
    assert nav._probe_plan() and nav._nudge_off == -4.0
    nav.pose = Pose(244.0, 125.0, 0.0)  # map (294, 175): 26 cm from the anchor, 25 sideways
    nav._last_block = (294.0, 175.0, 0.0)
    assert nav._probe_plan()
    assert nav._anchor == (300.0, 150.0, 0.0) and nav._nudge_off == 8.0


def test_a_block_short_of_the_mouth_during_a_series_is_its_next_step() -> None:
    """Dead reckoning 10 cm short of the corridor's mouth on a nudged route: no passage
    at the body or the nose, yet with the series' anchor near the block is the next
    probe, not an obstacle to learn; without a series, or
    far from its anchor, it is not."""
    nav = scraped_nav(0.0)
    nav.pose = Pose(180.0, 112.0, 0.0)  # map (230, 162): nose 10 cm before x = 250
    assert not nav._in_passage() and not nav._nudging_here()
    nav._anchor, nav._nudge = (232.0, 150.0, 0.0), (0.0, 12.0, 232.0, 150.0)
    assert nav._nudging_here()
    nav.pose = Pose(50.0, 112.0, 0.0)  # map (100, 162): 132 cm back in the room
    assert not nav._nudging_here()


def test_the_doubted_heading_drifts_with_the_distance_from_where_it_arose() -> None:
    """A heading doubted by e moves the pose off by at most e [rad] times the straight
    distance from where the doubt arose: going 100 cm on and back adds nothing in the
    end, however far was driven; a correction starts it afresh."""
    nav = scraped_nav(0.0)
    nav._forget_fault_drift()
    nav.heading_err_deg = 10.0
    for _ in range(5):  # probing back and forth
        nav.pose = Pose(350.0, 100.0, 0.0)
        assert nav.fault_drift_cm == pytest.approx(100.0 * math.radians(10.0))
        nav.pose = Pose(250.0, 100.0, 0.0)
        assert nav.fault_drift_cm == pytest.approx(0.0)
    nav.pose = Pose(250.0, 300.0, 0.0)
    nav.correct_pose(Pose(300.0, 350.0, 0.0))
    assert nav.fault_drift_cm == 0.0


def test_drift_grows_with_distance_driven_and_restarts_at_a_correction() -> None:
    """Moves (not turns) add to the distance since the pose was known; a contact
    correction makes it known again."""
    nav = scraped_nav(0.0)
    assert nav.drift_cm == 3.0  # the floor
    nav.driven_cm = 500.0
    assert nav.drift_cm == pytest.approx(500.0 * nav.o.drift_per_cm)
    nav.correct_pose(Pose(300.0, 150.0, 0.0))
    assert nav.driven_cm == 0.0 and nav.drift_cm == 3.0


def test_after_a_long_drive_a_nudge_may_enter_a_mapped_wall() -> None:
    """5 m driven (20 cm of drift): a 20 cm shift into the corridor's wall, refused right
    after the start, is tried: dead reckoning may be that far off."""
    pts = [(420.0, 150.0), (500.0, 60.0)]
    nav = nudging_nav((250.0, 150.0, 0.0), 20.0)
    assert nav._nudged(pts) is None
    nav.driven_cm = 500.0
    assert nav._nudged(pts) == [(300.0, 170.0), *pts]


def gap_blocked_nav(driven_cm: float) -> Any:
    """A hider navigation (not started) stopped 5 cm into the gap of a 15 cm wall at x 400
    (gap y 300..335) by dead reckoning, 5 cm above its lower edge, after ``driven_cm``
    of driving: only the lower edge explains it within 14 cm; the upper wall's face
    does 20 cm up."""
    nav = make_nav("hider", pool=BufferPool(4))
    nav.map = nav.work_map = room_map(
        Truth(0, 0, 700, 450, boxes=((400, 0, 15, 300), (400, 335, 15, 115))))
    nav.origin = Pose(0.0, 0.0, 0.0)
    nav.pose = Pose(395.0, 312.5, 0.0)
    nav.last_motion = Motion("move", 20.0)
    nav.motion_from = Pose(375.0, 312.5, 0.0)
    nav.driven_cm = driven_cm
    return nav


def test_a_gap_edge_contact_is_acted_on_only_while_the_drift_is_small() -> None:
    """Right after the start the lower edge is the only likely explanation: the pose
    moves down. After 6 m (24 cm of drift) the upper face is as likely: no correction
    (the passage is probed sideways instead)."""
    nav = gap_blocked_nav(0.0)
    assert nav._contact_fix() and nav.map_pose.y < 312.5
    nav = gap_blocked_nav(600.0)
    assert not nav._contact_fix()
    assert nav.map_pose == Pose(395.0, 312.5, 0.0)
    assert nav._in_passage()


def test_a_contact_that_measures_only_along_the_heading_keeps_the_drift() -> None:
    """A correction whose sideways position is not known (a wall's face across the
    heading) moves the pose but keeps the distance driven, so the drift (and the
    sideways search it sizes) stays; a full correction restarts it."""
    nav = scraped_nav(0.0)
    nav.driven_cm = 500.0
    nav.correct_pose(Pose(296.0, 150.0, 0.0), sideways_known=False)
    assert nav.map_pose.x == pytest.approx(296.0)
    assert nav.drift_cm == pytest.approx(500.0 * nav.o.drift_per_cm)
    nav.correct_pose(Pose(296.0, 150.0, 0.0))
    assert nav.drift_cm == 3.0
