"""LIDAR Control in isolation: fake samples and poses in, scans out."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from actors import Actor, BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import (
    RECOVER_BATCHES,
    STUCK_SPAN_DEG,
    HealthOptions,
    LidarControl,
    LidarHealth,
    Scan,
    batch_health,
    roughness_cm,
)
from actors.firmware.hardware import Interrupt
from supervisors import ChildSpec, SupervisorSpec

from .test_fw_motor import FakeHardware


class Recorder(Actor):
    def __init__(self, log: list, pool: BufferPool) -> None:
        self.log, self.pool = log, pool

    async def handle(self, m):
        payload = self.pool.take(int(m.value)) if m.type == 4 else m.value
        self.log.append((m.command, payload))


@pytest.mark.trio
async def test_samples_are_stamped_with_the_pose_that_follows_them(autojump_clock) -> None:
    """Samples then a pose in one burst become one scan at that pose; duty goes to hardware."""
    hw, pool, log = FakeHardware(), BufferPool(16), []
    hw.duty = None
    hw.set_lidar_pwm = lambda d: setattr(hw, "duty", d)
    spec = SupervisorSpec([ChildSpec("map", lambda: Recorder(log, pool)),
                           ChildSpec("lidar", lambda: LidarControl(hw, pool), mailbox=1024)])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        await system.send("mapper/lidar", Message.float(Cmd.LIDAR_START, 0.5))
        await trio.sleep(0.01)
        assert hw.duty == 0.5
        for a in range(10):
            system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_SAMPLE, a * 10, 100 + a))
        system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_POSE_XY, 30, -4))
        system.send_nowait("mapper/lidar", Message.float(Cmd.LIDAR_POSE_HEADING, 45.0))
        await trio.sleep(0.01)
        (cmd, scan), = log
        assert cmd == Cmd.MAP_SCAN and isinstance(scan, Scan)
        assert (scan.pose.x, scan.pose.y, scan.pose.heading_deg) == (30.0, -4.0, 45.0)
        assert scan.angles_deg == pytest.approx(np.arange(10, dtype=np.float32))
        assert list(scan.ranges_cm) == [100 + a for a in range(10)]
        with pytest.raises(Exception):  # noqa: B017 - a bad duty is a crash of the message
            await system.call("mapper/lidar", Message.float(Cmd.LIDAR_RATE, 2.0), timeout=1)
        await system.send("mapper/lidar", Message.uint(Cmd.LIDAR_STOP, 0))
        await trio.sleep(0.01)
        assert hw.duty == 0.0
        assert pool.statistics().in_use == 0


@pytest.mark.trio
async def test_sample_batches_by_handle_become_one_scan_at_the_next_pose(autojump_clock) -> None:
    """LIDAR_SAMPLES handles (from the ISR's pool mode) join singles into one scan."""
    from actors.firmware.drivers.isr import LidarSamples

    hw, pool, log = FakeHardware(), BufferPool(16), []
    hw.set_lidar_pwm = lambda d: None
    spec = SupervisorSpec([ChildSpec("map", lambda: Recorder(log, pool)),
                           ChildSpec("lidar", lambda: LidarControl(hw, pool), mailbox=1024)])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "mapper")
        batch = LidarSamples(np.array([0, 100, 200], dtype=np.int32),
                             np.array([50, 60, 0], dtype=np.int32))
        system.send_nowait("mapper/lidar", Message.handle(Cmd.LIDAR_SAMPLES, pool.put(batch)))
        system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_SAMPLE, 300, 70))
        system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_POSE_XY, 5, 6))
        system.send_nowait("mapper/lidar", Message.float(Cmd.LIDAR_POSE_HEADING, 10.0))
        await trio.sleep(0.01)
        (cmd, scan), = log
        assert cmd == Cmd.MAP_SCAN
        assert (scan.pose.x, scan.pose.y, scan.pose.heading_deg) == (5.0, 6.0, 10.0)
        assert scan.angles_deg == pytest.approx([0.0, 10.0, 20.0, 30.0])
        assert list(scan.ranges_cm) == [50, 60, 0, 70]
        assert pool.statistics().in_use == 0


@pytest.mark.trio
async def test_a_noop_flood_is_ignored_not_a_crash(autojump_clock) -> None:
    """NOOP (a flood fault) costs queue slots only: no restart, samples still batch."""
    hw, pool, log = FakeHardware(), BufferPool(16), []
    hw.set_lidar_pwm = lambda d: None
    spec = SupervisorSpec([ChildSpec("map", lambda: Recorder(log, pool)),
                           ChildSpec("lidar", lambda: LidarControl(hw, pool), mailbox=64)])
    async with open_actor_system(1) as system:
        tree = await system.start_supervisor(spec, "mapper")
        accepted = system.flood("mapper/lidar", 200, Message.int(Cmd.NOOP, 0))
        assert accepted == 64
        await trio.sleep(0.1)
        system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_SAMPLE, 10, 100))
        system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_POSE_XY, 0, 0))
        system.send_nowait("mapper/lidar", Message.float(Cmd.LIDAR_POSE_HEADING, 0.0))
        await trio.sleep(0.01)
        assert [c for c, _ in log] == [Cmd.MAP_SCAN]
        assert [c.restarts for c in tree.which_children() if c.id == "lidar"] == [0]


# ---------------------------------------------------------------------- LIDAR health

def _frames(angles_cdeg, ranges_cm) -> bytes:
    """Data Packet A frames (devices.py) for the ISR."""
    out = bytearray()
    for a, d in zip(angles_cdeg, ranges_cm, strict=True):
        a0, a1, d0, d1 = a & 0xFF, a >> 8, d & 0xFF, d >> 8
        out += bytes([0xA5, a0, a1, d0, d1, a0 ^ a1 ^ d0 ^ d1])
    return bytes(out)


def _wall(start_deg: int, n: int = 100) -> tuple[list[int], list[int]]:
    """A sweep of ``n`` samples 1 deg apart at a flat wall 150 cm ahead of angle 0."""
    deg = [(start_deg + i) % 360 for i in range(n)]
    ranges = [round(min(150.0 / max(math.cos(math.radians(d)), 0.3), 500.0) / 2) * 2
              for d in deg]
    return [d * 100 for d in deg], ranges


def test_roughness_of_a_flat_wall_is_the_quantum_and_noise_is_far_above() -> None:
    """A flat wall's second difference stays at the 2 cm quantum; 5 cm noise lifts the
    median above the 5 cm limit."""
    a, r = _wall(300)
    angles = np.array(a) / 100.0
    smooth, n = roughness_cm(angles, np.array(r, dtype=float))
    assert n == 98 and smooth <= 2.0
    rng = np.random.default_rng(7)
    noisy, _ = roughness_cm(angles, np.array(r) + rng.normal(0.0, 5.0, len(r)))
    assert noisy > HealthOptions().noise_limit_cm
    assert roughness_cm(angles[:2], np.array(r[:2], dtype=float)) == (0.0, 0)


@pytest.mark.parametrize(("angles", "ranges", "bad", "verdict"), [
    (np.arange(100.0), np.full(100, 200.0), 0, LidarHealth.OK),
    (np.full(100, 42.0), np.full(100, 200.0), 0, LidarHealth.STUCK),
    (np.arange(100.0), 200.0 + 30.0 * (np.arange(100) % 2), 0, LidarHealth.NOISY),
    (np.arange(100.0), np.full(100, 200.0), 40, LidarHealth.GARBLED),
    (np.array([5.0]), np.array([900.0]), 3, LidarHealth.GARBLED),
    (np.full(5, 42.0), np.full(5, 200.0), 0, LidarHealth.OK),  # too few to judge
    (np.arange(350.0, 450.0) % 360, np.full(100, 200.0), 0, LidarHealth.OK),  # wraps
], ids=["wall", "stuck", "noisy", "garbled", "stray-frame", "few", "wrap"])
def test_batch_health_verdicts(angles, ranges, bad, verdict) -> None:
    """Each fault has its signature; a healthy sweep across 0 deg is not stuck or rough."""
    assert batch_health(angles, ranges, bad) == verdict


def test_a_rotor_is_stuck_exactly_when_every_angle_lies_within_a_degree_of_the_first() -> None:
    """Clusters of angles anywhere on the circle, across 0 deg too, narrow and a little
    wider than a degree, and sweeps: the verdict is STUCK exactly when the circular
    spread of every sample from the first is at most `STUCK_SPAN_DEG` (the shortcut on
    the angles' extent never decides otherwise)."""
    rng = np.random.default_rng(11)
    for trial in range(600):
        centre = rng.choice([0.0, 0.4, 359.6, 180.0, rng.uniform(0.0, 360.0)])
        width = rng.choice([0.0, 0.5, 0.99, 1.0, 1.01, 2.0, 2.6, 40.0, 359.0])
        angles = ((centre + rng.uniform(-width, width, 20)) % 360.0).astype(np.float32)
        a = angles.astype(np.float64)
        spread = np.abs((a - a[0] + 180.0) % 360.0 - 180.0).max()
        expected = LidarHealth.STUCK if spread <= STUCK_SPAN_DEG else LidarHealth.OK
        assert batch_health(angles, np.full(20, 200.0, dtype=np.float32), 0) == expected, (
            f"trial {trial}: {angles.tolist()}")


def _health_tree(log: list, pool: BufferPool, hw: FakeHardware) -> SupervisorSpec:
    return SupervisorSpec([ChildSpec("map", lambda: Recorder(log, pool)),
                           ChildSpec("nav", lambda: Recorder(log, pool)),
                           ChildSpec("lidar", lambda: LidarControl(hw, pool), mailbox=1024)])


async def _interrupt(system, hw: FakeHardware, data: bytes, heading: float = 0.0) -> None:
    """One Int A with ``data``, then the pose of that tick."""
    hw.handlers[int(Interrupt.INT_A)](data)
    system.send_nowait("mapper/lidar", Message.pair(Cmd.LIDAR_POSE_XY, 0, 0))
    system.send_nowait("mapper/lidar", Message.float(Cmd.LIDAR_POSE_HEADING, heading))
    await trio.sleep(0.05)


@pytest.mark.trio
async def test_stuck_rotor_batches_are_withheld_until_it_turns_again(autojump_clock) -> None:
    """Samples all at one angle: no scan from the first such batch on, navigation told
    STUCK once; after ``RECOVER_BATCHES`` good sweeps it is told OK and scans flow."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    async with open_actor_system(1) as system:
        await system.start_supervisor(_health_tree(log, pool, hw), "mapper")
        await system.send("mapper/lidar", Message.float(Cmd.LIDAR_START, 0.5))
        await _interrupt(system, hw, _frames(*_wall(0)))
        assert [c for c, _ in log] == [Cmd.MAP_SCAN]
        for _ in range(5):
            await _interrupt(system, hw, _frames([4200] * 100, [150] * 100))
        assert [(c, v) for c, v in log[1:]] == [(Cmd.NAV_LIDAR_HEALTH, LidarHealth.STUCK)]
        recover = RECOVER_BATCHES
        for i in range(recover - 1):
            await _interrupt(system, hw, _frames(*_wall(i * 100)))
        assert len(log) == 2  # good sweeps, but not yet enough of them
        await _interrupt(system, hw, _frames(*_wall(0)))  # the last one needed is sent
        assert sorted(c for c, _ in log[2:]) == [Cmd.NAV_LIDAR_HEALTH, Cmd.MAP_SCAN]
        assert (Cmd.NAV_LIDAR_HEALTH, LidarHealth.OK) in log[2:]
        assert pool.statistics().in_use == 0


@pytest.mark.trio
async def test_garbage_on_the_line_never_reaches_the_map(autojump_clock) -> None:
    """Random bytes (and the odd frame they happen to form): nothing is integrated, and
    navigation hears GARBLED once a stray frame comes through."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    rng = np.random.default_rng(3)
    async with open_actor_system(1) as system:
        await system.start_supervisor(_health_tree(log, pool, hw), "mapper")
        await system.send("mapper/lidar", Message.float(Cmd.LIDAR_START, 0.5))
        for _ in range(20):
            junk = bytearray(rng.integers(0, 256, 600, dtype=np.uint8).tobytes())
            junk += _frames([1000], [300])  # a frame that decodes among the garbage
            await _interrupt(system, hw, bytes(junk))
        assert Cmd.MAP_SCAN not in [c for c, _ in log]
        assert log[0] == (Cmd.NAV_LIDAR_HEALTH, LidarHealth.GARBLED)


@pytest.mark.trio
async def test_noisy_ranges_are_withheld(autojump_clock) -> None:
    """Range noise far above the calibrated 0.5 cm: no scan, navigation told NOISY."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    rng = np.random.default_rng(5)
    async with open_actor_system(1) as system:
        await system.start_supervisor(_health_tree(log, pool, hw), "mapper")
        await system.send("mapper/lidar", Message.float(Cmd.LIDAR_START, 0.5))
        for i in range(4):
            a, r = _wall(i * 90)
            r = [max(1, int(v + rng.normal(0.0, 10.0))) for v in r]
            await _interrupt(system, hw, _frames(a, r))
        assert log == [(Cmd.NAV_LIDAR_HEALTH, LidarHealth.NOISY)]


def test_roughness_is_the_median_of_the_second_differences() -> None:
    """Odd and even counts of triples (even: the mean of the middle two), as np.median."""
    rng = np.random.default_rng(7)
    for n in (3, 4, 5, 6, 40, 99, 100):
        angles = np.arange(n, dtype=float)
        ranges = np.round(rng.uniform(100.0, 300.0, n))
        rough, triples = roughness_cm(angles, ranges)
        d2 = np.abs(ranges[:-2] - 2.0 * ranges[1:-1] + ranges[2:])
        assert triples == n - 2
        assert rough == float(np.median(d2))
