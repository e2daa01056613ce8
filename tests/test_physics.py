"""Rovers driven by PWM move, collide, and report encoder ticks matching their travel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.hardware import decode_counter
from world.geometry import footprint
from world.scenario import load_scenario, parse_scenario
from world.world import World

ROOM = """
name = "box"
[room]
size_cm = [400, 300]
[rovers]
mapper = [100, 50, 0]
hider = [100, 150, 0]
seeker = [100, 250, 0]
"""


def drive(world: World, role: str, left: float, right: float, seconds: float) -> list[int]:
    """Drive one rover and collect its Int E payloads."""
    events: list[int] = []
    hw = world.hardware(role)
    hw.attach(0xE, events.append)
    hw.set_tread_pwm(left, right)
    end = world.time + seconds
    while world.time < end - 1e-9:
        world.step()
    return events


def tread_cm(events: list[int], cm_per_interrupt: float) -> tuple[float, float]:
    """Distance per tread from Int E payloads, as firmware's ISR computes it [cm]."""
    dist = [0.0, 0.0]
    for e in events:
        tread, forward = decode_counter(e)
        dist[tread] += cm_per_interrupt if forward else -cm_per_interrupt
    return dist[0], dist[1]


def test_straight_drive_ticks_match_ground_truth() -> None:
    """Encoder distance equals the true travel within the slip noise and one interrupt."""
    world = World(parse_scenario(ROOM), np.random.default_rng(1))
    start = world.true_pose("mapper")
    events = drive(world, "mapper", 0.6, 0.6, 5.0)
    end = world.true_pose("mapper")
    travelled = math.hypot(end.x - start.x, end.y - start.y)
    assert 60 < travelled < 95  # 0.6 * 30 cm/s for 5 s, less the motor lag
    left, right = tread_cm(events, world.hardware("mapper").spec.cm_per_interrupt)
    tol = 4 * world.params.slip_sigma * math.sqrt(travelled) + 0.5 + 0.5
    assert left == pytest.approx(travelled, abs=tol)
    assert right == pytest.approx(travelled, abs=tol)
    assert abs(end.heading_deg) < 1.0 or abs(end.heading_deg - 360) < 1.0


def test_backwards_drive_counts_backwards() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(2))
    events = drive(world, "hider", -0.5, -0.5, 2.0)
    left, right = tread_cm(events, 0.5)
    assert left < -10 and right < -10
    assert world.true_pose("hider").x < 100 - 10


def test_turn_in_place_matches_tread_difference() -> None:
    """Heading change equals (right - left) / track width, from encoders alone."""
    world = World(parse_scenario(ROOM), np.random.default_rng(3))
    events = drive(world, "seeker", -0.4, 0.4, 1.0)
    events += drive(world, "seeker", 0.0, 0.0, 0.5)
    left, right = tread_cm(events, 0.5)
    spec = world.hardware("seeker").spec
    estimate = math.degrees((right - left) / spec.track_width_cm)
    truth = world.true_pose("seeker").heading_deg
    assert 30 < truth < 200
    assert estimate == pytest.approx(truth, abs=8.0)
    pose = world.true_pose("seeker")
    assert math.hypot(pose.x - 100, pose.y - 250) < 3.0  # turned in place


def test_pushing_a_wall_stops_the_rover_and_its_encoders() -> None:
    """A rover driving into a wall for a long time stays inside and stops counting."""
    world = World(parse_scenario(ROOM), np.random.default_rng(4))
    drive(world, "mapper", 1.0, 1.0, 15.0)  # 300 cm of drive, the wall is 290 cm away
    pose = world.true_pose("mapper")
    assert 385 < pose.x + 10 <= 400.5  # nose at the wall
    later = drive(world, "mapper", 1.0, 1.0, 5.0)
    assert abs(world.true_pose("mapper").x - pose.x) < 0.5
    assert len(later) <= 4


def test_rovers_collide_instead_of_overlapping() -> None:
    """The hider drives into the idle mapper: it pushes it to the wall, never through it."""
    text = ROOM.replace("hider = [100, 150, 0]", "hider = [100, 90, 270]")
    world = World(parse_scenario(text), np.random.default_rng(5))
    drive(world, "hider", 0.8, 0.8, 12.0)
    mapper, hider = world.true_pose("mapper"), world.true_pose("hider")
    a = footprint(mapper, 20, 15)
    b = footprint(hider, 20, 15)
    assert a.intersection(b).area < 5.0
    assert mapper.y == pytest.approx(7.5, abs=1.0)  # pinned against the bottom wall
    assert hider.y == pytest.approx(mapper.y + 7.5 + 10, abs=1.5)


@pytest.mark.parametrize("name", ["cluttered", "corridor", "round"])
def test_nobody_leaves_the_room_in_long_random_driving(name: str) -> None:
    """Random PWM for 60 s in cluttered rooms: every rover stays in the room, out of walls."""
    s = load_scenario(name)
    world = World(s, np.random.default_rng(6))
    cmd = np.random.default_rng(7)
    w, h = s.room_size
    for k in range(60):
        for role in ("mapper", "hider", "seeker"):
            world.hardware(role).set_tread_pwm(*cmd.uniform(-1, 1, 2))
        for _ in range(20):
            world.step()
        for role in ("mapper", "hider", "seeker"):
            p = world.true_pose(role)
            assert 0 < p.x < w and 0 < p.y < h, (k, role, p)
            body = footprint(p, 20, 15)
            for o in s.obstacles:
                assert body.intersection(o).area < 10.0, (k, role, p)


def test_bad_pwm_is_refused() -> None:
    world = World(parse_scenario(ROOM), np.random.default_rng(0))
    with pytest.raises(ValueError, match="left must be a finite number, got nan"):
        world.hardware("mapper").set_tread_pwm(float("nan"), 0)
    world.hardware("mapper").set_tread_pwm(5, -5)  # clipped, not refused
    assert world.treads["mapper"][0].pwm == 1.0 and world.treads["mapper"][1].pwm == -1.0


def dead_reckon(events: list[int], cm: float, track: float, pose: tuple[float, float, float]
                ) -> tuple[float, float, float]:
    """Integrate Int E payloads into a pose (x, y [cm], heading [rad]) as firmware would."""
    x, y, a = pose
    for e in events:
        tread, forward = decode_counter(e)
        d = cm if forward else -cm
        dl, dr = (d, 0.0) if tread == 0 else (0.0, d)
        a_mid = a + (dr - dl) / (2 * track)
        x += (dl + dr) / 2 * math.cos(a_mid)
        y += (dl + dr) / 2 * math.sin(a_mid)
        a += (dr - dl) / track
    return x, y, a


def test_arc_drive_dead_reckons_to_the_true_pose() -> None:
    """Driving an arc, the pose integrated from encoder ticks ends where the rover really is."""
    world = World(parse_scenario(ROOM), np.random.default_rng(6))
    start = world.true_pose("hider")
    events = drive(world, "hider", 0.3, 0.5, 4.0)
    end = world.true_pose("hider")
    spec = world.hardware("hider").spec
    x, y, a = dead_reckon(events, spec.cm_per_interrupt, spec.track_width_cm,
                          (start.x, start.y, math.radians(start.heading_deg)))
    turned = (end.heading_deg - start.heading_deg) % 360
    assert 30 < turned < 120  # a real arc, to the left
    assert math.hypot(x - end.x, y - end.y) < 3.0
    assert math.degrees(a) % 360 == pytest.approx(end.heading_deg, abs=4.0)


@pytest.mark.parametrize("sigma", [0.0, 0.1])
def test_encoder_error_stays_within_the_slip_noise(sigma: float) -> None:
    """Slip sigma [cm / sqrt(cm)]: without slip ticks match truth to one interrupt; with
    slip the error is about sigma * sqrt(distance travelled), never wildly more."""
    text = ROOM + f"[devices]\nslip_sigma = {sigma}\n"
    errors = []
    for seed in range(6):
        world = World(parse_scenario(text), np.random.default_rng(seed))
        start = world.true_pose("mapper")
        events = drive(world, "mapper", 0.8, 0.8, 4.0)
        end = world.true_pose("mapper")
        travelled = math.hypot(end.x - start.x, end.y - start.y)
        left, _ = tread_cm(events, world.hardware("mapper").spec.cm_per_interrupt)
        errors.append(left - travelled)
    sd = sigma * math.sqrt(0.8 * 30 * 4.0)  # [cm] over the distance at speed
    if sigma == 0:
        assert max(abs(e) for e in errors) <= 0.5 + 1e-6
    else:
        assert max(abs(e) for e in errors) <= 4 * sd + 0.5
        assert np.std(errors) > 0.25 * sd  # the noise is really there


def test_direct_chipmunk_steps_and_reads_equal_pymunks_public_api(monkeypatch) -> None:
    """Stepping with Chipmunk's ``cpSpaceStep``, reading poses from Chipmunk and setting
    the control bodies there give the floats of pymunk's `Space.step`, its properties
    and setters, bit for bit, through drives, turns and a wall contact."""
    from world import physics  # noqa: PLC0415

    def play(direct: bool) -> list[tuple[float, float, float]]:
        if not direct:  # pymunk's public API alone: Space.step, properties, setters
            monkeypatch.setattr(physics, "_chipmunk", None)
        world = World(parse_scenario(ROOM), np.random.default_rng(3))
        out = []
        for left, right in ((0.8, 0.8), (0.5, -0.5), (1.0, 1.0), (-0.6, 0.9)):
            for role in ("mapper", "hider", "seeker"):
                world.hardware(role).set_tread_pwm(left, right)
            for _ in range(150):  # 3 s: the mapper reaches the wall ahead
                world.step()
                for role in ("mapper", "hider", "seeker"):
                    state = world.physics.state(role)
                    body = world.physics.rovers[role].body
                    assert state == (*body.position, body.angle)
                    out.append(state)
        monkeypatch.undo()
        return out

    fresh = World(parse_scenario(ROOM), np.random.default_rng(3))
    assert fresh.physics._direct_step() is None  # the bodies added are checked first
    fresh.step()
    assert fresh.physics._direct_step() is not None  # then every step is Chipmunk's
    assert play(direct=True) == play(direct=False)
