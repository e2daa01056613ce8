"""The passage room family (world/passage_rooms.py), measured on the geometry with shapely,
and the default family kept as it was."""

from __future__ import annotations

import hashlib

import pytest
import shapely

from world.geometry import footprint, room_polygon, union
from world.scenario import (
    ROOM_FAMILIES,
    Scenario,
    ScenarioError,
    generate_scenario,
    parse_generated,
)

ROOMS = [(seed, i) for seed in (1, 7, 34) for i in range(12)]


def _room(seed: int, i: int) -> Scenario:
    return generate_scenario(seed, i, "passages")


def _walls(s: Scenario) -> list[float]:
    """The x of each wall's middle: the boxes that touch the bottom of the room."""
    return sorted({(g.bounds[0] + g.bounds[2]) / 2 for g in s.obstacles if g.bounds[1] == 0
                   and g.bounds[3] - g.bounds[1] < s.room_size[1]})


def _gaps(s: Scenario, x: float) -> list[float]:
    """Lengths of the free stretches of the room's vertical line at ``x`` [cm]."""
    line = shapely.LineString([(x, 0), (x, s.room_size[1])])
    free = line.difference(union(list(s.obstacles)))
    return [g.length for g in getattr(free, "geoms", [free]) if g.length > 0]


def _body_floor(s: Scenario, half_width: float) -> shapely.Geometry:
    """Floor the centre of a body of this half width may be on."""
    floor = room_polygon(*s.room_size)
    return floor.buffer(-half_width).difference(union(list(s.obstacles)).buffer(half_width))


def _connected(region: shapely.Geometry, a: tuple[float, float], b: tuple[float, float]) -> bool:
    pa, pb = shapely.Point(a), shapely.Point(b)
    return any(p.contains(pa) and p.contains(pb) for p in getattr(region, "geoms", [region]))


@pytest.mark.parametrize(("seed", "i"), ROOMS)
def test_every_passage_room_is_cut_by_walls_whose_one_gap_is_25_to_45_cm(seed: int,
                                                                          i: int) -> None:
    s = _room(seed, i)
    walls = _walls(s)
    assert 1 <= len(walls) <= 2
    for x in walls:
        gaps = _gaps(s, x)
        assert len(gaps) == 1, gaps
        assert 25.0 - 1e-9 <= gaps[0] <= 45.0 + 1e-9


@pytest.mark.parametrize(("seed", "i"), ROOMS)
def test_the_gaps_are_the_only_narrow_places(seed: int, i: int) -> None:
    """Any two obstacles (the room's sides included) touch, stand 25-45 cm apart (a gap)
    or stand far apart, so no clutter narrows a passage further."""
    s = _room(seed, i)
    w, h = s.room_size
    sides = [shapely.box(-1, -1, w + 1, 0), shapely.box(-1, h, w + 1, h + 1),
             shapely.box(-1, 0, 0, h), shapely.box(w, 0, w + 1, h)]
    geoms = [*s.obstacles, *sides]
    for j, a in enumerate(geoms):
        for b in geoms[j + 1:]:
            d = a.distance(b)
            assert d == 0 or 25.0 - 1e-9 <= d <= 45.0 + 1e-9 or d >= 55.0, (a.wkt, b.wkt, d)


@pytest.mark.parametrize(("seed", "i"), ROOMS)
def test_the_hide_spot_is_reachable_only_through_a_passage(seed: int, i: int) -> None:
    """A rover's body (15 cm wide) fits from the start to the hide spot and the decoy;
    a body wider than 45 cm fits at the start but not to the hide spot; the hide spot
    lies beyond every wall and the decoy before them, where a rover can turn."""
    s = _room(seed, i)
    start = (s.starts["hider"].x, s.starts["hider"].y)
    hide, decoy = (s.hide_at.x, s.hide_at.y), s.seek_at[0]
    assert s.seek_at[-1] == hide
    rover = _body_floor(s, 7.5)
    assert _connected(rover, start, hide) and _connected(rover, start, decoy)
    wide = _body_floor(s, 23.0)
    assert wide.contains(shapely.Point(start)) and not _connected(wide, start, hide)
    walls = _walls(s)
    assert decoy[0] < min(walls) <= max(walls) < hide[0]
    turning = footprint(s.hide_at, 20, 15).buffer(5)
    assert not any(turning.intersects(o) for o in s.obstacles)


def test_passage_rooms_are_deterministic_by_seed_and_index() -> None:
    a, b = _room(3, 1), _room(3, 1)
    assert a == b
    assert [g.wkt for g in a.obstacles] == [g.wkt for g in b.obstacles]
    assert len({_room(3, i).room_size for i in range(8)}) > 1
    assert _room(3, 1).obstacles != _room(4, 1).obstacles
    assert a.name == "passages-3-1" and a.source == "generated:passages:3/1"


def test_the_default_family_draws_the_rooms_it_always_drew() -> None:
    """The fingerprint of twelve default rooms, taken from the generator before the
    passage family existed (the trace hashes of ``--generated`` games rest on it)."""
    h = hashlib.sha256()
    for seed in (1, 11, 12):
        for i in range(4):
            s = generate_scenario(seed, i)
            assert s == generate_scenario(seed, i, ROOM_FAMILIES[0])
            one = repr((s.name, s.room_size, [g.wkt for g in s.obstacles], s.hide_at,
                        s.seek_at, s.source)).encode()
            h.update(hashlib.sha256(one).hexdigest()[:16].encode())
    assert h.hexdigest()[:16] == "04f90f0564a50dbc"


def test_generated_room_references_read_family_seed_and_index() -> None:
    assert parse_generated("11:0") == (11, 0, "obstacles")
    assert parse_generated("passages:3:2") == (3, 2, "passages")
    assert generate_scenario(*parse_generated("passages:3:2")).name == "passages-3-2"
    for bad in ("11", "x:1", "mazes:1:2", "1:2:3:4", "passages:-1:0", ""):
        with pytest.raises(ScenarioError, match="generated room|room family|>= 0"):
            parse_generated(bad)
    with pytest.raises(ScenarioError, match="room family must be one of"):
        generate_scenario(1, 0, "mazes")
