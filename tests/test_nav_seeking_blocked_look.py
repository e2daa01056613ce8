"""Seeking navigation: a look whose turn is blocked by something the map does not show.

The fake hider is a disc the map leaves out; the fake motor stops a turn where the
seeker's body (20 x 15 cm) would touch it, as the world stops a turn against a body.
"""

from __future__ import annotations

import math

import pytest

from actors import BufferPool, open_actor_system
from server.protocol.pose import Pose, angle_diff_deg
from tests.test_nav_common import Body, Truth, room_map, rover_spec, send_route, wait_for

ORIGIN = {"x": 50.0, "y": 50.0, "heading": 0.0}  # the map frame is the own frame + (50, 50)
TRUTH_MAP = Truth(0, 0, 300, 200)
HALF_LENGTH, HALF_WIDTH = 10.0, 7.5
HIDER_R = 8.0  # the hider's body as a disc [cm]


def gap_to(pose: Pose, hider: tuple[float, float]) -> float:
    """Distance from the seeker's rectangular body to the hider disc's edge [cm]."""
    dx, dy = hider[0] - pose.x, hider[1] - pose.y
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    along, across = abs(dx * c + dy * s), abs(-dx * s + dy * c)
    return math.hypot(max(along - HALF_LENGTH, 0.0), max(across - HALF_WIDTH, 0.0)) - HIDER_R


def turn_stopped_by(hider: tuple[float, float]):
    """A turn script: the turn ends blocked at the last degree that keeps the body clear."""
    def script(pose: Pose, deg: float) -> float | None:
        step = math.copysign(1.0, deg)
        done = 0.0
        while abs(done) < abs(deg):
            nxt = done + step if abs(done + step) <= abs(deg) else deg
            if gap_to(Pose(pose.x, pose.y, pose.heading_deg + nxt), hider) < 0.0:
                return done
            done = nxt
        return None
    return script


def ir_sees(hider: tuple[float, float]):
    """IR model: the hider's centre within 60 cm of the nose and +-20 deg of the heading."""
    def sees(pose: Pose) -> bool:
        nose = (pose.x + HALF_LENGTH * math.cos(pose.heading_rad),
                pose.y + HALF_LENGTH * math.sin(pose.heading_rad))
        bearing = math.degrees(math.atan2(hider[1] - nose[1], hider[0] - nose[0]))
        return math.dist(nose, hider) <= 60.0 and \
            abs(angle_diff_deg(bearing, pose.heading_deg)) <= 20.0
    return sees


async def _look_beside(hider: tuple[float, float], *, always_blocked: bool = False) -> Body:
    """The seeker stands facing north in open floor with the hider 2 cm off its right side
    and is asked to look at the hider's place (within reach: it looks from where it is)."""
    body = Body(pose=Pose(100.0, 50.0, 90.0), truth=Truth(-50, -50, 250, 150),
                ir_in_range=ir_sees(hider),
                turn_script=(lambda _p, _d: 0.0) if always_blocked else turn_stopped_by(hider))
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        place = {"x": hider[0] + 50.0, "y": hider[1] + 50.0, "heading": None}
        await send_route(system, pool, "seeker", ORIGIN, place, room_map(TRUTH_MAP))
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 600.0)
    return body


@pytest.mark.trio
async def test_a_look_blocked_beside_an_unmapped_body_backs_off_and_looks_again(
        autojump_clock) -> None:
    """The turn to face the hider is stopped by its body: the seeker reverses its turning
    circle's diameter (25 cm) and, from there, faces the hider and reports ``found``."""
    hider = (117.0, 50.0)  # own frame: 17 cm right of the seeker's centre
    body = await _look_beside(hider)
    assert body.frames("not_found") == []
    assert body.frames("found")
    moves = [v for c, v in body.motor_log if c == "MOTOR_MOVE"]
    assert moves and moves[0] == pytest.approx(-25.0, abs=0.1)  # the back-off, first move
    f = body.frames("found")[0].data
    assert math.dist((f["x"] - 50.0, f["y"] - 50.0), (100.0, 50.0)) == pytest.approx(25.0,
                                                                                  abs=2.0)
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    assert any(d.startswith("blocked turning to look") for d in details)


@pytest.mark.trio
async def test_a_look_backs_off_once_per_look_point(autojump_clock) -> None:
    """Every turn blocked (a body it cannot get clear of): one back-off at a look point,
    then the look goes on from there to an answer instead of backing off again."""
    hider = (117.0, 50.0)
    body = await _look_beside(hider, always_blocked=True)
    assert body.frames("found") or body.frames("not_found")
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    backoffs = [i for i, d in enumerate(details) if d.startswith("blocked turning to look")]
    assert backoffs
    # between two back-offs the seeker drove to a new look point
    for a, b in zip(backoffs, backoffs[1:], strict=False):
        assert any(not d.startswith(("looking", "blocked")) for d in details[a + 1:b]), \
            details[a:b + 1]
