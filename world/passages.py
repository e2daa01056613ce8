"""Narrow passages of a room and the rovers' trips through them, from ground truth.

A passage is the floor between two obstacles (the room's sides count as
obstacles) that stand 0 < d <= `NARROW_CM` apart: the points whose distances to
the two add up to at most ``REACH * d``. Between parallel faces that is the
whole gap, however long (a corridor); past its mouths it reaches about 0.33 d
along the centre line, where a rover's nose is at the mouth. Its axis runs
across the shortest line between the two.

`PassageCounter` follows each rover's true centre: an **entry** is the centre
coming into a passage; the entry ends when the centre leaves it, **through** when
it leaves on the other side of the gap than it came in, **back** when on the same
side; one still inside when the game ends is **inside**. Metrics only: the
campaign's probe feeds it true poses, nothing steers by it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import shapely

from world.scenario import Scenario

#: obstacles this close or closer [cm] make a passage (the widest that the passage
#: room family draws: a rover is 15 cm wide)
NARROW_CM = 45.0
#: a point is in a passage when its distances to the two obstacles add up to at most
#: this many times their distance
REACH = 1.2
_SIDE_CM = 10.0     # thickness of the strips standing for the room's sides
_TOLERANCE_CM = 1e-6  # rounding of coordinates written to 0.1 cm
_NEAR_CM = 50.0     # a rover this close to a passage's box has its side noted [cm]


@dataclass(frozen=True, slots=True)
class Passage:
    """The floor between two obstacles that stand `NARROW_CM` or closer."""

    walls: tuple[shapely.Geometry, shapely.Geometry]
    """The two obstacles."""
    width_cm: float
    """The obstacles' distance [cm]."""
    centre: tuple[float, float]
    """Midpoint of the shortest line between the obstacles [cm]."""
    axis: tuple[float, float]
    """Unit vector along the passage (across the shortest line)."""
    bounds: tuple[float, float, float, float]
    """A box (x0, y0, x1, y1) round the passage [cm]."""

    def side(self, x: float, y: float) -> int:
        """Which side of the gap (x, y) lies on: +1 along `axis`, else -1."""
        along = (x - self.centre[0]) * self.axis[0] + (y - self.centre[1]) * self.axis[1]
        return 1 if along >= 0 else -1

    def contains(self, x: float, y: float) -> bool:
        """Whether (x, y) [cm] lies in the passage."""
        x0, y0, x1, y1 = self.bounds
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            return False
        p = shapely.Point(x, y)
        a, b = self.walls
        return a.distance(p) + b.distance(p) <= REACH * self.width_cm + _TOLERANCE_CM


def narrow_passages(scenario: Scenario, narrow_cm: float = NARROW_CM) -> list[Passage]:
    """Every passage of the room: each pair of obstacles 0 < d <= ``narrow_cm`` apart."""
    w, h = scenario.room_size
    s = _SIDE_CM
    geoms = [*scenario.obstacles, shapely.box(-s, -s, w + s, 0), shapely.box(-s, h, w + s, h + s),
             shapely.box(-s, 0, 0, h), shapely.box(w, 0, w + s, h)]
    out = []
    for i, a in enumerate(geoms):
        for b in geoms[i + 1:]:
            d = float(a.distance(b))
            if not 0 < d <= narrow_cm + _TOLERANCE_CM:
                continue
            (x0, y0), (x1, y1) = shapely.shortest_line(a, b).coords
            near = a.buffer(REACH * d).intersection(b.buffer(REACH * d))  # holds the passage
            out.append(Passage((a, b), d, ((x0 + x1) / 2, (y0 + y1) / 2),
                               (-(y1 - y0) / d, (x1 - x0) / d), near.bounds))
    return out


@dataclass
class PassageTrips:
    """One rover's trips through passages."""

    entries: int = 0
    through: int = 0
    back: int = 0


@dataclass
class PassageCounter:
    """Counts each rover's entries into ``passages`` from its true positions."""

    passages: list[Passage]
    trips: dict[str, PassageTrips] = field(default_factory=dict)
    _in: dict[str, tuple[int, int]] = field(default_factory=dict)
    """Rover -> (passage index, side it came in from) while inside one."""
    _side: dict[str, dict[int, int]] = field(default_factory=dict)
    """Rover -> passage index -> the side it was last seen on outside it."""

    def update(self, role: str, x: float, y: float) -> None:
        """Note the rover's true centre (room frame [cm])."""
        trips = self.trips.setdefault(role, PassageTrips())
        sides = self._side.setdefault(role, {})
        now = self._inside(x, y)
        held = self._in.get(role)
        if held is not None and held[0] != now:
            k, came = held
            if self.passages[k].side(x, y) == came:
                trips.back += 1
            else:
                trips.through += 1
            del self._in[role]
            held = None
        if now is not None and held is None:
            trips.entries += 1
            came = sides.get(now, self.passages[now].side(x, y))
            self._in[role] = (now, came)
        for k, p in enumerate(self.passages):
            x0, y0, x1, y1 = p.bounds
            if k != now and x0 - _NEAR_CM <= x <= x1 + _NEAR_CM \
                    and y0 - _NEAR_CM <= y <= y1 + _NEAR_CM:
                sides[k] = p.side(x, y)

    def _inside(self, x: float, y: float) -> int | None:
        for k, p in enumerate(self.passages):
            if p.contains(x, y):
                return k
        return None

    def summary(self) -> dict[str, dict[str, int]]:
        """Per rover: ``entries``, ``through``, ``back``, ``inside`` (a JSON-able dict)."""
        out = {}
        for role, t in sorted(self.trips.items()):
            inside = 1 if role in self._in else 0
            out[role] = {"entries": t.entries, "through": t.through, "back": t.back,
                         "inside": inside}
        return out
