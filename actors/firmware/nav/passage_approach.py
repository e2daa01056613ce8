"""A narrow passage on a route: where it is, how unsure across it the rover will be,
the face across it a rover can touch, and a slanted crossing squared to its axis.

Why
    A gap in a wall is a place across which the hider and the seeker cannot
    measure their position before they are in it: they have no range sensor, and
    the faces round a gap's mouth are square to its axis, so a contact with one
    tells how far the rover is from the wall, not where along it. What tells the
    lateral place before the gap is a face square to the lateral direction (the
    wall the gap's wall meets, a box's side), touched head-on
    (`lateral_touch.LateralTouch` uses `face_across`). At the gap itself, a body
    whose nose enters it has its lateral offset within the passage's play (the
    free-space model weighs out the rest at the next rest), and a nose that meets
    the face beside the mouth head-on gives a contact with two explanations,
    either side of the mouth (the probe series of `nudge` steps between them).
    Both need the body square to the passage: at a slant ``a`` a body of
    ``length x width`` spans ``width cos a + length sin a`` across the gap (a
    15 x 20 cm body at 30 deg: 23 cm of a 25 cm gap), so a route that crosses at
    a slant the doubt makes tight is drawn through the passage along its axis
    (`square_to_axis`).

What is a passage here
    The route's first stretch where the map's free width across the route is
    under `nudge.PROBE_WIDTH_CM` (`planning.clearance`) and that the route
    leaves again before its end (`passage_on_route`). Its axis is the direction,
    within `AXIS_SWEEP_DEG` of the route, across which the free width at its
    narrowest point is least (across a slanted line it is the gap's width over
    the cosine, flat within the sampling near the axis: the middle of the
    directions that give the least width); its centre is the middle of that
    narrowest section; its ends are where the width across the axis opens
    again, looked for as far as the route is long. The rover may miss it when
    the belief's lateral 95 % spread at it (`lateral_spread95_cm`) is more than
    half the play the passage leaves the body (`misses`).

Pure functions: no actor, no clock. Frame and units: map frame, [cm], [deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.localisation.gaussian_pose import Z_95
from actors.firmware.nav.nudge import PROBE_WIDTH_CM
from actors.firmware.planning.clearance import cross_section, first_occupied
from actors.firmware.planning.planner import line_of_sight, traversable
from server.protocol.grid_map import GridMap
from server.protocol.pose import angle_diff_deg

__all__ = ["Passage", "RoutePassage", "Touch", "AXIS_SWEEP_DEG", "passage_on_route",
           "lateral_spread95_cm", "body_span_cm", "misses", "square_to_axis",
           "approach_point", "face_across"]

Point = tuple[float, float]

AXIS_SWEEP_DEG = 45
"""The passage's axis is looked for within this many degrees either side of the route
where it crosses it, in whole degrees [deg]: a route crossing a gap more steeply than
45 deg from its axis has the body across the gap and does not pass at all."""


@dataclass(frozen=True, slots=True)
class Passage:
    """A narrow passage a route crosses (map frame)."""

    centre: Point
    """The middle of its narrowest cross-section [cm]."""
    axis_deg: float
    """Its axis, pointing the way the route crosses it [deg]."""
    width_cm: float
    """The map's free width across the axis at the centre [cm]."""
    entry_cm: float
    """From the centre back along the axis to where it opens [cm]."""
    exit_cm: float
    """From the centre on along the axis to where it opens [cm]."""

    @property
    def unit(self) -> Point:
        """The axis as a unit vector."""
        h = math.radians(self.axis_deg)
        return math.cos(h), math.sin(h)

    def along(self, t: float) -> Point:
        """The point ``t`` [cm] along the axis from the centre (negative: before it)."""
        ux, uy = self.unit
        return self.centre[0] + t * ux, self.centre[1] + t * uy

    def axial(self, p: Point) -> float:
        """How far ``p`` lies along the axis from the centre [cm] (negative: before it)."""
        ux, uy = self.unit
        return (p[0] - self.centre[0]) * ux + (p[1] - self.centre[1]) * uy

    def approach_cm(self, standoff_cm: float) -> float:
        """How far before the centre, along the axis, the approach point lies [cm]:
        ``standoff_cm`` [cm] before the passage opens. A rover nearer the centre than this
        is within the approach."""
        return self.entry_cm + standoff_cm


def _width(grid: GridMap, p: Point, heading_deg: float) -> tuple[float, float] | None:
    """The free cross-section at ``p`` across ``heading_deg`` when narrower than
    ``PROBE_WIDTH_CM`` (left, right) [cm], else None."""
    sides = cross_section(grid, p[0], p[1], heading_deg, max_cm=PROBE_WIDTH_CM)
    if sides is None or min(sides) == 0.0:  # none, or ``p`` is in a wall
        return None
    return sides if sum(sides) < PROBE_WIDTH_CM else None


@dataclass(frozen=True, slots=True)
class RoutePassage:
    """A passage on a route: the passage, and where on the route it lies."""

    passage: Passage
    """The passage."""
    first_leg: int
    """The leg (from 0: the rover's position to the first waypoint) it begins on."""
    last_leg: int
    """The leg it ends on."""
    along_cm: float
    """How far along the route its narrowest section lies [cm]."""
    slant_deg: float
    """The route's heading there, less the axis [deg]."""


def passage_on_route(grid: GridMap, legs: list[Point]) -> RoutePassage | None:
    """The first narrow passage the route ``legs`` (the rover's position, then the
    waypoints) crosses and leaves again, or None.

    The route is sampled every cell; a passage that reaches either end of the route
    (it starts or ends in one) is not one this approach can square up to.
    """
    step = grid.resolution_cm
    samples: list[tuple[Point, float, int, float]] = []  # (point, heading, leg, along)
    along = 0.0
    for k, (a, b) in enumerate(zip(legs, legs[1:], strict=False)):
        leg = math.dist(a, b)
        if leg <= 0.0:
            continue
        heading = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        for t in np.arange(0.0, leg, step):
            t = float(t)
            samples.append(((a[0] + (b[0] - a[0]) * t / leg, a[1] + (b[1] - a[1]) * t / leg),
                            heading, k, along + t))
        along += leg
    narrow = [_width(grid, q, h) for q, h, _, _ in samples]
    first = next((k for k, w in enumerate(narrow) if w is not None), None)
    if first is None or first == 0:
        return None
    last = first
    while last + 1 < len(narrow) and narrow[last + 1] is not None:
        last += 1
    if last == len(narrow) - 1:
        return None
    k = min(range(first, last + 1), key=lambda i: sum(narrow[i]))  # type: ignore[arg-type]
    p, heading, _, at = samples[k]
    widths = {turn: sides for turn in range(-AXIS_SWEEP_DEG, AXIS_SWEEP_DEG + 1)
              if (sides := _width(grid, p, heading + turn)) is not None}
    if not widths:
        return None
    least = min(sum(sides) for sides in widths.values())
    # the width varies as 1/cos near the axis, flat within the sampling: the axis is the
    # middle of the directions that give the least
    turns = [turn for turn, sides in widths.items() if sum(sides) == least]
    axis = heading + 0.5 * (min(turns) + max(turns))
    best = _width(grid, p, axis)
    if best is None:
        return None
    left, right = best
    h = math.radians(axis)
    off = 0.5 * (left - right)  # the middle, left of p positive
    centre = (p[0] - math.sin(h) * off, p[1] + math.cos(h) * off)
    ends = []
    for sign in (-1.0, 1.0):
        d = step
        while d <= along and _width(grid, (centre[0] + sign * d * math.cos(h),
                                           centre[1] + sign * d * math.sin(h)),
                                    axis) is not None:
            d += step
        if d > along:
            return None
        ends.append(d)
    passage = Passage(centre, axis, left + right, ends[0], ends[1])
    return RoutePassage(passage, samples[first][2], samples[last][2], at,
                        angle_diff_deg(heading, axis))


def lateral_spread95_cm(covariance: np.ndarray, axis_deg: float, ahead_cm: float = 0.0
                        ) -> float:
    """The belief's 95 % spread across ``axis_deg`` (either side) [cm], now or after
    driving ``ahead_cm`` [cm] along the axis: the heading's doubt (and its correlation
    with the position's) carries the rover sideways by ``ahead_cm`` times its error.

    Args:
        covariance: the belief's covariance of (x [cm], y [cm], heading [rad]).
        axis_deg: the passage's axis [deg].
        ahead_cm: the distance still to drive to the passage [cm].
    """
    h = math.radians(axis_deg)
    g = np.array([-math.sin(h), math.cos(h), ahead_cm])  # d(lateral)/d(x, y, heading)
    return Z_95 * math.sqrt(max(float(g @ covariance @ g), 0.0))


def body_span_cm(body_cm: tuple[float, float], slant_deg: float) -> float:
    """How wide a body (length, width) [cm] turned ``slant_deg`` [deg] from a passage's
    axis is across it [cm]."""
    a = math.radians(min(abs(slant_deg), 90.0))
    return body_cm[1] * math.cos(a) + body_cm[0] * math.sin(a)


def misses(passage: Passage, lateral95_cm: float, span_cm: float) -> bool:
    """A body spanning ``span_cm`` across the passage, whose place across it is known to
    ``lateral95_cm`` (95 %, either side), may touch its walls: the doubt is more than
    half the play the passage leaves it [cm]."""
    return lateral95_cm > 0.5 * (passage.width_cm - span_cm)


def square_to_axis(grid: GridMap, start: Point, pts: list[Point], *, covariance: np.ndarray,
                   body_cm: tuple[float, float], turn_radius_cm: float) -> list[Point]:
    """``pts`` (the route's waypoints from ``start``, the goal last) with its first
    narrow passage driven along its axis when the route crosses it at a slant that
    makes the body miss (`misses`, with `body_span_cm` at the slant).

    The waypoints within the passage are replaced by: the point on the axis a turning
    radius and a cell before the passage opens (`approach_point`), then the point as
    far beyond it. Left as it is when no passage is on the route, the route is square
    to it already or the body fits at its slant, the legs round it start or end within
    the approach, or the new legs would cross the map's walls for a body of half the
    width (the route's own narrowest tier).

    Args:
        grid: the map the route was planned on.
        start: the rover's position [cm].
        pts: the route's waypoints [cm].
        covariance: the belief's covariance of (x, y, heading) [cm^2, rad^2].
        body_cm: the body (length, width) [cm].
        turn_radius_cm: the radius the body sweeps turning in place [cm].
    """
    legs = [start, *pts]
    found = passage_on_route(grid, legs)
    if found is None:
        return pts
    passage = found.passage
    lateral = lateral_spread95_cm(covariance, passage.axis_deg)
    if abs(found.slant_deg) < 1.0 or \
            not misses(passage, lateral, body_span_cm(body_cm, found.slant_deg)):
        return pts
    standoff = turn_radius_cm + grid.resolution_cm
    before = approach_point(passage, standoff)
    beyond_t = passage.exit_cm + standoff
    beyond = passage.along(beyond_t)
    a, b = legs[found.first_leg], legs[found.last_leg + 1]
    if passage.axial(a) > -passage.approach_cm(standoff) or passage.axial(b) < beyond_t:
        return pts
    ok = traversable(grid, 0.5 * body_cm[1], 0.0, "blocked")
    if not all(_clear_line(grid, ok, p, q) for p, q in ((a, before), (before, beyond),
                                                         (beyond, b))):
        return pts
    return [*pts[:found.first_leg], before, beyond, *pts[found.last_leg:]]


def approach_point(passage: Passage, standoff_cm: float) -> Point:
    """The point on the axis ``standoff_cm`` [cm] before the passage opens."""
    return passage.along(-passage.approach_cm(standoff_cm))


def _clear_line(grid: GridMap, ok: np.ndarray, a: Point, b: Point) -> bool:
    """The segment ``a`` -> ``b`` [cm] crosses only cells of ``grid`` where ``ok``
    (`planning.planner.traversable`) lets the rover's centre be
    (`planning.planner.line_of_sight`, in cells)."""
    ox, oy = grid.origin_cm
    res = grid.resolution_cm

    def cell(p: Point) -> tuple[float, float]:
        return (p[1] - oy) / res - 0.5, (p[0] - ox) / res - 0.5

    return line_of_sight(ok, cell(a), cell(b))


@dataclass(frozen=True, slots=True)
class Touch:
    """Where to touch a face across a passage's axis, and how."""

    stand: Point
    """Where the rover stands to touch, a turning radius and a cell off the face [cm]."""
    heading_deg: float
    """Facing the face [deg]."""
    gap_cm: float
    """From the nose at ``stand`` to the face [cm]."""


def face_across(grid: GridMap, passage: Passage, *, body_cm: tuple[float, float],
                turn_radius_cm: float, reach_cm: float, ok: np.ndarray) -> Touch | None:
    """The nearer face square to the passage's lateral direction, within ``reach_cm``
    [cm] of the approach point along it, flat across the body's width (the map's
    first occupied cell along the lateral line from the approach point and from points
    half the body's width before and beyond it agree within a cell), with a stand
    point before it; None when neither side has one.

    The stand point lies on that line a turning radius and a cell off the face, or
    nearer the approach point by half cells until ``ok`` (`planning.planner.traversable`
    for the turning radius) lets the rover turn there.
    """
    standoff = turn_radius_cm + grid.resolution_cm
    s = approach_point(passage, standoff)
    ux, uy = passage.unit
    half = 0.5 * body_cm[1]
    best: tuple[float, float, Point] | None = None  # (distance, side, stand)
    for side in (1.0, -1.0):
        direction = passage.axis_deg + side * 90.0
        hits = [first_occupied(grid, s[0] + k * half * ux, s[1] + k * half * uy, direction,
                               max_cm=reach_cm, step_cm=1.0) for k in (0.0, -1.0, 1.0)]
        if any(h is None for h in hits):
            continue
        if max(hits) - min(hits) > grid.resolution_cm:  # type: ignore[operator]
            continue
        d = float(hits[0])  # type: ignore[arg-type]
        if best is not None and d >= best[0]:
            continue
        h = math.radians(direction)
        t = d - standoff
        while t > 0.0:
            stand = (s[0] + t * math.cos(h), s[1] + t * math.sin(h))
            r, c = grid.world_to_cell(*stand)
            if grid.contains(r, c) and ok[r, c]:
                best = (d, side, stand)
                break
            t -= 0.5 * grid.resolution_cm
    if best is None:
        return None
    d, side, stand = best
    gap = d - math.dist(stand, s) - 0.5 * body_cm[0]
    return Touch(stand, passage.axis_deg + side * 90.0, gap)
