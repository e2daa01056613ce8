"""Before a narrow passage the rover may miss: the passage's geometry on a route, the
lateral doubt expected at it, the face across it, and the hider that touches that face
before it drives through (`nav.passage_approach`, `nav.lateral_touch`).

The pure parts are checked on a mapped room; the behaviour drives the real navigation
actor among the fakes of `tests.test_nav_common` and reads what it sends.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors import BufferPool, open_actor_system
from actors.firmware.localisation.gaussian_pose import Z_95
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.passage_approach import (
    body_span_cm,
    face_across,
    lateral_spread95_cm,
    misses,
    passage_on_route,
    square_to_axis,
)
from actors.firmware.planning.planner import traversable
from tests.test_nav_common import Body, Truth, room_map, rover_spec, send_route, wait_for

# A room 500 x 300 cut by a wall 20 cm thick at x 250..270 with a gap at y 40..65 (25 cm,
# 5 cm from the body's width each side together); the room's bottom wall (y = 0) is a
# face across the gap's axis, 40 cm below it.
GAP_ROOM = Truth(0, 0, 500, 300, boxes=((250, 0, 20, 40), (250, 65, 20, 235)))
GAP_MAP = room_map(GAP_ROOM)
ORIGIN = {"x": 50.0, "y": 150.0, "heading": 0.0}
OWN_GAP_ROOM = Truth(-50, -150, 450, 150, boxes=((200, -150, 20, 40), (200, -85, 20, 235)))
"""The same room in the hider's own frame (shifted by ``ORIGIN``): the fake motor's."""
BODY = (20.0, 15.0)
TURN_RADIUS = 0.5 * math.hypot(*BODY)


def passage_on_leg(grid, a, b):  # noqa: ANN001, ANN201
    found = passage_on_route(grid, [a, b])
    return None if found is None else found.passage


def test_a_leg_through_a_gap_finds_its_centre_axis_width_and_ends() -> None:
    passage = passage_on_leg(GAP_MAP, (150.0, 100.0), (350.0, 14.0))
    assert passage is not None
    assert abs(passage.axis_deg) <= 3.0  # square to the wall, not along the slanted leg
    assert 250.0 <= passage.centre[0] <= 270.0 and 40.0 <= passage.centre[1] <= 65.0
    assert 15.0 <= passage.width_cm <= 30.0
    assert passage.entry_cm > 0.0 and passage.exit_cm > 0.0
    assert passage.entry_cm + passage.exit_cm <= 40.0


def test_a_route_that_ends_in_a_passage_or_crosses_none_has_no_passage() -> None:
    assert passage_on_leg(GAP_MAP, (100.0, 150.0), (200.0, 150.0)) is None  # open floor
    assert passage_on_leg(GAP_MAP, (100.0, 52.0), (260.0, 52.0)) is None  # ends inside


def test_a_passage_with_a_waypoint_inside_it_is_found_across_the_two_legs() -> None:
    found = passage_on_route(GAP_MAP, [(100.0, 100.0), (262.0, 52.0), (400.0, 52.0)])
    assert found is not None
    assert (found.first_leg, found.last_leg) == (0, 1)
    assert abs(found.passage.axis_deg) <= 3.0 and 250.0 <= found.passage.centre[0] <= 270.0
    assert found.along_cm > 150.0


def test_the_lateral_doubt_grows_with_the_heading_doubt_over_the_way_ahead() -> None:
    sigma_h = math.radians(2.0)
    cov = np.diag([4.0, 9.0, sigma_h ** 2])
    assert lateral_spread95_cm(cov, 0.0) == pytest.approx(Z_95 * 3.0)  # across x: y's doubt
    assert lateral_spread95_cm(cov, 90.0) == pytest.approx(Z_95 * 2.0)
    ahead = lateral_spread95_cm(cov, 0.0, ahead_cm=200.0)
    assert ahead == pytest.approx(Z_95 * math.sqrt(9.0 + (200.0 * sigma_h) ** 2))


def test_a_body_misses_a_passage_when_its_doubt_exceeds_half_the_play() -> None:
    passage = passage_on_leg(GAP_MAP, (100.0, 52.0), (400.0, 52.0))
    assert passage is not None
    play = passage.width_cm - BODY[1]
    assert not misses(passage, 0.4 * play, body_span_cm(BODY, 0.0))
    assert misses(passage, 0.6 * play, body_span_cm(BODY, 0.0))
    # turned 30 deg the body spans 23 cm: the same doubt that fits square misses slanted
    assert misses(passage, 0.4 * play, body_span_cm(BODY, 30.0))


def test_the_face_across_a_gap_is_the_nearer_flat_wall_with_a_stand_point_off_it() -> None:
    passage = passage_on_leg(GAP_MAP, (100.0, 52.0), (400.0, 52.0))
    assert passage is not None
    ok = traversable(GAP_MAP, TURN_RADIUS, 0.0, "blocked")
    touch = face_across(GAP_MAP, passage, body_cm=BODY, turn_radius_cm=TURN_RADIUS,
                        reach_cm=500.0, ok=ok)
    assert touch is not None
    assert touch.heading_deg == pytest.approx(-90.0, abs=3.0)  # the bottom wall, not the top
    assert touch.stand[0] < 250.0 - TURN_RADIUS  # before the wall's face
    assert TURN_RADIUS <= touch.stand[1] <= TURN_RADIUS + 10.0
    assert 0.0 < touch.gap_cm <= 10.0
    assert face_across(GAP_MAP, passage, body_cm=BODY, turn_radius_cm=TURN_RADIUS,
                       reach_cm=20.0, ok=ok) is None  # out of reach


def test_a_slanted_crossing_the_doubt_makes_tight_is_squared_to_the_axis() -> None:
    cov = np.diag([4.0, 4.0, 0.0])  # 3.9 cm either side: fits square, not at 23 deg
    start, goal = (150.0, 100.0), (350.0, 14.0)
    pts = square_to_axis(GAP_MAP, start, [goal], covariance=cov, body_cm=BODY,
                         turn_radius_cm=TURN_RADIUS)
    assert len(pts) == 3 and pts[-1] == goal
    (ax, ay), (bx, by) = pts[0], pts[1]
    assert ax < 250.0 < 270.0 < bx
    assert abs(ay - by) < 3.0 and 40.0 < ay < 65.0  # the two points lie on the axis
    square = square_to_axis(GAP_MAP, (100.0, 52.0), [(420.0, 52.0)], covariance=cov,
                            body_cm=BODY, turn_radius_cm=TURN_RADIUS)
    assert square == [(420.0, 52.0)]  # a leg on the axis is left alone


@pytest.mark.trio
async def test_a_hider_unsure_across_a_gap_touches_the_wall_across_it_then_drives_through(
        autojump_clock) -> None:
    """The hider sets out 3 m from a 25 cm gap with a degree of heading doubt: at the
    gap its lateral doubt would be more than the 5 cm of play. It drives first to the
    room's bottom wall beside the gap, faces it and drives into it (the move ends
    blocked: the contact), backs off, and then goes through the gap to its goal."""
    body = Body(truth=OWN_GAP_ROOM, radius=7.5)
    pool = BufferPool(64)
    origin = ORIGIN
    goal = {"x": 420.0, "y": 150.0, "heading": None}
    options = NavOptions(motion=MotionNoise(turn_sigma=0.05))
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=NavMemory(),
                                                 options=options), "hider")
        await send_route(system, pool, "hider", origin, goal, GAP_MAP)
        arrived = await wait_for(lambda: any(f.cmd == "arrived" for f in body.frames()),
                                 240.0)
    track = [(origin["x"] + p.x, origin["y"] + p.y, p.heading_deg)
             for _, p in body.published]
    touched = [k for k, (x, y, h) in enumerate(track)
               if y < 30.0 and x < 250.0 and abs(((h + 90.0) + 180.0) % 360.0 - 180.0) < 10.0]
    assert touched, "the hider never faced the bottom wall beside the gap"
    through = next(k for k, (x, _, _) in enumerate(track) if x > 270.0)
    assert touched[0] < through
    assert arrived
