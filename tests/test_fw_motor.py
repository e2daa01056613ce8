"""Motor Control: Command A against the simulated world, dead reckoning, restarts."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import trio

from actors import Actor, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.motor import MotorControl, PoseMemory
from actors.firmware.hardware import HardwareSpec, Interrupt, encode_counter
from actors.firmware.origin_wire import MM, xy_half
from server.protocol.pose import Pose, angle_diff_deg
from supervisors import ChildSpec, SupervisorSpec
from world import World, load_scenario, run_world


class Recorder(Actor):
    """Stand-in navigation: records every message with its time."""

    def __init__(self, log: list) -> None:
        self.log = log

    async def handle(self, message):
        self.log.append((trio.current_time(), message))


def motor_tree(hw, memory, log, **kw) -> SupervisorSpec:
    return SupervisorSpec([
        ChildSpec("nav", lambda: Recorder(log), mailbox=256),
        ChildSpec("motor", lambda: MotorControl(hw, memory, **kw), mailbox=256, watchdog=1.0),
    ])


async def wait_for(log, commands, timeout=30.0):
    """The first logged message with one of ``commands`` (waits in virtual time)."""
    with trio.fail_after(timeout):
        while True:
            for _, m in log:
                if m.command in commands:
                    log.remove((_, m))
                    return m
            await trio.sleep(0.05)


def dead_reckoned(log):
    """(x [cm], y [cm], heading [deg]) from the last NAV_POSE_* pair in ``log``."""
    xy = [m for _, m in log if m.command == Cmd.NAV_POSE_XY][-1].as_pair()
    hd = [m for _, m in log if m.command == Cmd.NAV_POSE_HEADING][-1].value
    return xy[0] / 10, xy[1] / 10, hd


def empty_room(slip_sigma: float | None):
    scenario = load_scenario("empty")
    if slip_sigma is None:
        return scenario
    return dataclasses.replace(scenario, devices={**scenario.devices, "slip_sigma": slip_sigma})


@pytest.mark.trio
@pytest.mark.parametrize(("slip", "tol", "seed"), [
    (0.0, 2.0, 1), (0.0, 2.0, 2), (None, 5.0, 1), (None, 5.0, 2)],
    ids=["noise-free-1", "noise-free-2", "default-slip-1", "default-slip-2"])
async def test_move_and_turn_land_close_in_the_simulated_world(autojump_clock, slip, tol,
                                                               seed) -> None:
    """A 100 cm move and a 90 deg turn land within ``tol`` cm / deg of the true pose
    (2 in a noise-free room; 5 with the default encoder slip noise)."""
    world = World(empty_room(slip), np.random.default_rng(seed))
    hw = world.hardware("hider")
    start = world.true_pose("hider")
    log: list = []
    async with trio.open_nursery() as nursery, open_actor_system(seed) as system:
        nursery.start_soon(run_world, world)
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        await system.send("hider/motor", Message.float(Cmd.MOTOR_MOVE, 100.0))
        done = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
        assert done.command == Cmd.NAV_MOTION_DONE
        assert done.value == pytest.approx(100.0, abs=1.0)
        p = world.true_pose("hider")
        travelled = math.hypot(p.x - start.x, p.y - start.y)
        assert travelled == pytest.approx(100.0, abs=tol)
        assert abs(angle_diff_deg(p.heading_deg, start.heading_deg)) < tol

        await system.send("hider/motor", Message.float(Cmd.MOTOR_TURN, 90.0))
        done = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
        assert done.command == Cmd.NAV_MOTION_DONE
        assert done.value == pytest.approx(90.0, abs=3.0)
        q = world.true_pose("hider")
        assert angle_diff_deg(q.heading_deg, p.heading_deg) == pytest.approx(90.0, abs=tol)
        assert math.hypot(q.x - p.x, q.y - p.y) < 2.0  # turned in place

        x, y, hd = dead_reckoned(log)
        assert x == pytest.approx(100.0, abs=1.0) and abs(y) < 1.0
        assert hd == pytest.approx(90.0, abs=2.5)
        nursery.cancel_scope.cancel()


@pytest.mark.trio
async def test_turn_back_and_forth_in_the_world_keeps_dead_reckoning_close(autojump_clock) -> None:
    """A square path (4 x (50 cm, 90 deg)) ends near the start, in truth and dead reckoning."""
    world = World(load_scenario("empty"), np.random.default_rng(3))
    hw = world.hardware("hider")
    start = world.true_pose("hider")
    log: list = []
    async with trio.open_nursery() as nursery, open_actor_system(3) as system:
        nursery.start_soon(run_world, world)
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        for _ in range(4):
            for cmd, v in ((Cmd.MOTOR_MOVE, 50.0), (Cmd.MOTOR_TURN, 90.0)):
                await system.send("hider/motor", Message.float(cmd, v))
                m = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
                assert m.command == Cmd.NAV_MOTION_DONE
        p = world.true_pose("hider")
        assert math.hypot(p.x - start.x, p.y - start.y) < 10.0
        x, y, _ = dead_reckoned(log)
        assert math.hypot(x, y) < 5.0
        nursery.cancel_scope.cancel()


class FakeHardware:
    """Records device commands; tests fire interrupts by calling the handlers."""

    def __init__(self) -> None:
        self.spec = HardwareSpec("hider", cm_per_interrupt=0.5, track_width_cm=13.0)
        self.handlers: dict = {}
        self.pwm: list[tuple[float, float]] = []

    def attach(self, line, handler) -> None:
        self.handlers[int(line)] = handler

    def set_tread_pwm(self, left, right) -> None:
        self.pwm.append((left, right))

    def set_lidar_pwm(self, duty) -> None: ...

    def set_ir_timer(self, rate_hz) -> None: ...

    def start_adc(self) -> None: ...

    def wifly_write(self, data) -> None: ...


@pytest.mark.trio
@pytest.mark.parametrize("seed", [1, 2, 3])
async def test_healthy_treads_of_the_simulated_world_stay_within_the_tread_model(
        autojump_clock, seed) -> None:
    """Moves, a square turn and a run of look turns (20 deg each) on the world's healthy
    treads, with its default slip noise: Motor Control reports no tread fault."""
    world = World(empty_room(None), np.random.default_rng(seed))
    hw = world.hardware("hider")
    log: list = []
    commands = [(Cmd.MOTOR_MOVE, 40.0), (Cmd.MOTOR_TURN, 90.0)] + \
        [(Cmd.MOTOR_TURN, 20.0)] * 9 + [(Cmd.MOTOR_MOVE, -30.0), (Cmd.MOTOR_TURN, -45.0),
                                        (Cmd.MOTOR_MOVE, 15.0)]
    async with trio.open_nursery() as nursery, open_actor_system(seed) as system:
        nursery.start_soon(run_world, world)
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        for command, amount in commands:
            await system.send("hider/motor", Message.float(command, amount))
            done = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
            assert done.command == Cmd.NAV_MOTION_DONE
        nursery.cancel_scope.cancel()
    assert tread_reports(log) == []


@pytest.mark.trio
async def test_no_encoder_progress_reports_blocked(autojump_clock) -> None:
    """Treads commanded with no Int E while the model says one went 3 cm (about 0.25 s from
    standing, the lag included): NAV_MOTION_BLOCKED and treads stopped."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        t0 = trio.current_time()
        await system.send("hider/motor", Message.float(Cmd.MOTOR_MOVE, 20.0))
        m = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
        assert m.command == Cmd.NAV_MOTION_BLOCKED and m.value == 0.0
        assert 0.15 <= trio.current_time() - t0 <= 0.4
        assert hw.pwm[-1] == (0.0, 0.0)
        assert max(left for left, _ in hw.pwm) > 0.5  # it did drive forward


@pytest.mark.trio
async def test_ticks_advance_the_pose_and_publish_it(autojump_clock) -> None:
    """Int E ticks move the pose: 20 left+right forward = 10 cm; 13 right only turns left."""
    hw = FakeHardware()
    log: list = []
    memory = PoseMemory()
    async with open_actor_system(1) as system:
        await system.start_supervisor(motor_tree(hw, memory, log), "hider")
        isr = hw.handlers[Interrupt.INT_E]
        for _ in range(20):
            isr(encode_counter(0, True))
            isr(encode_counter(1, True))
        await trio.sleep(0.2)
        assert dead_reckoned(log)[:2] == pytest.approx((10.0, 0.0), abs=0.05)
        for _ in range(13):  # 6.5 cm of the right tread on a 13 cm track: 0.5 rad left
            isr(encode_counter(1, True))
        await trio.sleep(0.2)
        assert dead_reckoned(log)[2] == pytest.approx(math.degrees(0.5), abs=0.1)
        assert memory.pose.heading_deg == pytest.approx(math.degrees(0.5), abs=0.01)


@pytest.mark.trio
async def test_restart_keeps_the_pose_and_reports_the_cut_command(autojump_clock) -> None:
    """A crash mid-move: the new incarnation republishes the same pose and says BLOCKED."""
    hw = FakeHardware()
    log: list = []
    memory = PoseMemory()
    async with open_actor_system(1) as system:
        tree = await system.start_supervisor(motor_tree(hw, memory, log), "hider")
        isr = hw.handlers[Interrupt.INT_E]
        await system.send("hider/motor", Message.float(Cmd.MOTOR_MOVE, 50.0))
        for _ in range(10):
            isr(encode_counter(0, True))
            isr(encode_counter(1, True))
        await trio.sleep(0.2)
        before = memory.pose
        system.inject_crash("hider/motor")
        m = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED}, timeout=2.0)
        assert m.command == Cmd.NAV_MOTION_BLOCKED
        assert [c.restarts for c in tree.which_children() if c.id == "motor"] == [1]
        assert memory.pose == before
        assert dead_reckoned(log)[0] == pytest.approx(5.0, abs=0.01)
        assert hw.pwm[-1] == (0.0, 0.0)


@pytest.mark.trio
async def test_get_pose_republishes_and_unknown_command_is_a_crash(autojump_clock) -> None:
    """MOTOR_GET_POSE publishes at once; an unknown command is poison, the motor restarts."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        await trio.sleep(0.1)
        log.clear()
        await system.send("hider/motor", Message.uint(Cmd.MOTOR_GET_POSE, 0))
        await trio.sleep(0.01)
        assert [m.command for _, m in log] == [Cmd.NAV_POSE_XY, Cmd.NAV_POSE_HEADING]
        down = system.monitor("hider/motor")
        await system.send("hider/motor", Message.uint(0x7777, 0))
        with trio.fail_after(1):
            notice = await down.receive()
        assert "unknown command" in str(notice.reason)


@pytest.mark.trio
async def test_the_mapper_motor_publishes_the_raw_odometry_pose_to_navigation_and_lidar(
        autojump_clock) -> None:
    """Motor Control knows no map frame: on MOTOR_GET_POSE navigation and the LIDAR both get
    the odometry pose as counted (navigation in mm, the LIDAR in cm), Map Management gets
    nothing, and a NOOP flood message is ignored (no restart)."""
    hw = FakeHardware()
    log: list = []
    lidar_log: list = []
    map_log: list = []
    memory = PoseMemory(Pose(100.0, -20.0, 90.0))
    spec = SupervisorSpec([
        ChildSpec("nav", lambda: Recorder(log), mailbox=256),
        ChildSpec("lidar", lambda: Recorder(lidar_log), mailbox=256),
        ChildSpec("map", lambda: Recorder(map_log), mailbox=256),
        ChildSpec("motor", lambda: MotorControl(hw, memory, lidar=True), mailbox=256,
                  watchdog=1.0),
    ])
    async with open_actor_system(1) as system:
        tree = await system.start_supervisor(spec, "mapper")
        await trio.sleep(0.1)
        log.clear()
        lidar_log.clear()
        system.send_nowait("mapper/motor", Message.int(Cmd.NOOP, 0))
        system.send_nowait("mapper/motor", Message.uint(Cmd.MOTOR_GET_POSE, 0))
        await trio.sleep(0.01)
        assert [m.command for _, m in log] == [Cmd.NAV_POSE_XY, Cmd.NAV_POSE_HEADING]
        assert dead_reckoned(log) == (100.0, -20.0, 90.0)
        assert [m.command for _, m in lidar_log] == [Cmd.LIDAR_POSE_XY, Cmd.LIDAR_POSE_HEADING]
        assert lidar_log[0][1].as_pair() == (100, -20) and lidar_log[1][1].value == 90.0
        assert map_log == []
        assert [c.restarts for c in tree.which_children() if c.id == "motor"] == [0]


async def drive_fake_treads(hw: FakeHardware, counts: tuple[float, float],
                            until: float, phase: tuple[float, float] = (0.0, 0.0)) -> None:
    """Stand-in for the treads and encoders: each tread goes as its last PWM says (30 cm/s
    at full duty, 80 ms lag) and counts ``counts[tread]`` of that travel (0: a stuck
    encoder, 0.5: a slipping one) as Int E every 0.5 cm, starting ``phase`` cm into an
    interrupt (the treads' interrupts need not come together)."""
    isr = hw.handlers[Interrupt.INT_E]
    speed = [0.0, 0.0]
    counted = list(phase)
    dt = 0.05
    while trio.current_time() < until:
        await trio.sleep(dt)
        left, right = hw.pwm[-1] if hw.pwm else (0.0, 0.0)
        for tread, duty in enumerate((left, right)):
            speed[tread] += (duty * 30.0 - speed[tread]) * (1.0 - math.exp(-dt / 0.08))
            counted[tread] += speed[tread] * dt * counts[tread]
            while abs(counted[tread]) >= 0.5:
                forward = counted[tread] > 0
                counted[tread] -= 0.5 if forward else -0.5
                isr(encode_counter(tread, forward))


@pytest.mark.trio
@pytest.mark.parametrize(("command", "amount"), [(Cmd.MOTOR_MOVE, 30.0),
                                                 (Cmd.MOTOR_TURN, -8.0)],
                         ids=["move", "small-turn"])
async def test_a_driven_tread_that_does_not_count_is_reported_at_once(
        autojump_clock, command, amount) -> None:
    """The right encoder stuck: NAV_TREAD_FAULT (value 1, the right tread) once, within
    about 2 cm of the left tread's travel; the command itself goes on."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system, trio.open_nursery() as nursery:
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
        t0 = trio.current_time()
        nursery.start_soon(drive_fake_treads, hw, (1.0, 0.0), t0 + 3.0)
        await system.send("hider/motor", Message.float(command, amount))
        m = await wait_for(log, {Cmd.NAV_TREAD_FAULT}, timeout=3.0)
        assert m.value == 1
        # the left tread counted four interrupts at most (the first 50 ms steps of a move
        # bring two or three at once): dead reckoning is at most 2 cm / 13 cm (8.8 deg) off
        assert abs(dead_reckoned(log)[2]) <= math.degrees(2.0 / 13.0) + 0.1
        await trio.sleep(3.0)
        assert [x for _, x in log if x.command == Cmd.NAV_TREAD_FAULT] == []  # only once
        nursery.cancel_scope.cancel()


FOUR = [(Cmd.MOTOR_MOVE, 40.0), (Cmd.MOTOR_TURN, 90.0), (Cmd.MOTOR_TURN, -8.0),
        (Cmd.MOTOR_MOVE, -10.0)]  # two moves and two turns, one of them too short to judge


async def run_commands(counts: tuple[float, float], commands: list, *, horizon: float,
                       timeout: float = 10.0, phase: tuple[float, float] = (0.0, 0.0),
                       **motor_kw) -> tuple[list, list]:
    """Motor Control (as the hider's) on fake treads counting ``counts`` of their travel,
    given ``commands`` one after another, each to its end. Returns what navigation was
    sent and, per command, how it ended and how long it took [s]."""
    hw = FakeHardware()
    log: list = []
    outcomes = []
    async with open_actor_system(1) as system, trio.open_nursery() as nursery:
        await system.start_supervisor(motor_tree(hw, PoseMemory(), log, **motor_kw), "hider")
        nursery.start_soon(drive_fake_treads, hw, counts, trio.current_time() + horizon, phase)
        for command, amount in commands:
            t0 = trio.current_time()
            await system.send("hider/motor", Message.float(command, amount))
            m = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED},
                               timeout=timeout)
            outcomes.append((m.command, trio.current_time() - t0))
        seen = list(log)
        nursery.cancel_scope.cancel()
    return seen, outcomes


def tread_reports(log: list) -> list[int]:
    """The NAV_TREAD_FAULT values navigation got, in order."""
    return [int(x.value) for _, x in log if x.command == Cmd.NAV_TREAD_FAULT]


@pytest.mark.trio
@pytest.mark.parametrize(("counts", "tread"), [((1.0, 1.0), None), ((0.0, 0.0), None),
                                               ((1.0, 0.5), 1), ((0.45, 1.0), 0)],
                         ids=["healthy", "both-silent", "right-half", "left-0.45"])
async def test_a_tread_that_counts_short_is_reported_once_per_command(autojump_clock, counts,
                                                                      tread) -> None:
    """Healthy treads give no NAV_TREAD_FAULT, both silent only value 4 in the turns (both
    blocked); a tread that counts about half of its travel (a slipping encoder) gives
    value 2 | tread in each command long enough to judge (its modelled travel reaches 5 cm:
    the moves and the 90 deg turn); in the 8 deg turn a tread counting 0.45 may be silent."""
    log, _ = await run_commands(counts, FOUR, horizon=20.0)
    reports = tread_reports(log)
    if tread is None:  # both silent: only the turns' value 4 (see the test below)
        assert reports == ([4, 4] if counts == (0.0, 0.0) else [])
    else:
        assert {r & 1 for r in reports} == {tread}
        assert [r for r in reports if r & 2] == [2 | tread] * 3


@pytest.mark.trio
@pytest.mark.parametrize(("counts", "blocked"), [((0.0, 0.0), True), ((0.3, 0.3), False),
                                                 ((1.0, 1.0), False)],
                         ids=["both-stuck", "both-0.3", "healthy"])
async def test_both_encoders_silent_block_within_a_few_cm(autojump_clock, counts,
                                                         blocked) -> None:
    """Both encoders stuck (nothing to compare with): NAV_MOTION_BLOCKED once the model
    says a tread went about 3 cm unseen, not after a second; treads counting 0.3 of their
    travel (a weak motor at 0.3 looks the same) and healthy ones finish every command."""
    log, outcomes = await run_commands(counts, [(Cmd.MOTOR_MOVE, 40.0), (Cmd.MOTOR_TURN, 90.0),
                                                (Cmd.MOTOR_MOVE, -10.0), (Cmd.MOTOR_TURN, -8.0)],
                                       horizon=60.0, timeout=20.0)
    assert all((c == Cmd.NAV_MOTION_BLOCKED) == blocked for c, _ in outcomes)
    if blocked:
        # at 24 cm/s cruise behind an 80 ms lag, 3 cm of modelled travel is about 0.25 s;
        # the 8 deg turn's treads have under 1 cm to go: the blocked timer (1 s) ends it
        assert all(dt <= 0.45 for _, dt in outcomes[:3]), outcomes
        assert 0.9 <= outcomes[3][1] <= 1.2
    # a turn blocked without a single Int E is a tread fault too (value 4: both
    # silent), sent before its end; moves are not (a rover against a wall)
    assert [r for r in tread_reports(log) if r == 4] == ([4, 4] if blocked else [])


def driven_reports(log: list) -> list[tuple[float, float]]:
    """The NAV_TREAD_DRIVEN values navigation got [cm], in order."""
    return [xy_half(x, MM) for _, x in log if x.command == Cmd.NAV_TREAD_DRIVEN]


@pytest.mark.trio
async def test_a_turn_on_stuck_encoders_reports_how_far_the_drive_model_went(
        autojump_clock) -> None:
    """Both encoders stuck in a 23 deg turn (2.6 cm a tread commanded): Motor Control
    ends it by its model once a tread went about 3 cm unseen, and the treads coast on
    after the stop, so the turn went beyond the command. NAV_TREAD_DRIVEN says how far
    (signed as driven: left back, right forward), after the report;
    healthy treads send none."""
    log, outcomes = await run_commands((0.0, 0.0), [(Cmd.MOTOR_TURN, 23.0)], horizon=10.0)
    kinds = [x.command for _, x in log if x.command in (
        Cmd.NAV_TREAD_FAULT, Cmd.NAV_TREAD_DRIVEN)]
    assert kinds == [Cmd.NAV_TREAD_FAULT, Cmd.NAV_TREAD_DRIVEN]
    assert outcomes[0][0] == Cmd.NAV_MOTION_BLOCKED
    [(left, right)] = driven_reports(log)
    commanded = 0.5 * 13.0 * math.radians(23.0)
    assert left < 0.0 < right
    assert commanded + 1.0 < right < 3.0 * commanded and left == pytest.approx(-right, abs=0.2)
    healthy, _ = await run_commands((1.0, 1.0), FOUR, horizon=20.0)
    assert driven_reports(healthy) == []


@pytest.mark.trio
@pytest.mark.parametrize("phase", [(0.0, 0.0), (0.0, 0.2), (0.35, 0.0), (0.0, 0.45)])
@pytest.mark.parametrize("counts", [(0.3, 0.3), (0.7, 0.7)], ids=["both-0.3", "both-0.7"])
async def test_both_treads_counting_alike_slowly_is_no_silent_tread(autojump_clock, counts,
                                                                    phase) -> None:
    """Both treads counting 0.3 of their modelled travel (two weak motors at 0.3, within
    the faults' range) or 0.7 (a rover pushing against something: each false report
    costs a blocked move and 10 deg more heading doubt) keep
    their counts together, however their interrupts interleave: no single tread is
    reported silent (value 0/1). Only the hider is driven, so no value 6 either."""
    log, _ = await run_commands(counts, [(Cmd.MOTOR_MOVE, 40.0), (Cmd.MOTOR_TURN, 90.0),
                                         (Cmd.MOTOR_MOVE, -10.0), (Cmd.MOTOR_TURN, -8.0),
                                         (Cmd.MOTOR_MOVE, 25.0), (Cmd.MOTOR_TURN, -45.0)],
                                horizon=60.0, timeout=20.0, phase=phase)
    assert [r for r in tread_reports(log) if not r & 2] == []


@pytest.mark.trio
@pytest.mark.parametrize(("counts", "lidar", "expected"), [
    ((0.45, 0.45), True, [6, 6, 6]), ((0.45, 0.45), False, [6, 6, 6]),
    ((0.6, 0.6), False, [6]), ((0.6, 0.6), True, [6, 6, 6]),
    ((1.0, 1.0), True, []), ((1.0, 0.45), True, [3, 3, 3])],
    ids=["both-short-mapper", "both-short-hider", "both-0.6-hider", "both-0.6-mapper",
         "healthy-mapper", "right-short-mapper"])
async def test_both_treads_counting_short_are_reported_to_the_mapper_and_in_turns(
        autojump_clock, counts, lidar, expected) -> None:
    """Both encoders slipping alike (each counts 0.45): navigation gets value 6 once in
    each command long enough to tell (the moves and the 90 deg turn), and no
    single-tread report with it. Both short in a hider's move must also count under
    ``BOTH_MOVE_RATIO``: counting 0.6 (a rover sliding along a wall counts 0.55-0.65)
    is reported in the turn only, the mapper's everywhere; one tread short is still
    reported as that tread. The 8 deg turn's 2.8 cm of modelled travel at 0.45 lie
    within a standard deviation of the model's reach, so whether it is reported too
    depends on where the interrupts fall."""
    log, _ = await run_commands(counts, FOUR, horizon=30.0, lidar=lidar)
    reports = [r for r in tread_reports(log) if r & 2]
    assert reports == expected or (counts == (0.45, 0.45) and reports == [6] * 4)


@pytest.mark.trio
@pytest.mark.parametrize(("counts", "expected"), [((0.8, 1.0), {2}), ((1.0, 0.8), {3}),
                                                  ((1.0, 1.0), set())],
                         ids=["left-0.8", "right-0.8", "healthy"])
async def test_a_tread_driven_harder_for_level_counts_counts_short_in_a_move(
        autojump_clock, counts, expected) -> None:
    """One encoder counting 0.8: the cross-coupling keeps the counts level, so only the
    PWM it needs shows it (23 deg turned unseen per 20 cm). In the 40 cm move that tread
    is reported as counting short; healthy treads are not (the difference of their
    uncounted travel stays within two interrupts' lags)."""
    log, _ = await run_commands(counts, [(Cmd.MOTOR_MOVE, 40.0)], horizon=10.0)
    assert set(tread_reports(log)) == expected


@pytest.mark.trio
async def test_both_treads_hardly_counting_lately_in_a_move_is_a_push(autojump_clock) -> None:
    """Both treads count right, then 0.12 of their travel (a rover sliding along a wall it met
    at an angle): the move ends blocked, without a value 6 (a push
    is not a fault to hold for); two slipping encoders counting 0.45 from the start are
    not a push (value 6, the move goes on to its count)."""
    for counts, push in (([1.0, 1.0], True), ([0.45, 0.45], False)):
        hw = FakeHardware()
        log: list = []
        async with open_actor_system(1) as system, trio.open_nursery() as nursery:
            await system.start_supervisor(motor_tree(hw, PoseMemory(), log), "hider")
            nursery.start_soon(drive_fake_treads, hw, counts, trio.current_time() + 20.0,
                               (0.0, 0.25))
            await system.send("hider/motor", Message.float(Cmd.MOTOR_MOVE, 60.0))
            await trio.sleep(0.5)
            if push:
                counts[:] = [0.12, 0.12]
            m = await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED}, timeout=15.0)
            assert (m.command == Cmd.NAV_MOTION_BLOCKED) == push
            assert tread_reports(log) == ([] if push else [6])
            nursery.cancel_scope.cancel()


@pytest.mark.trio
async def test_the_lidar_gets_each_new_pose_once_and_the_last_one(autojump_clock) -> None:
    """Turning on the mapper (every Int E turns the heading): each LIDAR_POSE pair the
    LIDAR gets has a heading other than the one before (a pose is not sent again by the
    control period), and the last is the pose at rest."""
    hw = FakeHardware()
    log: list = []
    lidar_log: list = []
    memory = PoseMemory()
    spec = SupervisorSpec([
        ChildSpec("nav", lambda: Recorder(log), mailbox=256),
        ChildSpec("lidar", lambda: Recorder(lidar_log), mailbox=4096),
        ChildSpec("map", lambda: Recorder([]), mailbox=256),
        ChildSpec("motor", lambda: MotorControl(hw, memory, lidar=True), mailbox=256),
    ])
    async with open_actor_system(1) as system, trio.open_nursery() as nursery:
        await system.start_supervisor(spec, "mapper")
        await trio.sleep(0.1)
        lidar_log.clear()  # the pose at start
        nursery.start_soon(drive_fake_treads, hw, (1.0, 1.0), trio.current_time() + 4.0)
        await system.send("mapper/motor", Message.float(Cmd.MOTOR_TURN, 90.0))
        await wait_for(log, {Cmd.NAV_MOTION_DONE, Cmd.NAV_MOTION_BLOCKED})
        await trio.sleep(0.5)
        nursery.cancel_scope.cancel()
    commands = [m.command for _, m in lidar_log]
    assert commands == [Cmd.LIDAR_POSE_XY, Cmd.LIDAR_POSE_HEADING] * (len(commands) // 2)
    headings = [m.value for _, m in lidar_log if m.command == Cmd.LIDAR_POSE_HEADING]
    assert len(headings) > 10  # it turned: one pose per step's Int E
    assert all(a != b for a, b in zip(headings, headings[1:], strict=False))
    assert headings[-1] == pytest.approx(memory.pose.heading_deg, abs=1e-4)  # float32
