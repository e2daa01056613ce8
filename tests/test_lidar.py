"""LIDAR: packets match ray casts within the quantisation; rate, range and UART limits."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from world.geometry import boundary_segments, circle, footprint, room_segments
from world.raycast import cast_rays, cull_to_wedge
from world.scenario import load_scenario, parse_scenario
from world.world import World

ROOM = """
name = "lidar"
[room]
size_cm = [400, 300]
[[obstacles]]
box = [250, 100, 50, 100]
[rovers]
mapper = [100, 150, 0]
hider = [100, 60, 0]
seeker = [350, 40, 0]
[devices]
lidar_noise_cm = 0.0
"""


def decode(data: bytes) -> list[tuple[float, int]]:
    """(angle [deg], distance [cm]) per Data Packet A frame."""
    out = []
    for i in range(0, len(data), 6):
        sync, angle, dist, check = struct.unpack("<BHHB", data[i:i + 6])
        assert sync == 0xA5 and check == data[i + 1] ^ data[i + 2] ^ data[i + 3] ^ data[i + 4]
        out.append((angle / 100.0, dist))
    return out


def spin(world: World, seconds: float, pwm: float = 0.5) -> list[tuple[float, int]]:
    got: list[bytes] = []
    world.hardware("mapper").attach(0xA, got.append)
    world.hardware("mapper").set_lidar_pwm(pwm)
    end = world.time + seconds
    while world.time < end - 1e-9:
        world.step()
    return decode(b"".join(got))


def test_cast_rays_against_a_known_box() -> None:
    segs = boundary_segments([shapely.box(100, -50, 120, 50)])
    d = cast_rays((0.0, 0.0), np.radians([0.0, 90.0, 180.0, 20.0]), segs, 4000.0)
    assert d[0] == pytest.approx(100.0)
    assert math.isinf(d[1]) and math.isinf(d[2])
    assert d[3] == pytest.approx(100 / math.cos(math.radians(20)))
    assert math.isinf(cast_rays((0.0, 0.0), np.array([0.0]), segs, 50.0)[0])  # beyond range


@settings(max_examples=60, deadline=None)
@given(x=st.floats(20, 380), y=st.floats(20, 280), start=st.floats(0, 2 * math.pi),
       span=st.floats(0, 2.8))
def test_wedge_culling_never_changes_a_range(x: float, y: float, start: float,
                                              span: float) -> None:
    """Culling to the rays' wedge gives exactly the ranges of casting against everything."""
    segs = np.vstack([room_segments(400, 300), boundary_segments(
        [circle(200, 150, 40), shapely.box(50, 50, 90, 70)])])
    angles = start + np.linspace(0, span, 40)
    full = cast_rays((x, y), angles, segs, 4000.0)
    culled = cast_rays((x, y), angles, cull_to_wedge((x, y), start, span, segs), 4000.0)
    np.testing.assert_array_equal(full, culled)


def test_packets_match_geometry_within_quantisation() -> None:
    """Every range equals the true distance to the nearest surface within 1 cm (2 cm steps)."""
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    samples = spin(world, 0.5)
    assert len(samples) > 300
    by_angle = dict(samples)
    assert by_angle[0.0] == pytest.approx(150, abs=1)  # box face at x = 250
    assert by_angle[90.0] == pytest.approx(150, abs=1)  # top wall
    assert by_angle[180.0] == pytest.approx(100, abs=1)  # left wall
    assert by_angle[270.0] == pytest.approx(90 - 7.5, abs=1)  # the hider's near side
    segs = np.vstack([room_segments(400, 300), boundary_segments(
        [shapely.box(250, 100, 300, 200), footprint(world.true_pose("hider"), 20, 15),
         footprint(world.true_pose("seeker"), 20, 15)])])
    for angle, dist in samples:
        true = cast_rays((100.0, 150.0), np.radians([angle]), segs, 4000.0)[0]
        assert dist % 2 == 0
        assert abs(dist - true) <= 1.0 + 1e-9, (angle, dist, true)


def test_rate_is_proportional_to_pwm_and_zero_stops() -> None:
    """5.5 rev/s at PWM 0.5 (360 samples each), 11 at full, nothing at 0."""
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    assert len(spin(world, 2.0, 0.5)) == pytest.approx(2 * 5.5 * 360, abs=2)
    assert len(spin(world, 1.0, 1.0)) == pytest.approx(11 * 360, abs=2)
    assert spin(world, 1.0, 0.0) == []


def test_angles_advance_one_degree_per_sample() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    angles = [a for a, _ in spin(world, 0.3)]
    steps = np.diff(angles) % 360
    assert set(np.round(steps, 2)) == {1.0}


def test_out_of_range_reads_zero() -> None:
    text = ROOM.replace("[devices]", "[devices]\nlidar_range_cm = 120")
    world = World(parse_scenario(text), np.random.default_rng(0))
    by_angle = dict(spin(world, 0.5))
    assert by_angle[0.0] == 0 and by_angle[90.0] == 0  # 150 cm away
    assert by_angle[180.0] == 100


def test_noise_is_gaussian_with_the_configured_sigma() -> None:
    text = ROOM.replace("lidar_noise_cm = 0.0", "lidar_noise_cm = 3.0")
    world = World(parse_scenario(text), np.random.default_rng(0))
    dists = np.array([d for a, d in spin(world, 4.0) if a == 180.0], dtype=float)
    assert len(dists) >= 20
    assert 1.5 < dists.std() < 5.0
    assert dists.mean() == pytest.approx(100, abs=2)


def test_slow_uart_drops_whole_packets_and_counts_them() -> None:
    """At 19200 baud only 1920 bytes/s get through; the rest is dropped and counted."""
    text = ROOM.replace("[devices]", "[devices]\nlidar_baud = 19200")
    world = World(parse_scenario(text), np.random.default_rng(0))
    samples = spin(world, 2.0, 0.5)
    assert len(samples) == pytest.approx(2 * 1920 / 6, abs=2)
    assert world.lidar.dropped_bytes == pytest.approx((2 * 1980 - len(samples)) * 6, abs=12)


def test_lidar_sees_the_other_rovers() -> None:
    world = World(load_scenario("empty"), np.random.default_rng(0))
    by_angle = dict(spin(world, 0.5))
    # hider at (50, 110), mapper at (50, 50): its near side is 60 - 7.5 cm away
    assert by_angle[90.0] == pytest.approx(52.5, abs=2)
