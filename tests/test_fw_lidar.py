"""LIDAR Control in isolation: fake samples and poses in, scans out."""

from __future__ import annotations

import numpy as np
import pytest
import trio

from actors import Actor, BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.lidar import LidarControl, Scan
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
    from actors.firmware.isr import LidarSamples

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
