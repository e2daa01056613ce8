"""Every fault kind has its effect while active and none once cleared."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from actors.firmware.hardware import ROLES, decode_counter
from supervisors.rover import rover_tree
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_ACTORS, check_fault
from world.scenario import ScenarioError, parse_scenario
from world.world import World

ROOM = """
name = "faults"
[room]
size_cm = [600, 300]
[rovers]
mapper = [100, 250, 0]
hider = [200, 150, 0]
seeker = [150, 150, 0]
[devices]
lidar_noise_cm = 0.0
"""


def make(events: list | None = None, extra: str = "") -> World:
    cb = None if events is None else (lambda k, t, d: events.append((k, t, d)))
    return World(parse_scenario(ROOM + extra), np.random.default_rng(0), on_event=cb)


def run(world: World, seconds: float) -> None:
    end = world.time + seconds
    while world.time < end - 1e-9:
        world.step()


def lidar_bytes(world: World, seconds: float) -> bytes:
    got: list[bytes] = []
    world.hardware("mapper").attach(0xA, got.append)
    world.hardware("mapper").set_lidar_pwm(0.5)
    run(world, seconds)
    return b"".join(got)


def frames(data: bytes) -> list[tuple[int, int]]:
    out = []
    for i in range(0, len(data) - 5, 6):
        s, a, d, c = struct.unpack("<BHHB", data[i:i + 6])
        if s == 0xA5 and c == data[i + 1] ^ data[i + 2] ^ data[i + 3] ^ data[i + 4]:
            out.append((a, d))
    return out


def tread_cm(world: World, role: str, left: float, right: float, seconds: float) -> list[float]:
    got: list[int] = []
    world.hardware(role).attach(0xE, got.append)
    world.hardware(role).set_tread_pwm(left, right)
    run(world, seconds)
    dist = [0.0, 0.0]
    for e in got:
        tread, fwd = decode_counter(e)
        dist[tread] += 0.5 if fwd else -0.5
    return dist


# ---------------------------------------------------------------- LIDAR

def test_lidar_dead_then_cleared() -> None:
    events: list = []
    world = make(events)
    fid = world.inject_fault("mapper/lidar", "dead")
    assert lidar_bytes(world, 0.5) == b""
    assert world.clear_fault(fid) == 1
    assert len(frames(lidar_bytes(world, 0.5))) > 900
    assert [e[0] for e in events] == ["fault_injected", "fault_cleared"]
    assert events[0][1] == "mapper/lidar" and events[0][2]["kind"] == "dead"
    assert events[1][2] == {"time_s": 0.5, "id": fid, "kind": "dead", "reason": "cleared"}


def test_lidar_garbage_bytes_then_cleared() -> None:
    world = make()
    world.inject_fault("mapper/lidar", "garbage")
    data = lidar_bytes(world, 0.5)
    assert len(data) > 5000 and len(frames(data)) < 20  # bytes flow, hardly a valid frame
    world.clear_fault("mapper/lidar")
    assert len(frames(lidar_bytes(world, 0.5))) > 900


def test_lidar_stuck_rotation_then_cleared() -> None:
    world = make()
    world.inject_fault("mapper/lidar", "stuck")
    stuck = frames(lidar_bytes(world, 0.5))
    assert len(stuck) > 900 and len({a for a, _ in stuck}) == 1
    world.clear_fault("mapper/lidar")
    assert len({a for a, _ in frames(lidar_bytes(world, 0.5))}) > 300


def test_lidar_noisy_then_cleared() -> None:
    world = make()
    world.inject_fault("mapper/lidar", "noisy", sigma_cm=10)
    noisy = [d for a, d in frames(lidar_bytes(world, 2.0)) if a == 18000]
    world.clear_fault("mapper/lidar")
    clean = [d for a, d in frames(lidar_bytes(world, 2.0)) if a == 18000]
    assert np.std(noisy) > 5 and np.std(clean) == 0 and clean[0] == 100


# ---------------------------------------------------------------- encoders and motors

def test_encoder_stuck_then_cleared() -> None:
    world = make()
    world.inject_fault("hider/encoder_left", "stuck")
    left, right = tread_cm(world, "hider", 0.5, 0.5, 2.0)
    assert left == 0 and right > 20
    world.clear_fault("hider/encoder_left")
    left, right = tread_cm(world, "hider", 0.5, 0.5, 2.0)
    assert left == pytest.approx(right, abs=2)


def test_encoder_on_both_treads_stuck_then_cleared() -> None:
    """``encoder`` without a side covers both treads; clearing the target restores both."""
    world = make()
    world.inject_fault("seeker/encoder", "stuck")
    assert tread_cm(world, "seeker", 0.5, 0.5, 1.0) == [0.0, 0.0]
    assert world.clear_fault("seeker/encoder") == 1
    left, right = tread_cm(world, "seeker", 0.5, 0.5, 1.0)
    assert left > 10 and right > 10


def test_encoder_slipping_then_cleared() -> None:
    world = make()
    world.inject_fault("hider/encoder_right", "slipping", ratio=0.5)
    left, right = tread_cm(world, "hider", 0.5, 0.5, 2.0)
    assert right == pytest.approx(left / 2, abs=2)
    world.clear_fault("hider/encoder_right")
    left, right = tread_cm(world, "hider", 0.5, 0.5, 2.0)
    assert right == pytest.approx(left, abs=2)


def test_motor_stalled_then_cleared() -> None:
    """Both treads stalled: the rover stays put although driven; cleared, it moves."""
    world = make()
    world.inject_fault("hider/motor", "stalled")
    x0 = world.true_pose("hider").x
    tread_cm(world, "hider", 0.8, 0.8, 1.0)
    assert world.true_pose("hider").x == pytest.approx(x0, abs=0.1)
    world.clear_fault("hider/motor")
    tread_cm(world, "hider", 0.8, 0.8, 1.0)
    assert world.true_pose("hider").x > x0 + 10


def test_motor_weak_tread_curves_then_cleared() -> None:
    """A weak right tread makes a straight command turn right; cleared, it drives straight."""
    world = make()
    world.inject_fault("hider/motor_right", "weak", strength=0.5)
    tread_cm(world, "hider", 0.5, 0.5, 1.0)
    heading = world.true_pose("hider").heading_deg
    assert 180 < heading < 350  # clockwise
    world.clear_fault("hider/motor_right")
    before = world.true_pose("hider").heading_deg
    tread_cm(world, "hider", 0.5, 0.5, 1.0)
    assert world.true_pose("hider").heading_deg == pytest.approx(before, abs=3)


# ---------------------------------------------------------------- IR

@pytest.mark.parametrize(("kind", "value"), [("stuck_high", 4095), ("stuck_low", 0)])
def test_ir_stuck_then_cleared(kind: str, value: int) -> None:
    world = make()
    got: list[int] = []
    hw = world.hardware("seeker")
    hw.attach(0xD, lambda _: hw.start_adc())
    hw.attach(0xC, got.append)
    hw.set_ir_timer(20)
    world.inject_fault("seeker/ir", kind)
    run(world, 0.5)
    assert set(got) == {value}
    world.clear_fault("seeker/ir")
    got.clear()
    run(world, 0.5)
    assert value not in got and 2500 < np.mean(got) < 4000  # the hider is 32.5 cm ahead


# ---------------------------------------------------------------- WiFly

def send_lines(world: World, role: str, n: int, seconds: float) -> list[tuple[float, bytes]]:
    link = world.wifly_link(role)
    got: list[tuple[float, bytes]] = []
    link.on_server_receive = lambda b: got.append((world.time, b))
    for _ in range(n):
        world.hardware(role).wifly_write(b"0123456789" * 5)
        run(world, seconds / n)
    run(world, 0.1)  # let the last chunk land
    return got


def test_wifly_down_for_a_while() -> None:
    """Down for 1 s: nothing gets through and the link reports it; then it recovers alone."""
    events: list = []
    world = make(events)
    world.inject_fault("mapper/wifly", "down", duration_s=1.0)
    assert not world.wifly_link("mapper").connected
    assert send_lines(world, "mapper", 10, 0.9) == []
    run(world, 0.2)
    assert world.wifly_link("mapper").connected
    assert len(send_lines(world, "mapper", 10, 1.0)) == 10
    assert events[-1][0] == "fault_cleared" and events[-1][2]["reason"] == "expired"


def test_wifly_packet_loss_then_cleared() -> None:
    world = make()
    world.inject_fault("seeker/wifly", "loss", percent=50)
    lossy = send_lines(world, "seeker", 100, 5.0)
    assert 25 < len(lossy) < 75
    world.clear_fault("seeker/wifly")
    assert len(send_lines(world, "seeker", 100, 5.0)) == 100


def test_wifly_corrupted_bytes_then_cleared() -> None:
    world = make()
    world.inject_fault("hider/wifly", "corrupt", per_byte=0.05)
    bad = b"".join(b for _, b in send_lines(world, "hider", 40, 2.0))
    assert len(bad) == 2000 and bad != b"0123456789" * 200
    world.clear_fault("hider/wifly")
    good = b"".join(b for _, b in send_lines(world, "hider", 40, 2.0))
    assert good == b"0123456789" * 200


def test_wifly_added_latency_then_cleared() -> None:
    world = make()
    world.inject_fault("hider/wifly", "latency", added_s=0.5)
    t0 = world.time
    slow = send_lines(world, "hider", 1, 1.0)
    assert slow[0][0] - t0 >= 0.5
    world.clear_fault("hider/wifly")
    t1 = world.time
    fast = send_lines(world, "hider", 1, 1.0)
    assert fast[0][0] - t1 < 0.2


# ---------------------------------------------------------------- catalogue rules

#: (device family, kind) -> the test above showing its effect and its clearance
EFFECT_TESTS = {
    ("lidar", "dead"): test_lidar_dead_then_cleared,
    ("lidar", "garbage"): test_lidar_garbage_bytes_then_cleared,
    ("lidar", "stuck"): test_lidar_stuck_rotation_then_cleared,
    ("lidar", "noisy"): test_lidar_noisy_then_cleared,
    ("encoder", "stuck"): test_encoder_stuck_then_cleared,
    ("encoder", "slipping"): test_encoder_slipping_then_cleared,
    ("motor", "stalled"): test_motor_stalled_then_cleared,
    ("motor", "weak"): test_motor_weak_tread_curves_then_cleared,
    ("ir", "stuck_high"): test_ir_stuck_then_cleared,
    ("ir", "stuck_low"): test_ir_stuck_then_cleared,
    ("wifly", "down"): test_wifly_down_for_a_while,
    ("wifly", "loss"): test_wifly_packet_loss_then_cleared,
    ("wifly", "corrupt"): test_wifly_corrupted_bytes_then_cleared,
    ("wifly", "latency"): test_wifly_added_latency_then_cleared,
}


def test_every_fault_kind_in_the_catalogue_has_an_effect_test() -> None:
    """A kind added to DEVICE_FAULTS without a test of its effect and clearance fails here."""
    catalogue = {(d.split("_")[0], k) for d, kinds in DEVICE_FAULTS.items() for k in kinds}
    assert catalogue == set(EFFECT_TESTS)


def test_wifly_down_cleared_by_hand_reconnects_at_once() -> None:
    events: list = []
    world = make(events)
    fid = world.inject_fault("hider/wifly", "down")
    run(world, 0.5)
    assert not world.wifly_link("hider").connected
    world.clear_fault(fid)
    assert world.wifly_link("hider").connected
    assert len(send_lines(world, "hider", 5, 0.5)) == 5
    assert [(k, d["kind"]) for k, _, d in events] == [("fault_injected", "down"),
                                                      ("fault_cleared", "down")]

@pytest.mark.parametrize(
    ("target", "kind", "params", "message"),
    [
        ("mapper/lidar", "melted", {}, "fault kind 'melted' does not apply to lidar"),
        ("hider/lidar", "dead", {}, "hider has no lidar"),
        ("seeker/toaster", "dead", {}, "unknown device 'toaster'"),
        ("dog/lidar", "dead", {}, "fault target rover must be one of mapper, hider, seeker"),
        ("mapper-lidar", "dead", {}, "fault target must be 'rover/device'"),
        ("mapper/lidar", "noisy", {"sigma": 3}, "fault 'noisy' has no parameter 'sigma'"),
        ("mapper/nav", "crash", {}, "'crash' is an actor fault"),
        ("hider/motor", "crash", {}, "'crash' is an actor fault"),
    ],
)
def test_bad_faults_are_refused(target: str, kind: str, params: dict, message: str) -> None:
    world = make()
    with pytest.raises(ValueError, match=message):
        world.inject_fault(target, kind, **params)
    assert world.active_faults() == []


def test_scheduled_faults_fire_and_expire_and_actor_faults_are_handed_over() -> None:
    events: list = []
    world = make(events, """
[[faults]]
at_s = 1
target = "mapper/lidar"
kind = "dead"
duration_s = 0.5
[[faults]]
at_s = 0.5
target = "seeker/nav"
kind = "hang"
""")
    assert world.actor_faults_due() == []
    run(world, 0.55)
    due = world.actor_faults_due()
    assert [(f.target, f.kind) for f in due] == [("seeker/nav", "hang")]
    assert world.actor_faults_due() == []  # each handed over once
    run(world, 0.5)
    assert [(f.target, f.kind) for f in world.active_faults()] == [("mapper/lidar", "dead")]
    run(world, 0.6)
    assert world.active_faults() == []
    kinds = [(k, t) for k, t, _ in events]
    assert kinds == [("actor_fault_due", "seeker/nav"), ("fault_injected", "mapper/lidar"),
                     ("fault_cleared", "mapper/lidar")]
    assert events[1][2]["scheduled"] is True and events[1][2]["time_s"] == pytest.approx(1.0)


# ---------------------------------------------------------------- device or actor: the kind decides

def schedule(*faults: tuple[str, str]) -> str:
    return "".join(f'\n[[faults]]\nat_s = 1\ntarget = "{t}"\nkind = "{k}"\n' for t, k in faults)


@pytest.mark.parametrize("target", ["hider/motor", "mapper/lidar", "seeker/ir", "mapper/wifly",
                                    "hider/wifly", "seeker/motor", "mapper/map", "hider/nav"])
@pytest.mark.parametrize("kind", list(ACTOR_FAULTS))
def test_actor_faults_on_actors_named_like_devices_are_accepted(target: str, kind: str) -> None:
    """crash/hang/flood on hider/motor, mapper/lidar, seeker/ir ... go to the runtime."""
    world = make(extra=schedule((target, kind)))
    assert [(f.target, f.kind) for f in world.scenario.actor_faults] == [(target, kind)]
    run(world, 1.0)
    assert [(f.target, f.kind) for f in world.actor_faults_due()] == [(target, kind)]
    assert world.active_faults() == []  # nothing happened to the device


def test_device_and_actor_faults_on_one_name_each_go_their_way() -> None:
    """hider/motor stalled stops the treads in the world; hider/motor crash is the runtime's."""
    world = make(extra=schedule(("hider/motor", "stalled"), ("hider/motor", "crash")))
    run(world, 1.05)  # the tick starting at 1 s fires the schedule
    assert [(f.target, f.kind) for f in world.active_faults()] == [("hider/motor", "stalled")]
    assert [(f.target, f.kind) for f in world.actor_faults_due()] == [("hider/motor", "crash")]
    x0 = world.true_pose("hider").x
    tread_cm(world, "hider", 0.8, 0.8, 1.0)
    assert world.true_pose("hider").x == pytest.approx(x0, abs=0.1)


def test_flood_takes_its_message_count_and_nothing_else() -> None:
    assert check_fault("seeker/ir", "flood", 0, {"messages": 5}) == {"messages": 5.0}
    assert check_fault("seeker/ir", "flood", 0, {}) == {"messages": 100.0}
    with pytest.raises(ValueError, match=r"fault 'hang' has no parameter 'seconds' "
                                         r"\(parameters: none\)"):
        check_fault("mapper/lidar", "hang", 2, {"seconds": 2})


@pytest.mark.parametrize(
    ("target", "kind", "message"),
    [
        ("mapper/encoder_left", "crash",
         "faults[0]: 'crash' is an actor fault but 'mapper/encoder_left' is not an actor; "
         "mapper's actors are wifly, motor, lidar, map, nav; "
         "device faults on encoder_left are stuck, slipping"),
        ("hider/lidar", "hang",
         "faults[0]: 'hang' is an actor fault but 'hider/lidar' is not an actor; "
         "hider's actors are wifly, motor, nav"),
        ("seeker/toaster", "flood",
         "faults[0]: 'flood' is an actor fault but 'seeker/toaster' is not an actor; "
         "seeker's actors are wifly, motor, ir, nav"),
        ("mapper/nav", "dead",
         "faults[0]: 'mapper/nav' is an actor and 'dead' is no actor fault; "
         "actor faults are crash, hang, flood"),
        ("mapper/map", "stalled",
         "faults[0]: 'mapper/map' is an actor and 'stalled' is no actor fault"),
        ("hider/motor", "dead",
         "faults[0]: fault kind 'dead' does not apply to motor; kinds are stalled, weak "
         "(actor faults: crash, hang, flood)"),
        ("seeker/encoder", "crash",
         "faults[0]: 'crash' is an actor fault but 'seeker/encoder' is not an actor"),
    ],
)
def test_a_kind_that_does_not_fit_the_target_is_refused_clearly(target: str, kind: str,
                                                                message: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(ROOM + schedule((target, kind)), source="f.toml")
    assert str(err.value).startswith("f.toml: " + message)


@pytest.mark.parametrize("role", ROLES)
def test_the_actor_catalogue_matches_the_rover_trees(role: str) -> None:
    """ROLE_ACTORS names exactly the workers supervisors/rover.py starts for each role."""
    world = make()
    spec = rover_tree(role, world.hardware(role))
    assert tuple(c.id for c in spec.children) == ROLE_ACTORS[role]


def test_every_device_in_the_catalogue_has_kinds() -> None:
    assert all(DEVICE_FAULTS[d] for d in DEVICE_FAULTS)


@pytest.mark.parametrize(("hider", "seen"), [
    ("[200, 150, 0]", True),  # ahead: the nose at 160, the hider's body from 190
    ("[300, 150, 0]", False),  # ahead, beyond the 60 cm range
    ("[90, 150, 0]", False),  # behind
    ("[190, 240, 0]", False),  # in range of the nose but far outside the field of view
])
def test_the_hider_in_ir_view_is_ground_truth_of_range_and_field_of_view(hider: str,
                                                                          seen: bool) -> None:
    """`World.hider_in_ir_view`: the hider's body within IR range of the seeker's nose and
    its centre within the field of view."""
    room = ROOM.replace("hider = [200, 150, 0]", f"hider = {hider}")
    world = World(parse_scenario(room), np.random.default_rng(0))
    assert world.hider_in_ir_view() is seen
