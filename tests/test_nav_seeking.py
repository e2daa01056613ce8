"""Seeking navigation: standoff approach, IR confirmation with a scan, found / not_found."""

from __future__ import annotations

import math

import pytest
import trio

from actors import BufferPool, open_actor_system
from actors.firmware.drivers.ir import IR_PINNED
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.options import NavOptions
from actors.firmware.nav.route import passable_at
from actors.firmware.nav.search import ring_reach_cm, search_ring, search_rings
from actors.firmware.nav.seeker import IR_PINNED_WAIT_S, Seek, SeekingOptions
from server.protocol.pose import Pose, angle_diff_deg
from tests.test_nav_common import (
    Body,
    Truth,
    believe,
    net,
    room_map,
    rover_spec,
    send_route,
    wait_for,
)

ORIGIN = {"x": 50.0, "y": 50.0, "heading": 0.0}
TRUTH_MAP = Truth(0, 0, 300, 200)
HIDER = (250.0, 150.0)  # map frame


def ir_sees_hider(pose: Pose) -> bool:
    """IR model: hider within 60 cm of the nose and +-20 deg of the heading (own frame)."""
    hx, hy = HIDER[0] - 50.0, HIDER[1] - 50.0
    nose = (pose.x + 10 * math.cos(pose.heading_rad), pose.y + 10 * math.sin(pose.heading_rad))
    bearing = math.degrees(math.atan2(hy - nose[1], hx - nose[0]))
    return math.dist(nose, (hx, hy)) <= 60.0 and abs(angle_diff_deg(bearing,
                                                                     pose.heading_deg)) <= 20


async def begin(system, pool, dest) -> None:
    await send_route(system, pool, "seeker", ORIGIN, dest, room_map(TRUTH_MAP))


@pytest.mark.trio
async def test_seeker_stops_at_a_standoff_facing_the_place_and_finds(autojump_clock) -> None:
    """A guess at the hider: it stops 30-55 cm away, facing it, and reports ``found``."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": HIDER[0], "y": HIDER[1], "heading": None})
        assert await wait_for(lambda: body.frames("found"), 120.0)
        f = body.frames("found")[0].data
        assert 28.0 <= math.dist((f["x"], f["y"]), HIDER) <= 57.0
        bearing = math.degrees(math.atan2(HIDER[1] - f["y"], HIDER[0] - f["x"]))
        assert abs(angle_diff_deg(bearing, f["heading"])) <= 20.0
        assert body.frames("not_found") == []


@pytest.mark.trio
async def test_seeker_scans_then_reports_not_found_and_takes_the_next_guess(autojump_clock) -> None:
    """A wrong guess: scan turns, ``not_found``; the next guess at the hider is ``found``."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": 120.0, "y": 60.0, "heading": None})
        assert await wait_for(lambda: body.frames("not_found"), 120.0)
        turns_at_end = [c for c, _ in body.motor_log[-12:] if c == "MOTOR_TURN"]
        assert len(turns_at_end) >= 4  # the scan
        assert "IR" in body.frames("not_found")[0].data["reason"]
        await net(system, pool, "seeker", "destination", {"x": HIDER[0], "y": HIDER[1]})
        assert await wait_for(lambda: body.frames("found"), 120.0)


@pytest.mark.trio
async def test_seeker_without_ir_reports_not_found(autojump_clock) -> None:
    """No IR reading ever in range (stuck low): ``not_found`` (after the search round the
    place its belief's doubt asks for), never ``found``."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=lambda pose: False)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": HIDER[0], "y": HIDER[1]})
        assert await wait_for(lambda: body.frames("not_found"), 600.0)
        assert body.frames("found") == []


@pytest.mark.trio
async def test_a_pinned_ir_sensor_holds_the_look_until_it_reads_again(autojump_clock) -> None:
    """The sensor pinned at an ADC rail (``NAV_IR`` 2) for the first 25 s: the seeker neither
    reports a hider nor gives up on the guess; once it reads again it finds the hider."""
    body = Body(truth=Truth(-50, -50, 250, 150),
                ir_in_range=lambda pose: IR_PINNED if trio.current_time() < 25.0
                else ir_sees_hider(pose))
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": HIDER[0], "y": HIDER[1], "heading": None})
        assert await wait_for(lambda: body.frames("found"), 120.0)
        assert trio.current_time() > 25.0
        assert body.frames("not_found") == []


@pytest.mark.trio
async def test_an_ir_sensor_pinned_past_the_wait_is_reported_not_a_hider(autojump_clock) -> None:
    """Pinned for good: after `IR_PINNED_WAIT_S` of the look, ``not_found`` naming the sensor,
    never ``found`` (a stuck-high sensor reads like a hider everywhere)."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=lambda pose: IR_PINNED)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": HIDER[0], "y": HIDER[1], "heading": None})
        assert await wait_for(lambda: body.frames("not_found"), 120.0)
        assert "pinned" in body.frames("not_found")[0].data["reason"]
        assert trio.current_time() > IR_PINNED_WAIT_S
        assert body.frames("found") == []


@pytest.mark.trio
@pytest.mark.parametrize("guess", [(200.0, 120.0), (195.0, 150.0), (250.0, 95.0)],
                         ids=["behind-diagonal", "behind-left", "below"])
async def test_seeker_finds_a_hider_anywhere_within_ir_range_of_the_guess(autojump_clock,
                                                                           guess) -> None:
    """The hider 50-60 cm from the guess, on the far side from the seeker: the standoff
    scan misses it, the all-round scan from the guess itself finds it."""
    assert 50.0 <= math.dist(guess, HIDER) <= 60.0
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, {"x": guess[0], "y": guess[1]})
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 240.0)
        assert body.frames("not_found") == []
        f = body.frames("found")[0].data
        assert math.dist((f["x"], f["y"]), guess) <= 10.0  # found from the guess itself
        statuses = [fr.data.get("detail", "") for fr in body.frames("status")]
        assert "looking with the IR sensor all round" in statuses


# ============================================================================ the search ring


def test_ring_reach_and_the_cheapest_ring_that_sees_far_enough() -> None:
    """Six points on a 50 cm ring, each seeing 70 cm, see everything within ~109 cm of the
    centre; the ring chosen has the fewest points, then the smallest radius, that see as
    far as needed; none when the scan from the place sees far enough; the cap holds."""
    assert ring_reach_cm(50.0, 70.0, 6) == pytest.approx(25 * math.sqrt(3) + math.sqrt(4275))
    assert ring_reach_cm(80.0, 70.0, 6) == 0.0  # holes next to the points
    assert search_ring(65.0, 70.0, 6, 60.0) is None
    for need in (75.0, 90.0, 100.0, 110.0):
        n, r = search_ring(need, 70.0, 6, 60.0)
        assert ring_reach_cm(r, 70.0, n) >= need
        assert r == 20.0 or ring_reach_cm(r - 5.0, 70.0, n) < need  # the smallest radius
        assert all(ring_reach_cm(q, 70.0, n - 1) < need for q in range(20, 61, 5))
    assert search_ring(78.0, 70.0, 6, 60.0)[0] == 3
    assert search_ring(500.0, 70.0, 6, 60.0) == (6, 60.0)


def test_the_outward_scan_sweeps_plus_minus_100_deg() -> None:
    assert SeekingOptions().outward_deg() == tuple(float(a) for a in range(-100, 101, 20))


WIDE = NavOptions(motion=MotionNoise(turn_sigma=1.0))
"""A motion model that doubts every turn: the belief grows wide on the way."""
QUIET = NavOptions(motion=MotionNoise(encoder_sigma=0.005, turn_sigma=0.05))
"""A motion model that trusts the counts: the belief stays narrow on the way."""
FAR_GUESS = (160.0, 140.0)  # 90 cm from the hider: beyond what the scan from it sees


async def _seek_far_guess(options: NavOptions | None, seeking: SeekingOptions | None):
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool, options=options,
                                                 seeking=seeking), "seeker")
        await begin(system, pool, {"x": FAR_GUESS[0], "y": FAR_GUESS[1]})
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 600.0)
    return body


@pytest.mark.trio
async def test_a_large_drift_searches_a_ring_round_the_guess_and_finds(autojump_clock) -> None:
    """Dead reckoning believed far off (a belief whose turns scrub 5 times as much as the
    default motion model says): after the scan
    from the guess saw nothing, the seeker looks from a ring round it and finds the hider
    90 cm from the guess, from a point nearer the hider than the guess is."""
    assert math.dist(FAR_GUESS, HIDER) == pytest.approx(90.55, abs=0.01)
    body = await _seek_far_guess(WIDE, None)
    assert body.frames("not_found") == []
    f = body.frames("found")[0].data
    assert math.dist((f["x"], f["y"]), HIDER) < 80.0
    assert 20.0 <= math.dist((f["x"], f["y"]), FAR_GUESS) <= 65.0
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    assert "looking with the IR sensor all round" in details  # the guess itself first
    assert any(d.startswith("round the place, ring") for d in details)


@pytest.mark.trio
async def test_without_the_search_the_same_guess_is_not_found(autojump_clock,
                                                             monkeypatch) -> None:
    """The same game with the search off (no ring is ever planned): the hider is out of
    reach of the guess."""
    monkeypatch.setattr(Seek, "plan_search", lambda self: False)
    body = await _seek_far_guess(WIDE, None)
    assert body.frames("found") == []
    assert "IR" in body.frames("not_found")[0].data["reason"]


@pytest.mark.trio
async def test_a_small_drift_needs_no_search(autojump_clock) -> None:
    """A belief that stays narrow on the way (a motion model that trusts the counts: a
    95 % radius of a few cm) lets the scan from the guess cover every spot within IR
    range of it: ``not_found`` without a ring."""
    body = await _seek_far_guess(QUIET, None)
    assert body.frames("found") == []
    assert "ring" not in body.frames("not_found")[0].data["reason"]
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    assert not any(d.startswith("round the place") for d in details)


def searching_nav(place: tuple[float, float], driven_cm: float) -> Seek:
    """The role behaviour of a seeker navigation (not started) standing on ``place`` in a
    300 x 200 cm room (map frame = own frame), with a belief whose 95 % radius is about
    4 % of ``driven_cm`` (a Gaussian's 95 % radius is 2.45 standard deviations)."""
    nav = make_nav("seeker", pool=BufferPool(4))
    nav.map = nav.work_map = room_map(Truth(0, 0, 300, 200))
    nav.origin = Pose(0.0, 0.0, 0.0)
    nav.pose = Pose(place[0], place[1], 0.0)
    seek = nav.behaviour
    seek.place = place
    seek.stage = "close"
    believe(nav, max(0.3, 0.04 * driven_cm / 2.45), 1.0)
    return seek


def test_the_ring_grows_with_the_drift_and_stays_on_free_ground() -> None:
    """In the open, a larger drift asks for a wider ring or more points; every ring point
    is passable and on the ring (or pulled in toward the place). Little drift: no ring."""
    assert not searching_nav((150.0, 100.0), 100.0).plan_search()  # drift 4 cm
    rings = []
    for driven in (600.0, 1000.0, 1500.0):
        nav = searching_nav((150.0, 100.0), driven)
        assert nav.plan_search() and nav.stage == "search"
        rings.append((len(nav.search.points), nav.search.ring_cm))
        ring = nav.search.ring_cm
        for q in nav.search.points:
            assert 0.5 * ring - 0.1 <= math.dist(q, (150.0, 100.0)) <= ring + 0.1
            assert passable_at(nav.nav.map, q[0], q[1], nav.nav.radius_cm, 0.0)
    assert rings == sorted(rings) and rings[0] != rings[-1]
    first = searching_nav((150.0, 100.0), 1500.0)
    first.plan_search()
    assert first.search.points[0][0] > 150.0  # facing +x: the point ahead first


@pytest.mark.trio
async def test_the_search_says_what_comes_after_its_rings(autojump_clock) -> None:
    """The search is a part the seeker calls, and it answers what comes next: with no
    ring point left, the end (and why) for a plain guess; for a wider guess (``within``)
    planned with time left, a step of the sweep by touch, ring or not."""
    from actors.firmware.nav.search import Next

    seek = searching_nav((150.0, 100.0), 100.0)  # drift 4 cm: no ring is needed
    assert not seek.search.plan(seek.place)
    assert await seek.search.next_point() is Next.OVER
    assert seek.search.over_reason(swept=False).startswith(
        "the IR sensor saw nothing there, nor on a ring of")
    wider = searching_nav((150.0, 100.0), 100.0)
    wider.nav.memory.within = 40.0  # the operator's wider search: 40 + 4 cm < the reach
    assert not wider.search.plan(wider.place)  # no ring...
    assert await wider.search.next_point() is Next.SWEEP  # ...but the sweep's time
    assert "rings out to" in wider.search.over_reason(swept=True)


def test_ring_points_in_walls_are_pulled_in_or_left_out() -> None:
    """Ring points in or near the walls are pulled in toward the place (a place by a
    wall), or left out when no pulled-in point is passable either (in a corner)."""
    nav = searching_nav((20.0, 20.0), 1000.0)
    assert nav.plan_search()
    open_room = searching_nav((150.0, 100.0), 1000.0)
    assert open_room.plan_search() and open_room.search.ring_cm == nav.search.ring_cm
    assert 0 < len(nav.search.points) < len(open_room.search.points)
    by_wall = searching_nav((40.0, 100.0), 1000.0)
    assert by_wall.plan_search()
    assert len(by_wall.search.points) == len(open_room.search.points)
    assert any(math.dist(q, (40.0, 100.0)) < by_wall.search.ring_cm - 1.0
               for q in by_wall.search.points)
    for q in nav.search.points + by_wall.search.points:
        assert passable_at(nav.nav.map, q[0], q[1], nav.nav.radius_cm, 0.0)


# ============================================================================ the wider search


@pytest.mark.parametrize("need", [150.0, 200.0, 300.0])
def test_wider_rings_see_everything_within_the_need(need) -> None:
    """The rings of a wider search leave no hole: every point within ``need`` of the place
    is within reach of the place itself, of a first-ring point (scanned all round by the
    place's scan and its own), or of a wider ring's point in its outward scan (+-100 deg
    plus the sensor's 20)."""
    reach = 70.0
    rings = search_rings(need, reach, 6, 60.0, 70.0, 6)
    assert rings[0] == search_ring(need, reach, 6, 60.0) and len(rings) >= 2
    points = [(i, r * math.cos(2 * math.pi * k / n), r * math.sin(2 * math.pi * k / n))
              for i, (n, r) in enumerate(rings) for k in range(n)]

    def seen(x: float, y: float) -> bool:
        if math.hypot(x, y) <= reach:
            return True
        for i, px, py in points:
            if math.dist((x, y), (px, py)) > reach:
                continue
            out = math.degrees(math.atan2(py, px))
            to = math.degrees(math.atan2(y - py, x - px))
            if i == 0 or abs(angle_diff_deg(to, out)) <= 120.0:
                return True
        return False

    for rho in range(0, int(need) + 1, 5):
        for a in range(0, 360, 3):
            x, y = rho * math.cos(math.radians(a)), rho * math.sin(math.radians(a))
            assert seen(x, y), (rho, a)
    assert search_rings(need, reach, 6, 60.0, 70.0, 1) == rings[:1]  # a plain guess: one ring


GUESS_OFF = (100.0, 80.0)  # 165 cm from the hider: far beyond IR range of the guess


async def _seek(dest: dict) -> Body:
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await begin(system, pool, dest)
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 1200.0)
    return body


@pytest.mark.trio
async def test_a_guess_with_within_searches_rings_round_it_and_finds(autojump_clock) -> None:
    """The operator's wider search (``within`` 180 cm) round a guess 165 cm from the hider
    finds it from a wider ring; the same guess without ``within`` is not found."""
    assert math.dist(GUESS_OFF, HIDER) == pytest.approx(165.5, abs=0.1)
    plain = await _seek({"x": GUESS_OFF[0], "y": GUESS_OFF[1]})
    assert plain.frames("found") == []
    wider = await _seek({"x": GUESS_OFF[0], "y": GUESS_OFF[1], "within": 180.0})
    assert wider.frames("not_found") == []
    f = wider.frames("found")[0].data
    assert math.dist((f["x"], f["y"]), GUESS_OFF) > 90.0  # beyond the first ring
    assert math.dist((f["x"], f["y"]), HIDER) < 80.0


@pytest.mark.trio
async def test_a_wider_search_gives_up_after_its_time(autojump_clock) -> None:
    """Out of time (`SeekingOptions.wide_search_s`, here 1 s), the ring points left are
    dropped: the seeker answers ``not_found`` after the first ring point."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool,
                                                 seeking=SeekingOptions(wide_search_s=1.0)),
                                      "seeker")
        await begin(system, pool, {"x": GUESS_OFF[0], "y": GUESS_OFF[1], "within": 180.0})
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 1200.0)
    assert "rings out to" in body.frames("not_found")[0].data["reason"]
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    assert sum(d.startswith("round the place") for d in details) == 1


async def _seek_lost(dest: dict) -> Body:
    """A seeker told it starts 100 cm right of where it stands: it believes it is at the
    guess while it is 100 cm short of it, and every ring round the guess is off too."""
    body = Body(truth=Truth(-50, -50, 250, 150), ir_in_range=ir_sees_hider)
    pool = BufferPool(64)
    wrong = {**ORIGIN, "x": ORIGIN["x"] + 100.0}
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("seeker", body, pool), "seeker")
        await send_route(system, pool, "seeker", wrong, dest, room_map(TRUTH_MAP))
        assert await wait_for(lambda: body.frames("found") or body.frames("not_found"), 1200.0)
    return body


@pytest.mark.trio
async def test_a_wider_search_sweeps_by_touch_when_its_pose_is_wrong(autojump_clock) -> None:
    """The pose 100 cm off without the seeker knowing: a plain guess at the hider is not
    found; a wider one (``within`` 40 cm, so no ring is needed) sweeps the room by touch
    and finds it."""
    plain = await _seek_lost({"x": HIDER[0], "y": HIDER[1]})
    assert plain.frames("found") == []
    wider = await _seek_lost({"x": HIDER[0], "y": HIDER[1], "within": 40.0})
    assert wider.frames("not_found") == [], wider.frames("not_found")
    assert wider.frames("found")
    states = [fr.data.get("state") for fr in wider.frames("status")]
    assert "sweeping" in states and "searching" not in states


@pytest.mark.trio
async def test_a_search_point_where_the_seeker_stands_is_scanned_and_the_search_goes_on(
        autojump_clock, monkeypatch) -> None:
    """A ring point the seeker already stands on (it was blocked on the ring's radius, and
    the ring starts on its side): the route ends as it starts, the scan from that point
    runs, and the search goes on to an answer instead of waiting in ``searching`` with
    nothing in flight."""
    plan = Seek.plan_search

    def here_first(self: Seek) -> bool:
        if not plan(self):
            return False
        self.search.points.insert(0, (self.nav.map_pose.x, self.nav.map_pose.y))
        return True

    monkeypatch.setattr(Seek, "plan_search", here_first)
    body = await _seek_far_guess(WIDE, None)
    assert body.frames("found") or body.frames("not_found")
    details = [fr.data.get("detail", "") for fr in body.frames("status")]
    first = details.index("looking with the IR sensor from the search ring")
    assert not details[first + 1].startswith("round the place")
