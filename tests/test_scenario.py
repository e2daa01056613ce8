"""Scenario files: built-ins load, bad files are refused with file, key and reason."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest
import shapely

from world.geometry import footprint
from world.scenario import (
    ScenarioError,
    builtin_scenarios,
    generate_scenario,
    load_scenario,
    parse_scenario,
)
from world.truth import truth_raster

GOOD = """
name = "studio"
[room]
size_cm = [600, 450]
[[obstacles]]
box = [100, 200, 60, 40]
[[obstacles]]
circle = [400, 300, 25]
[[obstacles]]
polygon = [[250, 50], [320, 60], [300, 120]]
[rovers]
mapper = [50, 50, 0]
hider = [50, 110, 0]
seeker = [50, 170, 0]
[game]
hide_at = [520, 380, 90]
seek_at = [[300, 200], [520, 380]]
[devices]
lidar_noise_cm = 1.0
[[faults]]
at_s = 20
target = "mapper/lidar"
kind = "dead"
duration_s = 10
[[faults]]
at_s = 5
target = "mapper/nav"
kind = "crash"
"""


def test_issue_example_parses() -> None:
    """The example from the issue is a valid scenario with every section."""
    s = parse_scenario(GOOD, "studio.toml")
    assert s.name == "studio" and s.room_size == (600.0, 450.0)
    assert len(s.obstacles) == 3
    assert s.starts["hider"].y == 110
    assert s.hide_at.heading_deg == 90 and s.seek_at == ((300, 200), (520, 380))
    assert s.params().lidar_noise_cm == 1.0
    assert [f.kind for f in s.faults] == ["crash", "dead"]  # sorted by time
    assert [f.target for f in s.actor_faults] == ["mapper/nav"]


def test_builtins_are_graded_and_all_load() -> None:
    """At least the eight required built-ins exist, easiest first, and validate."""
    names = builtin_scenarios()
    for required in ("empty", "furniture", "l_shaped", "corridor", "cluttered", "hall",
                     "round", "gap"):
        assert required in names
    assert names[0] == "empty" and names.index("gap") > names.index("furniture")
    for name in names:
        s = load_scenario(name)
        assert s.starts["mapper"].heading_deg == 0
        assert s.hide_at is not None and s.seek_at


def test_hall_is_ten_by_eight_metres() -> None:
    assert load_scenario("hall").room_size == (1000.0, 800.0)


def test_gap_hiding_spot_is_reachable_only_through_the_gap() -> None:
    """Blocking the gap makes the hide spot unreachable: it is the only way in."""
    s = load_scenario("gap")
    truth = truth_raster(s)
    hx, hy = int(s.hide_at.x // 5), int(s.hide_at.y // 5)
    assert truth.reachable[hy, hx]
    blocked = parse_scenario(
        pathlib.Path("world/scenarios/gap.toml").read_text()
        + "\n[[obstacles]]\nbox = [400, 300, 15, 35]\n", "gap-closed")
    assert not truth_raster(blocked).reachable[hy, hx]


@pytest.mark.parametrize("resolution", [5.0, 3.0, 7.5])
def test_the_truth_raster_marks_the_cells_whose_interior_an_obstacle_overlaps(
        resolution: float) -> None:
    """Every cell, decided from its centre or from its box, is occupied exactly when its
    box (shrunk by 1e-6 cm, clipped to the room) intersects an obstacle: built-in rooms,
    generated ones and a room whose size is no multiple of the cell."""
    rooms = [load_scenario(name) for name in ("furniture", "l_shaped", "cluttered",
                                              "round", "gap")]
    rooms += [generate_scenario(11, i) for i in range(3)]
    rooms.append(parse_scenario(GOOD.replace("size_cm = [600, 450]",
                                             "size_cm = [601.3, 449.99]"), "odd"))
    for s in rooms:
        w, h = s.room_size
        nx, ny = int(np.ceil(w / resolution)), int(np.ceil(h / resolution))
        x0, y0 = np.meshgrid(np.arange(nx) * resolution, np.arange(ny) * resolution)
        e = 1e-6
        boxes = shapely.box(x0 + e, y0 + e, np.minimum(x0 + resolution, w) - e,
                            np.minimum(y0 + resolution, h) - e)
        want = shapely.intersects(shapely.union_all(list(s.obstacles)), boxes)
        assert np.array_equal(truth_raster(s, resolution).occupied, want), s.name


def test_corridor_is_barely_wider_than_a_rover() -> None:
    s = load_scenario("corridor")
    width = s.obstacles[1].bounds[1] - s.obstacles[0].bounds[3]
    assert s.params().width_cm < width < s.params().width_cm * 2.5


def _with(old: str, new: str) -> str:
    assert old in GOOD
    return GOOD.replace(old, new)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (_with('name = "studio"', 'name = "studio"\ncolour = "red"'),
         "bad.toml: colour: unknown key"),
        (_with("size_cm = [600, 450]", 'size_cm = ["600", 450]'),
         "bad.toml: room.size_cm: must be a list of 2 numbers"),
        (_with("box = [100, 200, 60, 40]", "box = [580, 200, 60, 40]"),
         "bad.toml: obstacles[0].box: lies partly outside the room (600 x 450 cm)"),
        (_with("circle = [400, 300, 25]", "circle = [400, 300, -5]"),
         "bad.toml: obstacles[1].circle: radius must be > 0"),
        (_with("mapper = [50, 50, 0]", "mapper = [120, 215, 0]"),
         "bad.toml: rovers.mapper: start pose (120, 215) is inside or touches obstacles[0]"),
        (_with("seeker = [50, 170, 0]", "seeker = [55, 115, 0]"),
         "bad.toml: rovers.seeker: overlaps the hider rover's start pose"),
        (_with("hider = [50, 110, 0]", "hider = [5, 110, 0]"),
         "bad.toml: rovers.hider: rover at (5, 110) does not fit inside the room"),
        (_with("seek_at = [[300, 200], [520, 380]]", "seek_at = [[300, 900]]"),
         "bad.toml: game.seek_at[0]: (300, 900) is outside the room"),
        (_with("lidar_noise_cm = 1.0", "lidar_noise = 1.0"),
         "bad.toml: devices.lidar_noise: unknown key"),
        (_with("lidar_noise_cm = 1.0", "lidar_quantum_cm = 0"),
         "bad.toml: devices.lidar_quantum_cm: lidar_quantum_cm must be > 0, got 0"),
        (_with("lidar_noise_cm = 1.0", "lidar_samples_per_rev = 100000"),
         "bad.toml: devices.lidar_samples_per_rev: lidar_samples_per_rev must be at most "
         "36000, got 100000"),
        (_with("lidar_noise_cm = 1.0", "wifly_loss = 1.5"),
         "bad.toml: devices.wifly_loss: wifly_loss must be at most 1, got 1.5"),
        (_with('kind = "dead"', 'kind = "sleepy"'),
         "bad.toml: faults[0]: fault kind 'sleepy' does not apply to lidar"),
        (_with('target = "mapper/lidar"', 'target = "hider/lidar"'),
         "bad.toml: faults[0]: hider has no lidar"),
        (_with('kind = "crash"', 'kind = "explode"'),
         "bad.toml: faults[1]: 'mapper/nav' is an actor and 'explode' is no actor fault"),
        ("name = 'x'\n[room\n", "bad.toml: not valid TOML"),
        (_with("[rovers]\nmapper = [50, 50, 0]\n", "[rovers]\n"),
         "bad.toml: rovers.mapper: missing"),
    ],
    ids=["unknown-key", "wrong-type", "outside-room", "negative-radius", "start-in-obstacle",
         "overlapping-rovers", "rover-outside", "guess-outside", "unknown-device-param",
         "zero-quantum", "too-many-samples", "loss-above-one",
         "bad-fault-kind", "device-not-on-rover", "bad-actor-kind", "not-toml",
         "missing-rover"],
)
def test_bad_file_is_refused_naming_file_key_and_reason(text: str, expected: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "bad.toml")
    assert str(info.value).startswith(expected), str(info.value)


def test_load_by_path_and_unknown_name(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "studio.toml"
    path.write_text(GOOD)
    assert load_scenario(str(path)).name == "studio"
    with pytest.raises(ScenarioError, match="no-such-room: no such scenario file or built-in"):
        load_scenario("no-such-room")
    path.write_text(_with("[room]", "[roomz]"))
    with pytest.raises(ScenarioError, match=f"{path}: roomz: unknown key"):
        load_scenario(str(path))


def test_generator_is_seeded_and_valid() -> None:
    """Same seed and index give the same room; the hide spot is reachable floor."""
    a, b = generate_scenario(3, 1), generate_scenario(3, 1)
    assert a.room_size == b.room_size and a.hide_at == b.hide_at
    assert [g.wkt for g in a.obstacles] == [g.wkt for g in b.obstacles]
    rooms = {generate_scenario(3, i).room_size for i in range(6)}
    assert len(rooms) > 1
    for i in range(8):
        s = generate_scenario(11, i)
        truth = truth_raster(s)
        hx, hy = int(s.hide_at.x // 5), int(s.hide_at.y // 5)
        assert truth.reachable[hy, hx]
        body = footprint(s.hide_at, 20, 15)
        assert not any(body.intersects(o) for o in s.obstacles)
        assert s.seek_at[-1] == (s.hide_at.x, s.hide_at.y)
        assert np.isfinite(s.room_size).all()
