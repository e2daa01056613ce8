"""The world's device encoders agree with the firmware's datasheet definitions."""

from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from actors.firmware import hardware as fw
from world import hardware as hw
from world import packets
from world.params import RoverSpec
from world.scenario import load_scenario
from world.world import World


def test_counter_payloads_decode_on_the_firmware_side() -> None:
    for tread in (packets.TREAD_LEFT, packets.TREAD_RIGHT):
        for forward in (True, False):
            assert fw.decode_counter(packets.encode_counter(tread, forward)) == (tread, forward)
            assert packets.encode_counter(tread, forward) == fw.encode_counter(tread, forward)


def test_lidar_packets_follow_the_datasheet() -> None:
    """Sync, little-endian angle and distance, XOR checksum, as firmware documents."""
    assert packets.LIDAR_SYNC == fw.LIDAR_SYNC
    assert packets.LIDAR_PACKET_SIZE == fw.LIDAR_PACKET_SIZE
    data = packets.encode_lidar_packets(np.array([0, 12345, 35999, 36100]),
                                        np.array([0, 402, 65535, 70000]))
    frames = [data[i:i + 6] for i in range(0, len(data), 6)]
    decoded = []
    for f in frames:
        sync, angle, dist, check = struct.unpack("<BHHB", f)
        assert sync == fw.LIDAR_SYNC
        assert check == f[1] ^ f[2] ^ f[3] ^ f[4]
        decoded.append((angle, dist))
    assert decoded == [(0, 0), (12345, 402), (35999, 65535), (100, 65535)]


def test_lidar_packets_parse_in_the_firmware_isr() -> None:
    """The firmware's Int A ISR turns our bytes into the same (angle, distance) samples."""
    isr_mod = pytest.importorskip("actors.firmware.drivers.isr")
    got = []
    isr = isr_mod.LidarUartIsr(got.append)
    isr(packets.encode_lidar_packets(np.array([0, 9000, 27050]), np.array([100, 402, 0])))
    assert len(got) == 3


def test_spec_has_the_firmware_spec_fields() -> None:
    ours = [f.name for f in dataclasses.fields(RoverSpec)]
    theirs = [f.name for f in dataclasses.fields(fw.HardwareSpec)]
    assert ours == theirs
    fw.HardwareSpec(**dataclasses.asdict(RoverSpec("mapper", 0.5, 13.0)))


def test_interrupt_lines_match() -> None:
    assert (hw.INT_A, hw.INT_B, hw.INT_C, hw.INT_D, hw.INT_E) == tuple(fw.Interrupt)


def test_sim_hardware_is_a_rover_hardware() -> None:
    world = World(load_scenario("empty"), np.random.default_rng(0))
    for role in ("mapper", "hider", "seeker"):
        h = world.hardware(role)
        assert isinstance(h, fw.RoverHardware)
        assert h.spec.role == role and h.spec.cm_per_interrupt == 0.5
        h.attach(fw.Interrupt.INT_E, lambda p: None)  # the firmware's enum works as a line
        assert fw.Interrupt.INT_E in h.handlers
