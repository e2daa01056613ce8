"""Before a narrow passage the rover may miss: touch a face across its axis first.

Why
    The hider and the seeker reach a gap with their lateral doubt grown by every
    metre driven since their last contact (a degree of heading doubt is 3.5 cm
    over 2 m). The faces round a gap's mouth are square to its axis: a contact with
    one says how far the rover is from the wall, not where along it, so the
    rover cannot learn its lateral place at the mouth except by finding the gap
    (`nudge`'s probe series: blocks, each a back-off and a sidestep, split beliefs
    either side of the mouth). A face square to the lateral direction can tell
    it: the wall the gap's wall meets, or a box's side. Touched head-on, the
    contact model (`localisation.contact_model`) puts the rover's lateral place
    within a centimetre or two; driven back along the gap's wall to the
    approach point, the doubt grows only by the counts' error along the way, not
    by the heading's.

What it does
    When the route's first narrow passage (`passage_approach.passage_on_route`)
    would be missed on its axis (`passage_approach.misses`: the lateral 95 %
    spread expected at the approach point, the heading's doubt carried over the
    distance still to drive, is more than half the play), and a flat face lies
    across the axis in the map (`passage_approach.face_across`), the route goes
    to a stand point a turning radius and a cell off that face, facing it
    (`detour`). There the rover
    drives into the face (`touch_motion`: the nose's gap to the mapped face, a
    cell for a face mapped in front of the wall, and the lateral doubt); the
    move ends blocked, the contact update weighs the belief, the rover backs off
    and the route is planned again from the corrected pose. One touch per
    passage: a touch that taught nothing (the face not met, or something
    unmapped in the way) is not tried again, and the probe series is left to the
    mouth. Once the rover is through the passage (`passed`), the route is planned
    again, so the next passage on it gets its own check.

The navigation actor (`route_nav.RouteNav`) owns one and calls it when it plans
(`detour`), when the route to the stand point ends (`touch_motion`), when the
touch ends (`take_touch`) and at every step (`passed`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from actors.firmware.nav.passage_approach import (
    Passage,
    Touch,
    face_across,
    lateral_spread95_cm,
    misses,
    passage_on_route,
)
from actors.firmware.nav.route import Motion
from actors.firmware.planning.planner import traversable

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["LateralTouch"]

Point = tuple[float, float]


class LateralTouch:
    """One route's touch of a face across a passage (see the module docstring).

    Args:
        nav: the navigation actor whose map, pose belief and options it reads.
    """

    def __init__(self, nav: RouteNav) -> None:
        self.nav = nav
        self.touch: Touch | None = None
        """The touch the route is driving to (None: none)."""
        self.tried = False
        """This route has had its touch for the passage ahead."""
        self.passage: Passage | None = None
        """The passage the touch was for, until the rover is through it."""
        self._in_flight = False  # the move into the face is the motion in flight

    def new_route(self) -> None:
        """A new route: it may touch before its first passage."""
        self.touch, self.tried, self.passage, self._in_flight = None, False, None, False

    def passed(self) -> bool:
        """The rover is through the passage it touched for, a turning radius and a cell
        beyond it: the route may touch again before the next passage (True once, then
        the route is planned again)."""
        nav, passage = self.nav, self.passage
        if passage is None or nav.map is None:
            return False
        p = nav.map_pose
        if passage.axial((p.x, p.y)) < passage.exit_cm + nav.radius_cm + nav.map.resolution_cm:
            return False
        self.passage, self.tried = None, False
        return True

    def detour(self, pts: list[Point]) -> Touch | None:
        """The touch to make before the route ``pts`` (waypoints from the rover's
        map-frame position, the goal last) reaches its first narrow passage, or None.

        None when the route has touched already, a sideways search is on, the belief
        or the map is missing, no leg crosses a passage, the rover is within the
        approach already, the doubt expected at the approach point is within the play,
        or no flat face lies across the axis in the map with a stand point before it
        that the rover can turn on.
        """
        nav = self.nav
        spread = nav.spread
        if self.tried or nav.nudges.nudge is not None or spread is None or nav.map is None:
            return None
        grid = nav.map
        p = nav.map_pose
        found = passage_on_route(grid, [(p.x, p.y), *pts])
        if found is None:
            return None
        passage = found.passage
        standoff = nav.radius_cm + grid.resolution_cm
        if passage.axial((p.x, p.y)) >= -passage.approach_cm(standoff):
            return None  # the rover is within the approach
        ahead = max(found.along_cm - passage.approach_cm(standoff), 0.0)
        lateral = lateral_spread95_cm(spread.covariance, passage.axis_deg, ahead)
        if not misses(passage, lateral, nav.width_cm):
            return None
        work = nav.work_map or grid
        touch = face_across(grid, passage, body_cm=(nav.length_cm, nav.width_cm),
                            turn_radius_cm=nav.radius_cm,
                            reach_cm=math.hypot(*grid.shape) * grid.resolution_cm,
                            ok=traversable(work, nav.radius_cm, 0.0, "blocked"))
        if touch is None:
            return None
        self.touch, self.tried, self.passage = touch, True, passage
        return touch

    def touch_motion(self) -> Motion | None:
        """At the stand point facing the face: the move into it, or None when no touch
        is planned. The move reaches the mapped face's cell beyond the nose's gap, and
        the lateral doubt beyond that (the face may be that much farther)."""
        touch, self.touch = self.touch, None
        if touch is None or self.nav.map is None:
            return None
        spread = self.nav.spread
        lateral = 0.0 if spread is None else \
            lateral_spread95_cm(spread.covariance, touch.heading_deg - 90.0)
        self._in_flight = True
        self.nav.counters["touches"] = self.nav.counters.get("touches", 0) + 1
        return Motion("move", touch.gap_cm + self.nav.map.resolution_cm + lateral)

    def take_touch(self) -> bool:
        """The motion that ended was the move into the face (asked once per motion)."""
        was, self._in_flight = self._in_flight, False
        return was
