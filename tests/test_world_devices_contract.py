"""The world's devices and the firmware agree on the device contract.

The contract (``actors/firmware/hardware.py``) is written once; these tests
round-trip what the world's devices produce through the firmware's ISRs.
"""

from __future__ import annotations

import struct

import numpy as np

from actors import Message
from actors.firmware import hardware as fw
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import LidarUartIsr, MotorCounterIsr
from world import packets
from world.drive import Tread
from world.params import DeviceParams, rover_spec
from world.scenario import load_scenario
from world.world import World


def test_counter_payloads_round_trip() -> None:
    """Every Int E payload the contract encodes decodes to the same tread and direction."""
    for tread in (fw.TREAD_LEFT, fw.TREAD_RIGHT):
        for forward in (True, False):
            assert fw.decode_counter(fw.encode_counter(tread, forward)) == (tread, forward)


def test_a_tread_driven_backwards_posts_backward_counts_to_the_motor() -> None:
    """The world's tread raises Int E with payloads the firmware's ISR turns into motor messages."""
    got: list[Message] = []
    isr = MotorCounterIsr(lambda m: got.append(m) is None)
    tread = Tread(fw.TREAD_RIGHT)
    for payload in tread.encode(-12.0, ticks_per_cm=8.0, per_interrupt=4):
        isr(payload)
    assert len(got) == 24 and all(m.command == Cmd.MOTOR_TICK for m in got)
    assert {fw.decode_counter(m.value) for m in got} == {(fw.TREAD_RIGHT, False)}


def test_lidar_packets_follow_the_datasheet() -> None:
    """Sync, little-endian angle and distance, XOR checksum, as the contract documents."""
    data = packets.encode_lidar_packets(np.array([0, 12345, 35999, 36100]),
                                        np.array([0, 402, 65535, 70000]))
    frames = [data[i:i + fw.LIDAR_PACKET_SIZE] for i in range(0, len(data), fw.LIDAR_PACKET_SIZE)]
    decoded = []
    for f in frames:
        sync, angle, dist, check = struct.unpack("<BHHB", f)
        assert sync == fw.LIDAR_SYNC
        assert check == f[1] ^ f[2] ^ f[3] ^ f[4]
        decoded.append((angle, dist))
    assert decoded == [(0, 0), (12345, 402), (35999, 65535), (100, 65535)]


def test_lidar_packets_parse_in_the_firmware_isr() -> None:
    """The firmware's Int A ISR turns the world's bytes back into the same samples, sample
    for sample and in order ([0.1 deg] angle, [cm] distance), however the UART splits
    the bytes: whole, one byte at a time, or in random pieces."""
    rng = np.random.default_rng(3)
    angles = np.concatenate([[0, 9000, 27050, 35999], rng.integers(0, 36000, 500)])
    distances = np.concatenate([[100, 402, 0, 32767], rng.integers(0, 32768, 500)])
    data = packets.encode_lidar_packets(angles, distances)
    want = [(int(a) // 10, int(d)) for a, d in zip(angles, distances, strict=True)]
    cuts = np.sort(rng.choice(np.arange(1, len(data)), 300, replace=False))
    for pieces in ([data], [data[i:i + 1] for i in range(len(data))],
                   np.split(np.frombuffer(data, np.uint8), cuts)):
        got: list[Message] = []
        isr = LidarUartIsr(lambda m, got=got: got.append(m) is None)
        for piece in pieces:
            isr(bytes(piece))
        assert all(m.command == Cmd.LIDAR_SAMPLE for m in got)
        assert [m.as_pair() for m in got] == want
        assert isr.bad_frames == 0


def test_the_world_builds_the_firmware_spec() -> None:
    """The world hands each rover the contract's own `HardwareSpec`, from its device parameters."""
    spec = rover_spec("seeker", DeviceParams(ticks_per_cm=10.0, ticks_per_interrupt=5))
    assert isinstance(spec, fw.HardwareSpec)
    assert (spec.role, spec.cm_per_interrupt) == ("seeker", 0.5)


def test_sim_hardware_is_a_rover_hardware() -> None:
    world = World(load_scenario("empty"), np.random.default_rng(0))
    for role in fw.ROLES:
        h = world.hardware(role)
        assert isinstance(h, fw.RoverHardware)
        assert h.spec.role == role and h.spec.cm_per_interrupt == 0.5
        h.attach(fw.Interrupt.INT_E, lambda p: None)
        assert fw.Interrupt.INT_E in h.handlers
