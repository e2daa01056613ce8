"""Map Management in isolation: scans in, rate-limited snapshots and scan counts out."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
import trio

from actors import BufferPool, Message, ValueType, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import Scan
from actors.firmware.hardware import HardwareSpec
from actors.firmware.mapping.map_management import MapManagement
from actors.firmware.origin_wire import PoseHalves
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose, compose
from supervisors import ChildSpec, SupervisorSpec

from .test_fw_lidar import Recorder

BENCH = HardwareSpec.bench("mapper")


def ring_scan(n: int = 360, r: float = 100.0) -> Scan:
    from server.protocol.pose import Pose
    return Scan(Pose(), np.arange(n, dtype=np.float32) * (360 / n),
                np.full(n, r, dtype=np.float32))


@pytest.mark.trio
async def test_map_management_rate_limits_updates_and_counts_scans(autojump_clock) -> None:
    """Ten identical scans in a burst: one snapshot and count at once (the hits), one more
    when the timer fires (the second scan confirmed the free space), then only counts
    (the map did not change, the scans kept arriving)."""
    pool, log = BufferPool(64), []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(400, 400),
                                                                  publish_s=0.25,
                                                                  matching=None))])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(10):
            system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.01)
        assert [c for c, _ in log] == [Cmd.NAV_MAP_UPDATE, Cmd.NAV_SCAN_COUNT]
        await trio.sleep(0.3)
        updates = [p for c, p in log if c == Cmd.NAV_MAP_UPDATE]
        counts = [p for c, p in log if c == Cmd.NAV_SCAN_COUNT]
        assert len(updates) == 2 and counts == [1, 10]
        snap = updates[-1]
        assert isinstance(snap, GridMap)
        r, c = snap.world_to_cell(101.0, 0.0)
        assert snap.cells[r, c] == 100
        assert snap.cells[snap.world_to_cell(50.0, 0.0)] == 0
        log.clear()
        await system.send("mapper/map", Message.uint(Cmd.MAP_GET, 0))
        await trio.sleep(0.01)
        assert [c for c, _ in log] == [Cmd.NAV_MAP_UPDATE, Cmd.NAV_SCAN_COUNT]


@pytest.mark.trio
async def test_restarted_map_says_lost_and_restores_from_a_snapshot(autojump_clock) -> None:
    """After a crash the new grid is empty, NAV_MAP_LOST goes out, MAP_RESTORE seeds it."""
    pool, log = BufferPool(64), []
    starts = [0]

    def make_map():
        starts[0] += 1
        return MapManagement(pool, BENCH, size_cm=(400, 400), restarted=starts[0] > 1)
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("map", make_map)])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        await system.send("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.01)
        before = [p for c, p in log if c == Cmd.NAV_MAP_UPDATE][-1]
        system.inject_crash("mapper/map")
        await trio.sleep(0.5)
        assert (Cmd.NAV_MAP_LOST, 0) in log
        log.clear()
        await system.send("mapper/map", Message.handle(Cmd.MAP_RESTORE, pool.put(before)))
        await trio.sleep(0.01)
        after = [p for c, p in log if c == Cmd.NAV_MAP_UPDATE][-1]
        assert np.array_equal(after.cells, before.cells)


@pytest.mark.trio
async def test_flood_of_noops_costs_dropped_messages_not_restarts(autojump_clock) -> None:
    """Flooding ``mapper/map`` with NOOPs while the LIDAR streams scans costs queue slots,
    not crashes: a crash per NOOP would make the supervisor give up. The
    flood only fills the queue: the LIDAR drops (and frees) the scans that do not fit, the
    map is never restarted, no pool slot leaks, and scans integrate again afterwards."""
    from actors.firmware.drivers.lidar import LidarControl

    from .test_fw_motor import FakeHardware

    hw, pool, log = FakeHardware(), BufferPool(8), []
    hw.set_lidar_pwm = lambda d: None
    starts = [0]

    def make_map():
        starts[0] += 1
        return MapManagement(pool, BENCH, size_cm=(400, 400), restarted=starts[0] > 1,
                             matching=None)
    lidar_holder = []

    def make_lidar():
        lidar_holder.append(LidarControl(hw, pool))
        return lidar_holder[-1]
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool), mailbox=4096),
                           ChildSpec("map", make_map, mailbox=64),
                           ChildSpec("lidar", make_lidar, mailbox=4096)],
                          intensity=3, period=10.0)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")

        def tick(k: int) -> None:
            for a in range(0, 3600, 100):
                system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_SAMPLE, a, 150))
            system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_POSE_XY, k % 3, 0))
            system.send_nowait("mapper/lidar", Message.float(Cmd.LIDAR_POSE_HEADING, 0.0))

        for k in range(5):
            tick(k)
            await trio.sleep(0.05)
        system.inject_hang("mapper/map", 0.3)  # busy: the flood cannot drain meanwhile
        await trio.sleep(0.01)
        accepted = system.flood("mapper/map", 500, Message.int(Cmd.NOOP, 0))
        assert 0 < accepted < 500  # the queue filled: the rest of the flood was dropped
        for k in range(5):  # scans keep coming while the queue is full
            tick(k)
            await trio.sleep(0.05)
        await trio.sleep(0.5)
        for k in range(5):
            tick(k)
            await trio.sleep(0.05)
        await trio.sleep(0.5)
        live_map = system.whereis("mapper/map").actor
        assert starts[0] == 1  # never restarted
        assert live_map.noops == accepted
        assert lidar_holder[-1].dropped_scans >= 1  # what did not fit was dropped...
        assert live_map.scans >= 9  # ...and scanning resumed after the flood
        assert pool.statistics().in_use == 0  # every dropped scan gave its slot back


def _stray_walls(before: np.ndarray, after: np.ndarray) -> int:
    """Occupied cells of ``after`` more than one cell from every occupied cell of ``before``."""
    occ = np.pad(before == 100, 1)
    near = np.zeros_like(before, dtype=bool)
    ny, nx = before.shape
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            near |= occ[dr:dr + ny, dc:dc + nx]
    return int(np.count_nonzero((after == 100) & ~near))


def _room_scans(pose_true, n: int = 120):
    """A box-room scan taken at ``pose_true`` (ranges from the true pose)."""
    from .test_scan_match import ray_scan, room_map
    return ray_scan(room_map(), pose_true, n)


def _map_tree(pool: BufferPool, log: list, **options) -> SupervisorSpec:
    """Map Management (a 10 x 10 m map, ``options``) beside a recorder standing in for
    navigation."""
    return SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(1000, 1000),
                                                                  **options))])


def _send_room_scan(system, pool: BufferPool, odom, taken_at) -> None:
    """A box-room scan taken at ``taken_at``, sent to Map Management as taken at ``odom``
    (the pose odometry gives)."""
    a, r = _room_scans(taken_at)
    system.send_nowait("mapper/map", Message.handle(
        Cmd.MAP_SCAN, pool.put(Scan(odom, a.astype(np.float32), r.astype(np.float32)))))


def origin_sent(log: list) -> Pose | None:
    """The correction Map Management last told navigation (``NAV_MAP_ORIGIN_XY`` then
    ``NAV_MAP_ORIGIN_HEADING``), read as navigation reads it; None when it sent none."""
    halves, sent = PoseHalves(), None
    for cmd, value in log:
        if cmd == Cmd.NAV_MAP_ORIGIN_XY:
            halves.take_xy(Message(cmd, ValueType.INT16X2, value))
        elif cmd == Cmd.NAV_MAP_ORIGIN_HEADING:
            sent = halves.take_heading(Message(cmd, ValueType.FLOAT32, value)) or sent
    return sent


def map_pose_sent(log: list, odom: Pose) -> Pose:
    """Where Map Management's messages put the rover whose odometry says ``odom``: the
    origin it last sent navigation (the identity before any) composed with ``odom``, as
    navigation computes its map pose."""
    return compose(origin_sent(log) or Pose(), odom)


def ring_hit(at: Pose, bearing_deg: float, r: float = 100.0) -> tuple[float, float]:
    """Where the ray ``bearing_deg`` of `ring_scan` taken at ``at`` (map frame) ends."""
    h = math.radians(at.heading_deg + bearing_deg)
    return at.x + r * math.cos(h), at.y + r * math.sin(h)


async def map_sent(system, log: list) -> np.ndarray:
    """The cells of the map Map Management sends navigation when asked (``MAP_GET``)."""
    system.send_nowait("mapper/map", Message.uint(Cmd.MAP_GET, 0))
    await trio.sleep(0.01)
    return [p for c, p in log if c == Cmd.NAV_MAP_UPDATE][-1].cells


def occupied_at(log: list, x: float, y: float) -> bool:
    """Whether the last snapshot Map Management sent navigation has (x, y) [cm] occupied."""
    snap = [p for c, p in log if c == Cmd.NAV_MAP_UPDATE][-1]
    return bool(snap.cells[snap.world_to_cell(x, y)] == 100)


@pytest.mark.trio
async def test_scans_with_a_heading_error_are_matched_onto_the_map(autojump_clock) -> None:
    """The rover turned 90 deg and odometry counted 94 (4 deg more than the truth, two
    standard deviations of what the motion model allows a 94 deg turn): the scans are
    registered onto the walls the reference scans drew, the correction (about -4 deg)
    goes to navigation as its origin (Motor Control hears nothing of it), and the wall
    stays one band thick instead of being drawn twice."""
    from server.protocol.pose import Pose

    pool, log, motor_log = BufferPool(64), [], []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("motor", lambda: Recorder(motor_log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(1000, 1000),
                                                                  warmup_scans=3))])
    truth = Pose(120.0, 80.0, 0.0)
    a, r = _room_scans(truth)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):  # the reference, at the true pose
            system.send_nowait("mapper/map", Message.handle(
                Cmd.MAP_SCAN, pool.put(Scan(truth, a.astype(np.float32), r.astype(np.float32)))))
        await trio.sleep(0.6)
        mm = system.whereis("mapper/map").actor
        before = await map_sent(system, log)
        turned = Pose(truth.x, truth.y, 90.0)
        a, r = _room_scans(turned)
        odom = Pose(truth.x, truth.y, 94.0)
        for _ in range(4):
            system.send_nowait("mapper/map", Message.handle(
                Cmd.MAP_SCAN, pool.put(Scan(odom, a.astype(np.float32), r.astype(np.float32)))))
            await trio.sleep(0.3)
        assert mm.matched >= 1
        # (the rest: later)
        assert origin_sent(log).heading_deg == pytest.approx(-4.0, abs=2.0)
        after = await map_sent(system, log)
        assert _stray_walls(before, after) <= 3  # no second wall (without matching: > 10)
        origin = [(c, p) for c, p in log
                  if c in (Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING)]
        assert origin and [c for c, _ in origin[-2:]] == [Cmd.NAV_MAP_ORIGIN_XY,
                                                          Cmd.NAV_MAP_ORIGIN_HEADING]
        assert map_pose_sent(log, odom).heading_deg == pytest.approx(turned.heading_deg, abs=2.0)
        assert motor_log == []


@pytest.mark.trio
async def test_a_batch_with_an_unchanged_odometry_stamp_is_matched_until_the_rover_stands(
        autojump_clock) -> None:
    """A turning rover's batch can carry the previous stamp (no Int E in its tick): once
    the stamps stood three batches (a motion's end) the window is matched onto the walls,
    not placed at the old pose (the correction follows it most of the way: a stamp's own
    error while turning is up to the step between two stamps), and the stopped rover's
    windows are matched until ``settle_s`` of unchanged odometry has passed; then they
    are placed unmatched (the rover stands)."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3, settle_s=1.0)
    truth = Pose(120.0, 80.0, 0.0)

    def send(system, odom: Pose, taken_at: Pose) -> None:
        _send_room_scan(system, pool, odom, taken_at)

    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):  # the reference, at the true pose
            send(system, truth, truth)
        await trio.sleep(0.6)
        mm = system.whereis("mapper/map").actor
        odom = Pose(truth.x + 0.6, truth.y, 0.0)
        send(system, odom, truth)  # odometry moved: gathered
        await trio.sleep(0.05)
        assert mm.matched == 0
        for _ in range(3):  # turned 3 deg, same stamp: the third ends the motion
            send(system, odom, Pose(truth.x, truth.y, 3.0))
            await trio.sleep(0.05)
        assert mm.matched == 1
        await trio.sleep(0.3)  # the update goes out
        assert 1.0 < origin_sent(log).heading_deg < 3.5  # (kept at 0 it would be 3 deg off)
        for _ in range(25):  # standing 1.25 s: matched for settle_s, then left alone
            send(system, odom, Pose(truth.x, truth.y, 3.0))
            await trio.sleep(0.05)
        standing = mm.matched
        assert 1 < standing < 1 + 25
        for _ in range(5):
            send(system, odom, Pose(truth.x, truth.y, 3.0))
            await trio.sleep(0.05)
        assert mm.matched == standing
        assert mm.scans + mm.unplaced == 3 + 4 + 25 + 5


@pytest.mark.trio
async def test_without_matching_a_heading_error_draws_a_second_wall(autojump_clock) -> None:
    """The same scans with matching off: the map grows a rotated copy of the walls (the
    failure the matching prevents)."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(1000, 1000),
                                                                  matching=None))])
    truth = Pose(120.0, 80.0, 0.0)
    a, r = _room_scans(truth)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for pose in [truth] * 3 + [Pose(truth.x, truth.y, 4.0)] * 3:
            system.send_nowait("mapper/map", Message.handle(
                Cmd.MAP_SCAN, pool.put(Scan(pose, a.astype(np.float32), r.astype(np.float32)))))
            await trio.sleep(0.3)
            if pose is truth:
                before = await map_sent(system, log)
        after = await map_sent(system, log)
        assert _stray_walls(before, after) > 10


@pytest.mark.trio
async def test_restarted_map_takes_the_correction_back_from_navigation(autojump_clock) -> None:
    """A restarted Map Management says NAV_MAP_LOST to navigation (Motor Control hears
    nothing), drops scans until navigation's MAP_ORIGIN_* arrives, then uses that origin
    as its correction; an unpaired heading is no origin."""
    from server.protocol.pose import Pose

    pool, log, motor_log = BufferPool(64), [], []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("motor", lambda: Recorder(motor_log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(400, 400),
                                                                  restarted=True))])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        await trio.sleep(0.01)
        assert log == [(Cmd.NAV_MAP_LOST, 0)] and motor_log == []
        system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.01)
        mm = system.whereis("mapper/map").actor
        assert mm.held_scans == 1 and mm.scans == 0
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_ORIGIN_XY, 125, -40))
        system.send_nowait("mapper/map", Message.float(Cmd.MAP_ORIGIN_HEADING, 2.5))
        system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.3)  # the update goes out
        # the scan (taken at odometry's origin) is placed by navigation's origin
        moved = Pose(12.5, -4.0, 2.5)
        assert all(occupied_at(log, *ring_hit(moved, a)) for a in (0.0, 180.0))
        assert not occupied_at(log, *ring_hit(Pose(), 180.0))
        assert mm.scans == 1
        assert pool.statistics().in_use == 0
        # the correction navigation has is not sent back to it
        assert not [c for c, _ in log if c in (Cmd.NAV_MAP_ORIGIN_XY,
                                                Cmd.NAV_MAP_ORIGIN_HEADING)]


@pytest.mark.trio
async def test_restarted_map_waits_a_bounded_time_for_navigations_origin(autojump_clock) -> None:
    """No answer from navigation: scans are dropped for 1 s, then placed with the identity;
    a late or unpaired MAP_ORIGIN_HEADING changes nothing."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("map", lambda: MapManagement(pool, BENCH, size_cm=(400, 400),
                                                                  restarted=True))])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        await trio.sleep(0.5)
        system.send_nowait("mapper/map", Message.float(Cmd.MAP_ORIGIN_HEADING, 7.0))
        system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.01)
        mm = system.whereis("mapper/map").actor
        assert mm.held_scans == 0 and mm.scans == 1
        await trio.sleep(1.0)
        assert all(occupied_at(log, *ring_hit(Pose(), a)) for a in (0.0, 180.0))  # identity
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_ORIGIN_XY, 125, -40))
        system.send_nowait("mapper/map", Message.float(Cmd.MAP_ORIGIN_HEADING, 2.5))
        system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(ring_scan())))
        await trio.sleep(0.3)
        assert mm.scans == 2 and not occupied_at(log, *ring_hit(Pose(12.5, -4.0, 2.5), 180.0))


@pytest.mark.trio
async def test_flooding_the_map_mid_game_costs_drops_and_mapping_still_completes(
        autojump_clock) -> None:
    """End to end: mapping the empty room, ``mapper/map`` flooded with
    NOOPs twice; no actor restarts, the flood shows as drops, the mapper finishes and
    uploads its map by itself."""
    from server.store import Store
    from supervisors.system import open_sim_system
    from world import load_scenario

    with Store(":memory:") as store:
        async with open_sim_system(load_scenario("empty"), seed=1, store=store) as system:
            with trio.fail_after(30):
                while len(system.server.snapshot().rovers) < 3:
                    await trio.sleep(0.1)
            assert (await system.command("start_mapping")).ok
            for _ in range(2):
                await trio.sleep(3.0)
                system.inject_fault("mapper/map", "flood", messages=500)
            with trio.fail_after(300):
                while system.server.snapshot().map is None:
                    await trio.sleep(1.0)
            assert system.restarts() == 0
            assert system.actors.statistics("mapper/map").dropped > 0
            assert system.actors.whereis("mapper/map").actor.noops >= 2 * 64 - 10


def test_an_odometry_stamp_across_the_heading_wrap_is_the_same_stamp() -> None:
    """179.9 and -179.95 deg are 0.15 deg apart: a rover standing there stands (it was
    read as moved, so its batches were matched again for nothing)."""
    from actors.firmware.mapping.scan_window import same_stamp
    from server.protocol.pose import Pose

    assert same_stamp(Pose(10.0, 5.0, 179.9), Pose(10.2, 5.0, -179.95))
    assert not same_stamp(Pose(10.0, 5.0, 179.9), Pose(10.0, 5.0, -179.0))
    assert not same_stamp(Pose(10.0, 5.0, 0.0), None)


async def _reference(system, spec: SupervisorSpec, send_truth, log: list) -> tuple:
    """Start the map tree ``spec`` and give it three reference batches (``send_truth``
    sends one taken at the true pose; ``log`` records what navigation is sent); returns
    Map Management, the cells of the map it sends then (`map_sent`) and its scan count."""
    await system.start_supervisor(spec, "mapper")
    for _ in range(3):
        send_truth()
    await trio.sleep(0.6)
    mm = system.whereis("mapper/map").actor
    return mm, await map_sent(system, log), mm.scans


@pytest.mark.trio
async def test_a_both_silent_turn_widens_the_belief_and_the_wide_search_refinds_the_pose(
        autojump_clock) -> None:
    """A 90 deg turn that ended with both treads silent (MAP_TREAD_FAULT: each tread driven
    10 cm beyond its count of 0) while the rover really turned 50 deg: the belief's 95 %
    heading grows past the local match's reach (by the motion model: two silent treads,
    nothing added by hand), the batches are not placed at the stale pose (which would draw
    the room turned), the wide search over the belief's bounds finds the heading, the
    belief narrows again, and the walls are not drawn a second time."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3)
    truth, turned = Pose(120.0, 80.0, 0.0), Pose(120.0, 80.0, 50.0)

    def send(system, taken_at: Pose) -> None:
        _send_room_scan(system, pool, truth, taken_at)

    async with open_actor_system(1) as system:
        mm, before, scans = await _reference(system, spec, lambda: send(system, truth), log)
        assert not mm.wide(mm.matching)
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_TREAD_FAULT, -102, 102))
        await trio.sleep(0.01)
        assert mm.wide(mm.matching)  # wider than the local match reaches
        system.send_nowait("mapper/map", Message.uint(Cmd.MAP_GET, 0))
        await trio.sleep(0.01)
        assert map_pose_sent(log, truth).heading_deg == pytest.approx(45.0, abs=1.0)  # halfway
        for _ in range(12):  # 0.1 s apart: a search every 0.5 s, the rest dropped
            send(system, turned)
            await trio.sleep(0.1)
        assert mm.searched >= 1
        assert not mm.wide(mm.matching)
        assert mm.scans > scans  # placed again once found
        # (2 stray: rays 3 deg apart land elsewhere)
        assert _stray_walls(before, await map_sent(system, log)) <= 3
        await trio.sleep(0.3)  # the last update goes out
        assert origin_sent(log).heading_deg == pytest.approx(50.0, abs=1.5)


@pytest.mark.trio
async def test_a_batch_taken_while_the_rover_coasts_after_a_tread_report_is_not_its_rest_pose(
        autojump_clock) -> None:
    """Both encoders stuck (odometry has not changed for over ``settle_s``) in a turn:
    MAP_TREAD_FAULT comes as the PWM stops, with the travel the drive model gives up to
    rest, and the belief widens round the halfway heading. The rover still coasts: the
    first batches after the report show it at 30 deg, then it rests at 50. A batch taken
    before rest is not the pose the report predicts, so no wide search runs for
    ``settle_s`` after the report; the search on the rover at rest finds 50 deg, the
    batches are placed there (not at the coasting pose, which the frozen stamps would
    keep as "standing"), and the walls are not drawn a second time."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3, settle_s=1.0)
    truth = Pose(120.0, 80.0, 0.0)
    coasting, resting = Pose(120.0, 80.0, 30.0), Pose(120.0, 80.0, 50.0)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):  # the reference, at the true pose
            _send_room_scan(system, pool, truth, truth)
        await trio.sleep(1.2)  # the stamps stand still longer than settle_s
        mm = system.whereis("mapper/map").actor
        before = await map_sent(system, log)
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_TREAD_FAULT, -102, 102))
        await trio.sleep(0.01)
        assert mm.wide(mm.matching)
        for k in range(30):  # the stamp never changes (both encoders stuck)
            _send_room_scan(system, pool, truth, coasting if k < 3 else resting)
            await trio.sleep(0.1)
        assert mm.refusals["coasting"] >= 3
        assert mm.searched >= 1
        await trio.sleep(0.3)  # the last update goes out
        assert map_pose_sent(log, truth).heading_deg == pytest.approx(50.0, abs=1.5)
        assert not mm.wide(mm.matching)
        assert _stray_walls(before, await map_sent(system, log)) <= 3


def _symmetric_room(kind: str) -> np.ndarray:
    """Occupied cells (origin (-100, -100), 5 cm, as `room_map`) of a room whose view
    from (150, 100) fits several headings alike: a 200 x 200 cm square (four headings
    90 deg apart), or a 400 cm corridor 100 cm wide (two headings 180 deg apart)."""
    occ = np.zeros((80, 100), dtype=bool)
    if kind == "square":  # x 50..250, y 0..200
        occ[20, 30:71] = occ[60, 30:71] = True
        occ[20:61, 30] = occ[20:61, 70] = True
    else:  # corridor: x -50..350, y 50..150
        occ[30, 10:91] = occ[50, 10:91] = True
        occ[30:51, 10] = occ[30:51, 90] = True
    return occ


@pytest.mark.trio
@pytest.mark.parametrize("room", ["square", "corridor", "box room"])
async def test_a_wide_search_narrows_the_belief_only_on_a_view_that_tells_headings_apart(
        room, autojump_clock) -> None:
    """A belief widened to every heading (two silent treads driven 40 cm beyond their
    counts) is searched wide. In a square room, or a corridor seen from its middle, the
    scan fits several headings alike: none is taken, the belief stays wide and the
    batches are dropped (`ambiguous`), nothing is drawn. In the box room the box tells
    the headings apart: the search finds the one the rover has and the belief narrows."""
    from server.protocol.pose import Pose

    from .test_scan_match import ray_scan, room_map

    occ = room_map() if room == "box room" else _symmetric_room(room)
    truth = Pose(150.0, 100.0, 0.0) if room != "box room" else Pose(120.0, 80.0, 0.0)
    turned = Pose(truth.x, truth.y, 90.0 if room == "square" else 180.0)
    if room == "box room":
        turned = Pose(truth.x, truth.y, 120.0)
    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3)

    def send(system, taken_at: Pose) -> None:
        a, r = ray_scan(occ, taken_at, 120)
        system.send_nowait("mapper/map", Message.handle(
            Cmd.MAP_SCAN, pool.put(Scan(truth, a.astype(np.float32), r.astype(np.float32)))))

    async with open_actor_system(1) as system:
        mm, before, scans = await _reference(system, spec, lambda: send(system, truth), log)
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_TREAD_FAULT, -400, 400))
        await trio.sleep(0.01)
        assert mm.wide(mm.matching)
        for _ in range(40):
            send(system, turned)
            await trio.sleep(0.1)
        if room == "box room":
            assert mm.searched >= 1 and not mm.wide(mm.matching)
            await trio.sleep(0.3)  # the last update goes out
            assert map_pose_sent(log, truth).heading_deg == pytest.approx(120.0, abs=1.5)
            assert _stray_walls(before, await map_sent(system, log)) <= 3
        else:
            assert mm.searched == 0 and mm.refusals["ambiguous"] >= 3
            assert mm.wide(mm.matching)
            assert mm.scans == scans and (await map_sent(system, log) == before).all()


@pytest.mark.trio
async def test_a_match_outside_the_belief_is_refused_and_counted_not_placed(
        autojump_clock) -> None:
    """The rover stands still (odometry unchanged) and a batch arrives drawn from a pose
    5 deg off: scan matching fits it there (a good fit), but the belief has not moved, so
    the scan likelihood's gate refuses it. The batch is dropped and counted under its
    reason, the correction stays, and nothing goes to navigation."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3, settle_s=10.0)
    truth = Pose(120.0, 80.0, 0.0)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):
            _send_room_scan(system, pool, truth, truth)
        await trio.sleep(0.6)
        mm = system.whereis("mapper/map").actor
        log.clear()
        scans = mm.scans
        _send_room_scan(system, pool, truth, Pose(truth.x, truth.y, 5.0))
        await trio.sleep(0.3)
        assert mm.refusals == {"outside the belief": 1}
        assert mm.scans == scans and origin_sent(log) is None
        assert not [c for c, _ in log if c in (Cmd.NAV_MAP_ORIGIN_XY,
                                                Cmd.NAV_MAP_ORIGIN_HEADING)]



@pytest.mark.trio
async def test_an_unseen_turn_of_a_standing_rover_is_refound_not_drawn(autojump_clock) -> None:
    """The same batches without MAP_TREAD_FAULT: odometry stands and the narrow belief says
    0 deg while the rover turned 50 deg. The scans fit badly at the mean and the local
    match cannot reach the truth: they are dropped, not placed at the stale heading, and
    they weigh for the "odometry broke unseen" hypothesis until it is the more probable.
    The belief then becomes its wide component, the wide search re-finds the heading,
    and the room is not drawn a second time (the gate does not lock the truth out)."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3)
    truth, turned = Pose(120.0, 80.0, 0.0), Pose(120.0, 80.0, 50.0)
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for k in range(3 + 30):
            _send_room_scan(system, pool, truth, truth if k < 3 else turned)
            await trio.sleep(0.1)
            if k == 2:
                mm = system.whereis("mapper/map").actor
                before, scans = await map_sent(system, log), mm.scans
            elif k == 3:  # the first bad scan alone does not outweigh the prior
                assert mm.searched == 0 and mm.scans == scans and not mm.wide(mm.matching)
        assert mm.refusals["odometry in doubt"] == 1
        assert mm.searched >= 1 and mm.scans > scans
        await trio.sleep(0.3)  # the last update goes out
        assert origin_sent(log).heading_deg == pytest.approx(50.0, abs=1.5)
        assert not mm.wide(mm.matching)
        assert _stray_walls(before, await map_sent(system, log)) <= 3  # (the rotated copy drew 102)


@pytest.mark.trio
async def test_frozen_stamps_of_a_rover_that_turns_unseen_are_not_read_as_standing(
        autojump_clock) -> None:
    """The rover stood and its batches were placed unmatched (odometry unchanged for
    ``settle_s``, the last match at the same stamp). Both encoders then stop counting
    and the rover turns 30 deg before Motor Control says anything: the stamps stay
    frozen, but the scans fit badly at the belief's mean, so they are not placed there;
    they are matched and weighed, the "odometry broke unseen" hypothesis takes over,
    the wide search finds the heading, and the room is not drawn a second time."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3, settle_s=1.0)
    truth, turned = Pose(120.0, 80.0, 0.0), Pose(120.0, 80.0, 30.0)
    odom = Pose(truth.x + 0.6, truth.y, 0.0)  # a stamp off the reference's: matched
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):  # the reference
            _send_room_scan(system, pool, truth, truth)
        await trio.sleep(0.1)
        mm = system.whereis("mapper/map").actor
        for _ in range(15):  # standing: matched, then placed unmatched after settle_s
            _send_room_scan(system, pool, odom, truth)
            await trio.sleep(0.1)
        matched, before, unplaced = mm.matched, await map_sent(system, log), mm.unplaced
        assert matched >= 1
        for _ in range(3):
            _send_room_scan(system, pool, odom, truth)
            await trio.sleep(0.1)
        assert (mm.matched, mm.unplaced) == (matched, unplaced)  # the standing shortcut
        for _ in range(30):  # turned unseen: the same stamp
            _send_room_scan(system, pool, odom, turned)
            await trio.sleep(0.1)
        assert mm.searched >= 1
        await trio.sleep(0.3)  # the last update goes out
        assert map_pose_sent(log, odom).heading_deg == pytest.approx(30.0, abs=1.5)
        assert _stray_walls(before, await map_sent(system, log)) <= 3


@pytest.mark.trio
async def test_a_slip_the_encoders_did_not_report_is_recovered(autojump_clock) -> None:
    """A 90 deg turn counted as 60 (an encoder slipping unseen, Motor Control reporting
    nothing): batch by batch the odometry falls behind the truth, the narrow belief's
    gate refuses what the scans say, and the scans weigh for "odometry broke unseen".
    The mapper re-finds the heading within a few batches after the turn instead of
    mapping the room rotated, and its belief holds the truth again."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    spec = _map_tree(pool, log, warmup_scans=3)
    x, y = 120.0, 80.0
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        for _ in range(3):
            _send_room_scan(system, pool, Pose(x, y, 0.0), Pose(x, y, 0.0))
            await trio.sleep(0.1)
        before = await map_sent(system, log)
        for k in range(1, 4):  # the turn: 20 deg counted, 30 deg turned per batch
            _send_room_scan(system, pool, Pose(x, y, 20.0 * k), Pose(x, y, 30.0 * k))
            await trio.sleep(0.05)
        for _ in range(30):  # standing at 90 deg, odometry at 60
            _send_room_scan(system, pool, Pose(x, y, 60.0), Pose(x, y, 90.0))
            await trio.sleep(0.1)
        await trio.sleep(0.3)  # the last update goes out
        assert origin_sent(log).heading_deg == pytest.approx(30.0, abs=2.0)
        assert map_pose_sent(log, Pose(x, y, 60.0)).heading_deg == pytest.approx(90.0, abs=2.0)
        assert _stray_walls(before, await map_sent(system, log)) <= 6


def _send_room_part(system, pool: BufferPool, odom, taken_at, part: int) -> None:
    """A quarter of a box-room revolution (rays ``part * 90`` to ``part * 90 + 90`` deg
    of the rover frame) taken at ``taken_at``, sent as taken at ``odom``: one world tick's
    batch."""
    a, r = _room_scans(taken_at)
    quarter = slice((part % 4) * 30, (part % 4) * 30 + 30)
    system.send_nowait("mapper/map", Message.handle(Cmd.MAP_SCAN, pool.put(
        Scan(odom, a[quarter].astype(np.float32), r[quarter].astype(np.float32)))))


@contextlib.asynccontextmanager
async def _mapped(**options):
    """Map Management (``options``, 3 warm-up batches) with its reference: three whole
    revolutions at the true pose (120, 80) @ 0; yields (system, pool, map, true pose,
    what navigation was sent)."""
    from server.protocol.pose import Pose

    pool, log = BufferPool(64), []
    truth = Pose(120.0, 80.0, 0.0)
    async with open_actor_system(1) as system:
        await system.start_supervisor(_map_tree(pool, log, warmup_scans=3, **options),
                                      "mapper")
        for _ in range(3):
            _send_room_scan(system, pool, truth, truth)
        await trio.sleep(0.6)
        yield system, pool, system.whereis("mapper/map").actor, truth, log


async def _drive(system, pool: BufferPool, truth, mm: MapManagement, batches: int = 2):
    """``batches`` quarter revolutions while driving 1 cm per tick along x from
    ``truth``; none is fused yet (the window gathers them). Returns the last stamp."""
    from server.protocol.pose import Pose

    scans, matched = mm.scans, mm.matched
    for k in range(batches):
        pose = Pose(truth.x + k + 1.0, truth.y, 0.0)
        _send_room_part(system, pool, pose, pose, k)
        await trio.sleep(0.05)
        assert (mm.scans, mm.matched) == (scans, matched)  # gathered
    return pose


@pytest.mark.trio
async def test_a_motions_end_is_processed_though_the_rover_moved_less_than_update_min_cm(
        autojump_clock) -> None:
    """A 2 cm drive (under ``update_min_cm``): batches whose stamps move are gathered,
    and a batch or two whose stamp did not move is a pause, not a cut; the revolution is
    a window that only predicts, but the third batch in a row whose stamp did not move
    (the motion ended) closes a window that is processed (matched and fused)."""
    async with _mapped() as (system, pool, mm, truth, log):
        scans, matched, windows = mm.scans, mm.matched, mm.windows
        pose = await _drive(system, pool, truth, mm)
        _send_room_part(system, pool, pose, pose, 2)  # the stamp did not move: a pause
        await trio.sleep(0.05)
        assert (mm.scans, mm.predicted, mm.windows) == (scans, 0, windows)  # gathered
        _send_room_part(system, pool, pose, pose, 3)
        await trio.sleep(0.05)
        assert (mm.scans, mm.predicted, mm.windows) == (scans + 4, 1, windows)
        _send_room_part(system, pool, pose, pose, 0)  # the third still batch: stopped
        await trio.sleep(0.05)
        assert (mm.scans, mm.matched, mm.windows) == (scans + 5, matched + 1, windows + 1)
        # (a quarter turn)
        await trio.sleep(0.3)  # the update goes out
        assert map_pose_sent(log, pose).x == pytest.approx(truth.x + 2.0, abs=2.0)


@pytest.mark.trio
async def test_a_window_is_processed_after_the_rover_moved_update_min_cm(
        autojump_clock) -> None:
    """Driving 1 cm a batch (windows of a revolution: 4 cm) with ``update_min_cm`` 8: the
    first window only predicts (the belief follows the odometry, the grid is left alone,
    its batches are counted), the second, 8 cm from the last processed window, is
    matched and fused."""
    async with _mapped(update_min_cm=8.0) as (system, pool, mm, truth, log):
        scans, matched, windows = mm.scans, mm.matched, mm.windows
        before = await map_sent(system, log)
        pose = await _drive(system, pool, truth, mm, batches=2)
        for k in (2, 3):
            pose = Pose(truth.x + k + 1.0, truth.y, 0.0)
            _send_room_part(system, pool, pose, pose, k)
            await trio.sleep(0.05)
        assert (mm.scans, mm.matched, mm.windows, mm.predicted) == (
            scans + 4, matched, windows, 1)
        assert np.array_equal(await map_sent(system, log), before)  # dropped from the grid
        assert origin_sent(log) is None  # (just asked) the prediction: the belief follows
        # odometry, the correction stays the identity
        for k in range(4, 8):
            pose = Pose(truth.x + k + 1.0, truth.y, 0.0)
            _send_room_part(system, pool, pose, pose, k)
            await trio.sleep(0.05)
        assert (mm.scans, mm.matched, mm.windows, mm.predicted) == (
            scans + 8, matched + 1, windows + 1, 1)
        await trio.sleep(0.3)  # the update goes out
        assert map_pose_sent(log, pose).x == pytest.approx(truth.x + 8.0, abs=2.5)


@pytest.mark.trio
async def test_after_a_refused_window_the_next_window_is_processed(
        autojump_clock, monkeypatch) -> None:
    """The motion is counted from the last window placed: once a processed window is
    refused (here every match ends worse than the guess), each following window is
    processed too, not only every ``update_min_cm``, so a run of refusals does not
    leave the belief uncorrected for many times that distance."""
    from actors.firmware.mapping import map_management
    from actors.firmware.mapping.scan_match import MatchResult

    def no_better(fields, points, guess, options=None):
        return MatchResult(guess, False, 0.9, 0.9, "the match fits worse than the guess", True)

    async with _mapped(update_min_cm=8.0) as (system, pool, mm, truth, log):
        monkeypatch.setattr(map_management, "match_scan", no_better)
        for k in range(12):  # 1 cm a batch: windows end at 4, 8 and 12 cm
            pose = Pose(truth.x + k + 1.0, truth.y, 0.0)
            _send_room_part(system, pool, pose, pose, k)
            await trio.sleep(0.05)
        assert mm.predicted == 1  # only the first: the second was refused, the third due
        assert mm.unplaced == 8


@pytest.mark.trio
async def test_a_turn_in_place_is_processed_every_update_min_deg(autojump_clock) -> None:
    """A turn in place one heading quantum (2.2 deg) a batch: each batch is a window of its
    own, and only one that turned ``update_min_deg`` (10 deg: the fifth quantum) since the
    last processed window is matched; the ones between only predict."""

    async with _mapped(update_min_deg=10.0) as (system, pool, mm, truth, log):
        windows = mm.windows
        for k in range(1, 9):
            at = Pose(truth.x, truth.y, k * BENCH.heading_quantum_deg)
            _send_room_part(system, pool, at, at, k)
            await trio.sleep(0.05)
        # windows of batches 1..7 were cut (each before the next turned): the 5th processed
        assert (mm.windows, mm.predicted) == (windows + 1, 6)


@pytest.mark.trio
async def test_a_drives_heading_flicker_is_one_window_placed_at_the_drives_heading(
        autojump_clock) -> None:
    """A straight drive whose stamps flicker a heading quantum off the drive's (one
    tread's interrupt before the other's), the last of them too, while the rover's
    heading does not move: its revolution is one window, matched once and placed at the
    drive's heading, and the belief keeps it."""
    from server.protocol.pose import Pose

    async with _mapped(update_min_cm=0.0) as (system, pool, mm, truth, log):
        scans, matched, windows = mm.scans, mm.matched, mm.windows
        q = BENCH.heading_quantum_deg
        for k, flicker in enumerate([0.0, q, 0.0, q]):
            taken = Pose(truth.x + k + 1.0, truth.y, 0.0)
            _send_room_part(system, pool, Pose(taken.x, taken.y, flicker), taken, k)
            await trio.sleep(0.05)
        assert (mm.scans, mm.matched, mm.windows) == (scans + 4, matched + 1, windows + 1)
        system.send_nowait("mapper/map", Message.uint(Cmd.MAP_GET, 0))
        await trio.sleep(0.01)
        # the window's stamp is the drive's heading, and the match leaves it there: no
        # correction of the flicker goes to navigation
        assert abs((origin_sent(log) or Pose()).heading_deg) <= 0.5


@pytest.mark.trio
async def test_a_turn_in_place_by_a_heading_quantum_cuts_the_window(autojump_clock) -> None:
    """A stamp a quantum off the window's heading with the position still is a turn (the
    treads went opposite ways), not a drive's flicker: the window is cut before it."""
    from server.protocol.pose import Pose

    async with _mapped() as (system, pool, mm, truth, log):
        scans = mm.scans + mm.unplaced
        at = Pose(truth.x + 1.0, truth.y, 0.0)
        _send_room_part(system, pool, at, at, 0)
        await trio.sleep(0.05)
        turned = Pose(at.x, at.y, BENCH.heading_quantum_deg)
        _send_room_part(system, pool, turned, turned, 1)
        await trio.sleep(0.05)
        assert mm.scans + mm.unplaced == scans + 1  # the first was placed (or dropped) alone


@pytest.mark.trio
async def test_a_window_is_cut_at_a_tread_fault_report(autojump_clock) -> None:
    """A tread fault report closes the window first: the batches taken before it are
    matched and fused where the counts put them, and only then does the report widen
    the belief."""
    async with _mapped() as (system, pool, mm, truth, log):
        scans, matched = mm.scans, mm.matched
        await _drive(system, pool, truth, mm)
        assert not mm.wide(mm.matching)
        system.send_nowait("mapper/map", Message.pair(Cmd.MAP_TREAD_FAULT, -50, 50))
        await trio.sleep(0.01)
        assert (mm.scans, mm.matched) == (scans + 2, matched + 1)
        assert mm.wide(mm.matching)  # then the report widened the belief past the local match


@pytest.mark.trio
async def test_a_standing_rover_fuses_its_batches_in_windows_without_matching(
        autojump_clock) -> None:
    """While odometry stands still, the batches are matched (in windows of a revolution)
    only until ``settle_s`` has passed; after that whole windows are fused at the belief's
    mean, unmatched, and every batch is counted."""
    from server.protocol.pose import Pose

    async with _mapped(settle_s=1.0) as (system, pool, mm, truth, log):
        stamp = Pose(truth.x + 1.0, truth.y, 0.0)
        for k in range(40):  # 2 s, 20 batches a second, a quarter revolution each
            _send_room_part(system, pool, stamp, stamp, k)
            await trio.sleep(0.05)
        matched, windows, scans = mm.matched, mm.windows, mm.scans
        assert 1 <= matched <= 6  # the first second: a window per revolution, matched
        for k in range(40):
            _send_room_part(system, pool, stamp, stamp, k)
            await trio.sleep(0.05)
        assert mm.matched == matched  # standing: not matched again
        assert mm.windows == windows + 10  # ...but fused, a revolution at a time
        assert mm.scans == scans + 40
        assert mm.scans + mm.unplaced == 3 + 80  # (a refused window counts its batches)


@pytest.mark.trio
async def test_a_standing_rover_whose_match_ends_worse_than_the_guess_still_stands(
        autojump_clock, monkeypatch) -> None:
    """When every local match ends a hair worse than the guess (refused), a rover that has
    stood ``settle_s`` with its scan fitting well at the belief's mean is still taken as
    standing: its windows are fused unmatched from then on, instead of all being dropped
    (which navigation would read as a silent LIDAR)."""
    from actors.firmware.mapping import map_management
    from actors.firmware.mapping.scan_match import MatchResult
    from server.protocol.pose import Pose

    def no_better(fields, points, guess, options=None):
        return MatchResult(guess, False, 0.9, 0.9, "the match fits worse than the guess", True)

    async with _mapped(settle_s=1.0) as (system, pool, mm, truth, log):
        monkeypatch.setattr(map_management, "match_scan", no_better)
        stamp = Pose(truth.x + 1.0, truth.y, 0.0)  # moved once, then stands
        for k in range(30):  # 1.5 s
            _send_room_part(system, pool, stamp, stamp, k)
            await trio.sleep(0.05)
        assert mm.refusals["the match fits worse than the guess"] > 0
        scans = mm.scans
        for k in range(20):
            _send_room_part(system, pool, stamp, stamp, k)
            await trio.sleep(0.05)
        assert mm.scans == scans + 20  # every batch fused while it stands


@pytest.mark.trio
async def test_frozen_stamps_of_a_rover_that_drives_on_a_little_are_not_read_as_standing(
        autojump_clock) -> None:
    """The rover stood and its windows were placed unmatched. Both encoders then stop
    counting and it drives on 8 cm unseen: its scans still fit "not badly" at the
    belief's mean (a few hits off by 8 cm), but their local match lies outside the
    belief's gate, so they are not placed at the stale mean; they weigh for "odometry
    broke unseen" until the belief widens and the wide search re-finds the rover, the
    truth inside the belief's gate (the update weighs the search's fit against the
    prediction: the mean lands 2-3 cm short of it)."""
    from server.protocol.pose import Pose

    async with _mapped(settle_s=1.0) as (system, pool, mm, truth, log):
        stamp = Pose(truth.x + 1.0, truth.y, 0.0)
        for k in range(40):  # stands: matched for settle_s, then placed unmatched
            _send_room_part(system, pool, stamp, stamp, k)
            await trio.sleep(0.05)
        windows, before = mm.windows, await map_sent(system, log)
        moved = Pose(stamp.x + 8.0, stamp.y, 0.0)
        for k in range(4):  # the first revolution there: a window placed nowhere yet
            _send_room_part(system, pool, stamp, moved, k)
            await trio.sleep(0.05)
        assert mm.windows == windows and mm.unplaced > 0  # not placed at the stale mean
        for k in range(4, 160):
            _send_room_part(system, pool, stamp, moved, k)
            await trio.sleep(0.05)
        await trio.sleep(0.3)  # the last update goes out
        assert abs(map_pose_sent(log, stamp).x - moved.x) <= 4.0  # not 8 cm behind the truth
        outside, scans = mm.refusals["outside the belief"], mm.scans
        for k in range(8):  # the truth lies inside the belief's gate: placed, not refused
            _send_room_part(system, pool, stamp, moved, k)
            await trio.sleep(0.05)
        assert mm.refusals["outside the belief"] == outside and mm.scans == scans + 8
        assert _stray_walls(before, await map_sent(system, log)) <= 3
