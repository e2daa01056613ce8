"""The geometry of the sideways search for a narrow passage: where a nudged route goes,
the series of offsets tried round a block, and whether a block is in a passage.

A route blocked where the map shows a way through was most likely missed by the
rover's own dead-reckoning error (a gap ~20 cm wider than the body is missed by a
heading drift of a few degrees over a few metres). The search shifts the route near
the block sideways, across the heading of the block, by a series of offsets (+s, -s,
+2s, -2s, ...), one per block. At a passage's mouth (`at_mouth`) the series is a probe
(`probe_route`): a line drawn from the block itself, stepped by the passage's play
(`probe_step`). `nudge_series.NudgeSeries` keeps the series' state and calls these
functions; they are pure (no actor, no messages, no clock).

Frame and units: the map frame [cm]; headings [deg] counter-clockwise from +x; a
block is where a move ended blocked, ``(x, y, heading)``; an offset is signed, left
of the block's heading positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from actors.firmware.nav.route import passable_at
from actors.firmware.planning.clearance import passage_width
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose

__all__ = ["Block", "Nudge", "NUDGE_STEP_MAX_CM", "MAX_NUDGES", "NUDGE_REACH_CM",
           "PROBE_WIDTH_CM", "nudge_step", "series_offset",
           "on_free_ground", "nudged_route", "probe_route", "with_sidestep", "progress",
           "near_block", "in_passage", "at_mouth", "probe_step", "through_distance"]

Block = tuple[float, float, float]
"""Where a move ended blocked: (x [cm], y [cm], heading [deg]), map frame."""

# The search's geometry follows from the game's passages (a 35 cm gap) and the body
# (20 x 15 cm).
NUDGE_STEP_MAX_CM = 12.0
"""Largest lateral step of the search for a narrow passage [cm]: below the free width a
35 cm gap leaves a 15 cm wide body (20 cm), so the offsets tried leave no hole between
them; a seeker can reach a gap 21-36 cm off, beyond the +-24 cm six steps of 8 reach."""
MAX_NUDGES = 6
"""Sideways offsets tried per route, at most."""
NUDGE_REACH_CM = 50.0
"""Waypoints this close to the block point are shifted by a nudge [cm]."""
PROBE_WIDTH_CM = 40.0
"""A block where the map's passage across the heading is narrower than this probes
sideways at once (`in_passage`), the nudged route beginning with a sidestep across the
heading of the block (`with_sidestep`) [cm]."""


@dataclass(frozen=True, slots=True)
class Nudge:
    """One offset of a series: the route near ``block`` shifted ``off`` sideways."""

    block: Block
    """The series' first block (its anchor): the shift is across its heading."""
    off: float
    """The signed offset [cm], left of the block's heading positive."""
    probe: bool = False
    """A probe of a narrow passage (`probe_route`): the shifted line is drawn from the
    block itself, not from the route's waypoints."""

    @property
    def shift(self) -> tuple[float, float]:
        """The offset as a map-frame vector (dx, dy) [cm]."""
        h = math.radians(self.block[2])
        return -math.sin(h) * self.off, math.cos(h) * self.off


def nudge_step(step_cm: float, drift_cm: float) -> float:
    """The series' step [cm]: ``step_cm``, or a third of the pose's doubt ``drift_cm``
    [cm] when that is more (a long drive searches wider), at most ``NUDGE_STEP_MAX_CM``."""
    return min(NUDGE_STEP_MAX_CM, max(step_cm, drift_cm / 3.0))


def series_offset(k: int, step_cm: float, first: float) -> float:
    """Offset ``k`` (from 0) of a series [cm]: +1, -1, +2, -2, +3, -3 steps of ``step_cm``,
    the first on side ``first`` (+1.0 left, -1.0 right)."""
    return step_cm * (k // 2 + 1) * (first if k % 2 == 0 else -first)


def on_free_ground(grid: GridMap | None, x: float, y: float) -> bool:
    """(x, y) [cm] is on free ground of ``grid`` (False without a map). Not more: the
    offset must also make up for a heading error the rover cannot see, so the point
    may lie closer to a wall than the body could stand."""
    return grid is not None and passable_at(grid, x, y, 0.0, 0.0)


def nudged_route(pts: list[tuple[float, float]], nudge: Nudge, grid: GridMap | None, *,
                 drift_cm: float, sidestep_from: tuple[float, float] | None = None,
                 tol_cm: float = 0.0) -> list[tuple[float, float]] | None:
    """The route ``pts`` (waypoints [cm], the goal last) with ``nudge`` applied.

    Waypoints within ``NUDGE_REACH_CM`` of the block, the goal excepted, are shifted
    sideways; when none is near (a long corridor), a shifted point ``NUDGE_REACH_CM``
    ahead of the block is driven to first. A shift of at most ``drift_cm`` [cm] (the
    pose's doubt) may put a point in a mapped wall: dead reckoning is that far off,
    so the wall may well be where the rover can pass; a wider one must keep its
    points on free ground of ``grid``. With ``sidestep_from`` (the rover's position),
    a shifted route begins with a sidestep to the shifted line (`with_sidestep`).

    Returns:
        The new route; ``pts`` itself when the goal is within reach of the block or
        ahead of the block leads away from it; None when a shifted point that must
        be on free ground is not (the search went wider than the passage).
    """
    dx, dy = nudge.shift
    cx, cy, heading = nudge.block
    reach = NUDGE_REACH_CM
    near = [i < len(pts) - 1 and math.dist(q, (cx, cy)) <= reach for i, q in enumerate(pts)]
    free = math.hypot(dx, dy) <= drift_cm
    if any(near):
        out = [(x + dx, y + dy) if n else (x, y) for (x, y), n in zip(pts, near, strict=True)]
        if not (free or all(on_free_ground(grid, *q) for q, n in zip(out, near, strict=True)
                            if n)):
            return None
    else:
        h = math.radians(heading)
        ahead = (cx + reach * math.cos(h) + dx, cy + reach * math.sin(h) + dy)
        to_goal = math.dist((cx, cy), pts[-1])
        if to_goal <= reach or math.dist(ahead, pts[-1]) >= to_goal:
            return pts  # the goal is near, or ahead of the block leads away from it
        if not (free or on_free_ground(grid, *ahead)):
            return None
        out = [ahead, *pts]
    if sidestep_from is None:
        return out
    return with_sidestep(out, nudge, sidestep_from, grid, tol_cm=tol_cm)


def probe_route(pts: list[tuple[float, float]], nudge: Nudge, grid: GridMap | None, *,
                drift_cm: float, at: tuple[float, float], through_cm: float,
                tol_cm: float = 0.0) -> list[tuple[float, float]] | None:
    """The route ``pts`` (waypoints [cm], the goal last) entered through a narrow
    passage on the line ``nudge.off`` beside the block, from a sidestep where the
    rover stands (``at``).

    The line is drawn from the block alone: a sidestep onto it, then the point
    ``through_cm`` beyond the block along its heading (the body through the mouth its
    nose met), then the route's waypoints beyond that point. Why not the route's
    own waypoints shifted (`nudged_route`): they lie where the map puts the passage,
    seen from the pose belief; a contact that moves the belief between explanations
    (one wall's end or the other's) would move every probe with it, and the probes
    would search where the belief jumped to, not round the place the rover met the
    wall. Drawn from the block, and the block held where the rover was (its own
    frame), the probes are a fixed pattern round that place.

    Returns:
        The new route; ``pts`` itself when the rover is already past the mouth or
        the goal lies before it; None when the point through the mouth is off free
        ground of ``grid`` and the offset exceeds ``drift_cm`` [cm] (a wider search
        than the pose's doubt must stay on free ground).
    """
    bx, by, bh = nudge.block
    h = math.radians(bh)
    ux, uy = math.cos(h), math.sin(h)
    dx, dy = nudge.shift
    if progress(nudge.block, *at) >= through_cm or progress(nudge.block, *pts[-1]) <= through_cm:
        return pts
    through = (bx + through_cm * ux + dx, by + through_cm * uy + dy)
    if abs(nudge.off) > drift_cm and not on_free_ground(grid, *through):
        return None
    rest = [q for i, q in enumerate(pts)
            if i == len(pts) - 1 or progress(nudge.block, *q) > through_cm]
    return with_sidestep([through, *rest], nudge, at, grid, tol_cm=tol_cm)


def with_sidestep(pts: list[tuple[float, float]], nudge: Nudge, at: tuple[float, float],
                  grid: GridMap | None, *, tol_cm: float) -> list[tuple[float, float]]:
    """``pts`` (a nudged route) preceded by a sidestep: the point beside the rover
    (at ``at`` [cm]) on the shifted line, across the heading of the block.

    Why: driven straight from where the back-off left it, the nudged route meets
    the passage's mouth at an angle; with a heading error of 7 deg the nose then
    hits the face before the body has moved across, or the body slides along the
    face, which the encoders do not see (from 26 to 60 cm off within a few
    probes). A sidestep moves the rover across first, square to the heading of
    the block, so the shifted line is joined where the rover stands and the mouth
    is met head-on. Not when the rover is already on the line (within ``tol_cm``)
    or the point is off free ground of ``grid``.
    """
    bx, by, bh = nudge.block
    h = math.radians(bh)
    nx, ny = -math.sin(h), math.cos(h)
    lateral = (at[0] - bx) * nx + (at[1] - by) * ny
    move = nudge.off - lateral
    side = (at[0] + move * nx, at[1] + move * ny)
    if abs(move) <= tol_cm or not on_free_ground(grid, *side):
        return pts
    return [side, *pts]


def progress(block: Block, x: float, y: float) -> float:
    """How far (x, y) [cm] lies beyond ``block`` along the block's heading [cm].

    Along, not straight-line: a nudge moves the block point across the heading by
    its own offset (up to 3 x ``NUDGE_STEP_MAX_CM``), and a contact fix moves it a
    few cm more; counted as progress, that would restart the series around the
    nudged point, 25 cm to the wrong side, and the offset that would pass would
    never be tried."""
    bx, by, bh = block
    h = math.radians(bh)
    return (x - bx) * math.cos(h) + (y - by) * math.sin(h)


def near_block(block: Block, x: float, y: float) -> bool:
    """(x, y) [cm] is within ``NUDGE_REACH_CM`` of ``block``: a block there, while a
    series runs, is the nudged route meeting a wall again at the passage it looks for.

    Why: blocked short of the mouth by dead reckoning (the nose a few cm before it,
    or on the face beside it), the block would be taken for an obstacle the map
    does not show; learned inside a mapped wall it changes nothing, and the same
    offset would be driven again and again. The next offset is the search's next
    step."""
    return math.dist((x, y), block[:2]) <= NUDGE_REACH_CM


def in_passage(grid: GridMap, pose: Pose, nose_cm: float) -> bool:
    """The map's walls are close on both sides of ``pose`` (narrower than
    ``PROBE_WIDTH_CM`` across its heading), at the body's centre or at its nose
    ``nose_cm`` [cm] ahead: a rover stopped at a gap's mouth has only its nose in
    the gap."""
    return any(_narrow_ahead(grid, pose, a) is not None for a in (0.0, nose_cm))


def _narrow(grid: GridMap, x: float, y: float, heading_deg: float) -> float | None:
    """The map's free width across ``heading_deg`` at (x, y) [cm] when under
    ``PROBE_WIDTH_CM``, else None."""
    w = passage_width(grid, x, y, heading_deg, max_cm=PROBE_WIDTH_CM)
    return w if w is not None and w < PROBE_WIDTH_CM else None


def _narrow_ahead(grid: GridMap, pose: Pose, ahead_cm: float) -> float | None:
    """`_narrow` at the point ``ahead_cm`` [cm] ahead of ``pose``, across its heading."""
    h = math.radians(pose.heading_deg)
    return _narrow(grid, pose.x + ahead_cm * math.cos(h), pose.y + ahead_cm * math.sin(h),
                   pose.heading_deg)


def at_mouth(grid: GridMap, pose: Pose, nose_cm: float) -> bool:
    """A narrow passage begins ahead of ``pose``: the map's walls are narrower than
    ``PROBE_WIDTH_CM`` across its heading at its nose (``nose_cm`` [cm] ahead) or a cell
    beyond, not at the body's centre. A rover blocked there met the face beside the
    mouth; one blocked with its centre in the passage scraped a side wall inside."""
    if _narrow_ahead(grid, pose, 0.0) is not None:
        return False
    return any(_narrow_ahead(grid, pose, a) is not None
               for a in (nose_cm, nose_cm + grid.resolution_cm))


def probe_step(grid: GridMap, pose: Pose, length_cm: float, width_cm: float, *,
               heading_doubt_deg: float, floor_cm: float) -> float | None:
    """The step of a probe series at a narrow passage [cm]: the passage's play for a body
    (``length_cm`` x ``width_cm``) whose heading may be off by ``heading_doubt_deg``,
    between ``floor_cm`` and ``NUDGE_STEP_MAX_CM``; None when no passage is there.

    The passage's width is the map's free width across ``pose``'s heading at the body's
    centre, its nose, or a cell beyond the nose (a rover blocked at a mouth has its nose
    on the face beside it), the narrowest under ``PROBE_WIDTH_CM``, plus one cell: a
    LIDAR hit on a face lands in the cell on the free side, so each mapped face lies up
    to a cell (half a cell on average) in front of the wall. A body turned by ``a`` from
    the passage's direction spans ``width cos a + length sin a`` across it; the play is
    what the width leaves of that.

    Why the play: the lateral places from which the body passes form a band as wide
    as the play; probes that step by no more than it cannot jump over the band, and
    probes that step by less spend blocks on places a step before already ruled out.
    """
    nose = 0.5 * length_cm
    widths = [w for a in (0.0, nose, nose + grid.resolution_cm)
              if (w := _narrow_ahead(grid, pose, a)) is not None]
    if not widths:
        return None
    a = math.radians(min(abs(heading_doubt_deg), 90.0))
    span = width_cm * math.cos(a) + length_cm * math.sin(a)
    return min(NUDGE_STEP_MAX_CM, max(floor_cm, min(widths) + grid.resolution_cm - span))


def through_distance(grid: GridMap, nudge: Nudge, length_cm: float) -> float:
    """How far beyond ``nudge.block``, along its heading and on its shifted line, the
    body is through the passage it met [cm]: where the line's free width across the
    heading is no longer under ``PROBE_WIDTH_CM``, plus half the body's ``length_cm``;
    at least ``length_cm``, at most ``NUDGE_REACH_CM``.

    Why: a probe's route turns toward the rest of the route at this point; turned while
    its body is still between the mouth's walls, the rover scrapes them, and the turn
    the encoders count is not the one the body made.
    """
    bx, by, bh = nudge.block
    h = math.radians(bh)
    ux, uy = math.cos(h), math.sin(h)
    dx, dy = nudge.shift
    step = grid.resolution_cm
    d, seen = 0.0, False
    while d <= NUDGE_REACH_CM:
        narrow = _narrow(grid, bx + d * ux + dx, by + d * uy + dy, bh) is not None
        if seen and not narrow:
            break
        seen = seen or narrow
        d += step
    return min(NUDGE_REACH_CM, max(length_cm, d + 0.5 * length_cm))
