"""IR sensor (Int D / Int C) and the WiFly link model."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from world.geometry import Pose, footprint
from world.ir import IR_EDGE, IrSensor
from world.lidar import Lidar
from world.params import DeviceParams
from world.scenario import parse_scenario
from world.world import World

ROOM = """
name = "io"
[room]
size_cm = [400, 300]
[rovers]
mapper = [50, 250, 0]
hider = [200, 150, 0]
seeker = [150, 150, 0]
"""


def run(world: World, seconds: float) -> None:
    end = world.time + seconds
    while world.time < end - 1e-9:
        world.step()


def ir_samples(world: World, rate_hz: float, seconds: float) -> tuple[int, list[int]]:
    """Wire the seeker's IR like firmware does: Int D starts the ADC, Int C posts the sample."""
    hw = world.hardware("seeker")
    timer: list[None] = []
    samples: list[int] = []
    hw.attach(0xD, lambda _: (timer.append(None), hw.start_adc()))
    hw.attach(0xC, samples.append)
    hw.set_ir_timer(rate_hz)
    run(world, seconds)
    return len(timer), samples


def test_ir_is_high_with_the_hider_in_front_and_low_otherwise() -> None:
    """Hider 32.5 cm ahead: readings near 3300; seeker turned away: near 200."""
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    n, samples = ir_samples(world, 50, 1.0)
    assert n == 50 and len(samples) == 50
    assert 3000 < np.mean(samples) < 3600
    world.hardware("seeker").set_tread_pwm(-0.5, 0.5)
    run(world, 0.6)  # about 80 deg to the left
    world.hardware("seeker").set_tread_pwm(0, 0)
    run(world, 0.5)
    _, away = ir_samples(world, 50, 1.0)
    assert np.mean(away) < 400
    assert all(0 <= s <= 4095 for s in samples + away)


@settings(max_examples=150, deadline=None)
@given(dx=st.floats(-90, 90), dy=st.floats(-90, 90), seeker_deg=st.floats(-360, 360),
       hider_deg=st.floats(-360, 360))
def test_ir_level_follows_the_distance_from_the_nose_to_the_hiders_body(
        dx: float, dy: float, seeker_deg: float, hider_deg: float) -> None:
    """The level is the documented function of the shapely distance nose -> body, within the FOV."""
    p = DeviceParams()
    seeker = (100.0, 100.0, math.radians(seeker_deg))
    hider = (100.0 + dx, 100.0 + dy, math.radians(hider_deg))
    got = IrSensor(p).reading(seeker, hider, 0.0)
    nose = (100.0 + math.cos(seeker[2]) * 10.0, 100.0 + math.sin(seeker[2]) * 10.0)
    body = footprint(Pose(hider[0], hider[1], hider_deg), p.length_cm, p.width_cm)
    d = shapely.distance(shapely.Point(nose), body)
    bearing = math.degrees(math.atan2(hider[1] - nose[1], hider[0] - nose[0])) - seeker_deg
    in_view = abs((bearing + 180.0) % 360.0 - 180.0) <= p.ir_fov_deg
    if in_view and d <= p.ir_range_cm:
        assert got == pytest.approx(p.ir_high - (p.ir_high - IR_EDGE) * d / p.ir_range_cm,
                                    abs=1e-6)
    elif not in_view or d > p.ir_range_cm + 1e-9:
        assert got == p.ir_low


def test_ir_is_low_beyond_range() -> None:
    text = ROOM.replace("hider = [200, 150, 0]", "hider = [260, 150, 0]")  # 92.5 cm away
    world = World(parse_scenario(text), np.random.default_rng(0))
    _, samples = ir_samples(world, 20, 1.0)
    assert np.mean(samples) < 400


def test_adc_started_outside_a_tick_completes_in_the_next_tick() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    got: list[int] = []
    world.hardware("seeker").attach(0xC, got.append)
    world.hardware("seeker").start_adc()
    assert got == []
    world.step()
    assert len(got) == 1
    world.step()
    assert len(got) == 1  # one conversion, one Int C


def test_ir_timer_stops_at_zero_and_refuses_nonsense() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    n, _ = ir_samples(world, 0, 1.0)
    assert n == 0
    with pytest.raises(ValueError, match="rate_hz must be a finite number >= 0, got -1"):
        world.hardware("seeker").set_ir_timer(-1)


def test_wifly_delivers_both_ways_with_latency_and_throughput() -> None:
    """2000 bytes at 11520 bytes/s arrive whole, in order, after the link's delay."""
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    link = world.wifly_link("hider")
    at_server: list[tuple[float, bytes]] = []
    at_rover: list[bytes] = []
    link.on_server_receive = lambda b: at_server.append((world.time, b))
    world.hardware("hider").attach(0xB, at_rover.append)
    payload = bytes(range(256)) * 8  # 2048 bytes
    world.hardware("hider").wifly_write(payload)
    link.server_write(b'{"cmd": "start"}\n')
    run(world, 1.0)
    assert b"".join(c for _, c in at_server) == payload
    assert b"".join(at_rover) == b'{"cmd": "start"}\n'
    assert at_server[-1][0] >= 2048 / 11520  # throughput-limited
    assert link.connected


def test_wifly_send_buffer_is_bounded_and_drops_are_counted() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    world.hardware("mapper").wifly_write(b"x" * 10000)
    stats = world.wifly_link("mapper").statistics()["up"]
    assert stats.buffered == 8192 and stats.dropped_bytes == 10000 - 8192


def test_wifly_disconnect_drops_and_connect_restores() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    link = world.wifly_link("seeker")
    got: list[bytes] = []
    link.on_server_receive = got.append
    link.disconnect()
    assert not link.connected
    world.hardware("seeker").wifly_write(b"lost")
    run(world, 0.5)
    assert got == []
    link.connect()
    world.hardware("seeker").wifly_write(b"kept")
    run(world, 0.5)
    assert got == [b"kept"]
    with pytest.raises(TypeError, match="data must be bytes, got str"):
        world.hardware("seeker").wifly_write("text")


def test_a_reading_is_the_level_of_the_poses_given_plus_its_noise() -> None:
    """The level kept for the last poses (a tick's samples) never stands in for others:
    new poses, equal or not, read their own level."""
    p = DeviceParams()
    ir = IrSensor(p)
    seeker = (100.0, 100.0, 0.0)
    near, far = (125.0, 100.0, 0.3), (500.0, 100.0, 0.3)
    assert ir.reading(seeker, near, 0.0) == ir.level(seeker, near) > p.ir_low
    assert ir.reading(seeker, near, 7.5) == ir.level(seeker, near) + 7.5  # the same tick
    assert ir.reading(seeker, far, 7.5) == p.ir_low + 7.5  # the hider moved away
    again = tuple(list(seeker)), tuple(list(near))  # equal poses, other objects
    assert again[0] is not seeker and ir.reading(*again, -3.0) == ir.level(seeker, near) - 3.0
    turned = (100.0, 100.0, math.pi)
    assert ir.reading(turned, near, 0.0) == p.ir_low  # the seeker turned away


def test_an_idle_lidar_or_ir_tick_would_have_done_nothing() -> None:
    """`idle` holds only where the tick's own arithmetic takes no sample, no Int D, and
    leaves the state as it was."""
    p = DeviceParams()
    lidar = Lidar(p)
    assert lidar.idle()
    before = (lidar.index, lidar.samples, lidar._sample_acc)
    assert lidar.due(0.05, False)[1] == 0 and (lidar.index, lidar.samples,
                                                 lidar._sample_acc) == before
    lidar.pwm = 0.5
    assert not lidar.idle() and lidar.due(0.05, False)[1] > 0
    lidar.pwm = 0.0  # stopped with part of a sample accumulated: still idle
    assert lidar.idle() == (lidar._sample_acc < 1.0)
    ir = IrSensor(p)
    assert ir.idle() and ir.timer_events(0.05) == 0 and ir.idle()
    ir.set_rate(50.0)
    assert not ir.idle() and ir.timer_events(0.05) == 2
    ir.set_rate(0.0)
    ir.start()  # a conversion pending: its Int C is still to come
    assert not ir.idle()
