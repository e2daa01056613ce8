"""LIDAR: packets match ray casts within the quantisation; rate, range and UART limits."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from world.geometry import Pose, boundary_segments, circle, footprint, room_segments
from world.packets import LidarFramer, encode_lidar_packets
from world.raycast import FanCaster, cast_rays, fan_may_hit_disc
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


SEGMENTS = np.vstack([room_segments(400, 300), boundary_segments(
    [circle(200, 150, 40), shapely.box(50, 50, 90, 70)])])


@settings(max_examples=80, deadline=None)
@given(x=st.floats(20, 380), y=st.floats(20, 280), start=st.floats(-7, 7),
       n=st.integers(1, 800), step_deg=st.sampled_from([0.5, 1.0, 7.0, 45.0]),
       box=st.tuples(st.floats(30, 370), st.floats(30, 270), st.floats(-4, 4)))
def test_fan_caster_gives_the_ranges_of_casting_every_ray(
        x: float, y: float, start: float, n: int, step_deg: float,
        box: tuple[float, float, float]) -> None:
    """Fans of any width (also past a full turn) equal the all-pairs caster, boxes included."""
    caster = FanCaster(SEGMENTS, boxes=1)
    caster.set_boxes([box], 20, 15)
    step = math.radians(step_deg)
    body = footprint(Pose(box[0], box[1], math.degrees(box[2])), 20, 15)
    if body.contains(shapely.Point(x, y)):
        return  # a LIDAR inside another rover's body is not a situation
    segs = np.vstack([SEGMENTS, boundary_segments([body])])
    angles = start + np.arange(n) * step
    want = cast_rays((x, y), angles, segs, 4000.0)
    got = caster.cast_fan((x, y), start, step, n, 4000.0)
    same = np.isclose(got, want, rtol=1e-9) | (np.isinf(got) & np.isinf(want))
    # where they differ the ray must graze a segment's end (a corner) to rounding error:
    # there hit or miss is a matter of the last bit of the direction
    ends = np.vstack([segs[:, :2], segs[:, 2:]]) - (x, y)
    for a in angles[~same]:
        off = np.abs(np.cos(a) * ends[:, 1] - np.sin(a) * ends[:, 0])  # distance to the ray's line
        assert off.min() < 1e-6, (a, got[angles == a], want[angles == a])


def test_a_box_edge_nearly_in_line_with_the_origin_hides_nothing() -> None:
    """Regression: an edge 1e-15 cm off the origin's line got a full-turn extent and a
    rounding-sized range that masked the wall behind every ray."""
    caster = FanCaster(SEGMENTS, boxes=1)
    caster.set_boxes([(30.0, 30.0, 2.220446049250313e-16)], 20, 15)  # left edge on x = 20
    d = caster.cast_fan((20.0, 20.0), 0.0, math.radians(0.5), 1, 4000.0)
    assert d[0] == pytest.approx(380.0)  # the right wall


@settings(max_examples=200, deadline=None)
@given(x=st.floats(20, 380), y=st.floats(20, 280), start=st.floats(-7, 7),
       n=st.integers(1, 120), box=st.tuples(st.floats(30, 370), st.floats(30, 270),
                                             st.floats(-4, 4)))
def test_a_body_the_fan_check_rules_out_is_never_hit(
        x: float, y: float, start: float, n: int, box: tuple[float, float, float]) -> None:
    """fan_may_hit_disc is safe: when it says no, casting with the body present or parked
    gives the same ranges; it says yes to a body ahead and no to one behind."""
    step = math.radians(1.0)
    radius = math.hypot(20, 15) / 2
    present = FanCaster(SEGMENTS, boxes=1)
    present.set_box(0, box, 20, 15)
    parked = FanCaster(SEGMENTS, boxes=1)
    with_body = present.cast_fan((x, y), start, step, n, 4000.0)
    without = parked.cast_fan((x, y), start, step, n, 4000.0)
    if not fan_may_hit_disc((x, y), start, (n - 1) * step, box[:2], radius):
        np.testing.assert_array_equal(with_body, without)
    assert fan_may_hit_disc((0.0, 0.0), 0.0, 0.1, (100.0, 5.0), radius)
    assert not fan_may_hit_disc((0.0, 0.0), 0.0, 0.1, (-100.0, 5.0), radius)


def test_a_ray_along_a_box_edge_hits_its_corner_without_warnings() -> None:
    """The edge the ray runs along is 0/0 (no hit, no RuntimeWarning); the corner is hit."""
    caster = FanCaster(SEGMENTS, boxes=1)
    caster.set_box(0, (30.0, 30.0, 0.0), 20, 15)  # bottom edge on y = 22.5 from x = 20
    assert caster.cast_fan((10.0, 22.5), 0.0, math.radians(1.0), 1, 4000.0)[0] == 10.0


def test_fan_caster_at_corners_edge_on_and_out_of_range() -> None:
    """A ray through a corner hits it; a wall seen edge-on is not hit; far walls read inf."""
    caster = FanCaster(room_segments(400, 300))
    d = caster.cast_fan((100.0, 100.0), math.radians(45.0), math.radians(90.0), 4, 4000.0)
    assert d[0] == pytest.approx(200 * math.sqrt(2))  # the corner (300, 300)
    assert d[2] == pytest.approx(100 * math.sqrt(2))  # the corner (0, 0)
    on_wall = caster.cast_fan((0.0, 100.0), math.radians(90.0), math.radians(1.0), 1, 4000.0)
    assert on_wall[0] == pytest.approx(200.0)  # along the left wall to the top wall
    assert np.isinf(caster.cast_fan((100.0, 100.0), 0.0, 1.0, 1, 250.0)[0])  # 300 cm > 250


def test_fan_caster_refuses_a_bad_step_and_box_count() -> None:
    caster = FanCaster(room_segments(400, 300), boxes=2)
    with pytest.raises(ValueError, match=r"step_rad must be within \(0, pi\], got 0.0"):
        caster.cast_fan((1.0, 1.0), 0.0, 0.0, 3, 100.0)
    with pytest.raises(ValueError, match="n must be >= 0, got -1"):
        caster.cast_fan((1.0, 1.0), 0.0, 0.1, -1, 100.0)
    assert caster.cast_fan((1.0, 1.0), 0.0, 0.1, 0, 100.0).shape == (0,)
    with pytest.raises(ValueError, match="expected 2 box poses, got 1"):
        caster.set_boxes([(1.0, 1.0, 0.0)], 20, 15)


@settings(max_examples=60, deadline=None)
@given(first=st.integers(0, 359), dists=st.lists(st.integers(0, 70000), max_size=500),
       stuck=st.booleans())
def test_framer_writes_the_bytes_of_the_reference_encoder(first: int, dists: list[int],
                                                          stuck: bool) -> None:
    framer = LidarFramer(360, 4096)
    d = np.array(dists, dtype=np.int64)
    idx = np.full(len(d), first) if stuck else first + np.arange(len(d))
    want = encode_lidar_packets((idx % 360) * 100, d)
    assert framer.frames(first, d, same_angle=stuck) == want
    assert framer.frames(first, d + 0.75, same_angle=stuck) == want  # fractions are dropped


def test_framer_refuses_more_samples_than_it_was_made_for() -> None:
    with pytest.raises(ValueError, match="at most 10 samples per call, got 11"):
        LidarFramer(360, 10).frames(0, np.zeros(11))


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
