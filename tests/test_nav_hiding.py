"""Hiding navigation: spot check, route round obstacles, arrival within tolerance, restarts."""

from __future__ import annotations

import math
from contextlib import asynccontextmanager

import numpy as np
import pytest
import trio

from actors import BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route import Motion
from actors.firmware.origin_wire import length_pair
from server.protocol.pose import Pose
from tests.test_nav_common import (
    Body,
    Truth,
    believe,
    download,
    room_map,
    rover_spec,
    send_orders,
    send_route,
    wait_for,
)
from tests.test_nav_recovery import scraped_nav

# the hider starts at (50, 50) @ 0 in the map frame; its own frame starts at (0, 0)
ORIGIN = {"x": 50.0, "y": 50.0, "heading": 0.0}
TRUTH_MAP = Truth(0, 0, 300, 200, boxes=((140, 0, 20, 150),))  # map frame


def own_truth() -> Truth:
    """The same room in the hider's own frame (shifted by the origin)."""
    return Truth(-50, -50, 250, 150, boxes=((90, -50, 20, 150),))


async def begin(system, pool, dest) -> None:
    """What the server sends for ``hide``: origin, start, destination; then the map."""
    await send_route(system, pool, "hider", ORIGIN, dest, room_map(TRUTH_MAP))


TURNING = {"x": 50.0, "y": 150.0, "heading": 90.0}  # its route begins with a turn
STRAIGHT_ON = {"x": 120.0, "y": 50.0, "heading": 0.0}  # its route begins with a move


@asynccontextmanager
async def hider_at_first(kind: str, dest: dict, **body_kw):
    """A hider on its way to ``dest``, caught at its first motor command ``kind``
    (MOTOR_TURN or MOTOR_MOVE): yields the system, the fake body and the nav actor."""
    body = Body(truth=own_truth(), **body_kw)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await begin(system, pool, dest)
        assert await wait_for(lambda: any(c == kind for c, _ in body.motor_log), 10.0)
        yield system, body, system.whereis("hider/nav").actor


@pytest.mark.trio
async def test_hider_requests_the_map_drives_round_the_wall_and_arrives(autojump_clock) -> None:
    """start -> map_request; a valid spot behind a wall is reached within 5 cm / 5 deg."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await begin(system, pool, {"x": 250.0, "y": 50.0, "heading": 90.0})
        assert len(body.frames("map_request")) == 1
        assert await wait_for(lambda: body.frames("arrived"), 120.0)
        arrived = body.frames("arrived")[0].data
        assert math.dist((arrived["x"], arrived["y"]), (250, 50)) <= 5.0
        assert abs(arrived["heading"] - 90.0) <= 5.0
        true = body.pose  # the fake motor is exact: own frame + origin = map frame
        assert math.dist((true.x + 50, true.y + 50), (250, 50)) <= 5.0
        assert not any(c == "MOTOR_MOVE" and v > 20.0 for c, v in body.motor_log)
        assert body.frames("status")[-1].data["state"] == "hidden"
        assert [c for c, o in body.sent if o.cmd == "arrived"] == ["WIFLY_SEND"]


@pytest.mark.trio
@pytest.mark.parametrize("dest, why", [
    ({"x": 150.0, "y": 50.0, "heading": 0.0}, "obstacle"),
    ({"x": 150.0, "y": 185.0, "heading": 0.0}, "obstacle"),
    ({"x": 900.0, "y": 50.0, "heading": 0.0}, "outside the map"),
], ids=["inside-wall", "too-tight", "off-map"])
async def test_invalid_spot_is_refused_with_a_reason_and_no_motion(autojump_clock, dest,
                                                                   why) -> None:
    """An invalid spot gets ``invalid_spot`` naming why; the rover does not move (with
    ``hide_within_cm`` 0: no place near it is looked for)."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool,
                                                 options=NavOptions(hide_within_cm=0.0)), "hider")
        await begin(system, pool, dest)
        assert await wait_for(lambda: body.frames("invalid_spot"), 5.0)
        assert body.frames("invalid_spot")[0].data["reason"].startswith(why)
        assert not any(c in ("MOTOR_MOVE", "MOTOR_TURN") for c, _ in body.motor_log)
        assert body.frames("arrived") == []


@pytest.mark.trio
async def test_hider_replans_after_being_blocked(autojump_clock) -> None:
    """Blocked twice (a rover in the way): it backs off, replans, and still arrives."""
    body = Body(truth=own_truth(), blocked_moves=2)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await begin(system, pool, {"x": 100.0, "y": 100.0, "heading": 0.0})
        assert await wait_for(lambda: body.frames("arrived"), 120.0)
        assert any(c == "MOTOR_MOVE" and v < 0 for c, v in body.motor_log)  # backed off
        nav = system.whereis("hider/nav").actor
        assert nav.counters["blocked"] == 2


@pytest.mark.trio
async def test_a_map_that_never_comes_is_asked_for_again_with_a_doubling_wait(
        autojump_clock) -> None:
    """The map lost on the way (a corrupted chunk refused, the map never completes):
    asked again after 20 s, then 40 s; once it comes the hider
    drives, and asks no more."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await send_orders(system, pool, "hider", ORIGIN, {"x": 250.0, "y": 50.0, "heading": 90.0})
        requests = lambda: len(body.frames("map_request"))  # noqa: E731
        await trio.sleep(19.0)
        assert requests() == 1
        assert await wait_for(lambda: requests() == 2, 2.0)
        await trio.sleep(37.0)
        assert requests() == 2  # the second wait is 40 s
        assert await wait_for(lambda: requests() == 3, 4.0)
        await download(system, pool, "hider", room_map(TRUTH_MAP))
        assert await wait_for(lambda: any(c == "MOTOR_MOVE" for c, _ in body.motor_log), 10.0)
        nav = system.whereis("hider/nav").actor
        held = nav.map
        await download(system, pool, "hider", room_map(TRUTH_MAP))  # a late second answer
        assert await wait_for(lambda: body.frames("arrived"), 120.0)
        assert requests() == 3 and nav.map is held


@pytest.mark.trio
async def test_hider_nav_crash_mid_route_resumes_and_arrives(autojump_clock) -> None:
    """A navigation crash while driving: the new incarnation re-requests the map and arrives."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    memory = NavMemory()
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=memory), "hider")
        await begin(system, pool, {"x": 250.0, "y": 50.0, "heading": 90.0})
        assert await wait_for(lambda: body.pose.distance_to(Pose()) > 40.0, 60.0)
        system.inject_crash("hider/nav")
        assert await wait_for(lambda: len(body.frames("map_request")) == 2, 5.0)
        await download(system, pool, "hider", room_map(TRUTH_MAP))
        assert await wait_for(lambda: body.frames("arrived"), 120.0)
        arrived = body.frames("arrived")[0].data
        assert math.dist((arrived["x"], arrived["y"]), (250, 50)) <= 5.0


@pytest.mark.trio
async def test_hider_passes_a_gap_barely_wider_than_its_turning_disc(autojump_clock) -> None:
    """A 30 cm gap: too tight for radius plus margin, passable at the turning radius alone."""
    boxes = ((190, 0, 15, 150), (190, 180, 15, 130))  # map frame: gap y 150..180
    truth_map = Truth(0, 0, 400, 300, boxes=boxes)
    own = Truth(-50, -50, 350, 250, boxes=tuple((x - 50, y - 50, w, h) for x, y, w, h in boxes))
    body = Body(truth=own)
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await send_orders(system, pool, "hider", ORIGIN, {"x": 300.0, "y": 60.0, "heading": 270.0})
        await trio.sleep(0.5)
        await download(system, pool, "hider", room_map(truth_map))
        assert await wait_for(lambda: body.frames("arrived") or body.frames("invalid_spot"),
                              180.0)
        assert body.frames("invalid_spot") == []
        nav = system.whereis("hider/nav").actor
        assert nav.tier == (nav.radius_cm, 0.0)  # the first tier found no path
        true = body.pose
        assert math.dist((true.x + 50, true.y + 50), (300, 60)) <= 5.0
        assert nav.counters["blocked"] == 0


@pytest.mark.trio
async def test_hider_finds_a_gap_its_dead_reckoning_misses_by_nudging_sideways(autojump_clock
                                                                               ) -> None:
    """The map shows the gap 10 cm off where it is (dead-reckoning drift): the rover hits
    the wall's end, and at the gap's mouth it probes sideways round the place it met it
    (one side, then the other) and gets through, with nothing reported invalid. It hides
    within the map's error of its spot, not closer: past the gap, free space weighs its
    belief against the map's walls, which are 10 cm off, and the heading that leaves
    drifts the pose over the last metre (a cell and a half of doubt)."""
    map_boxes = ((190, 0, 15, 150), (190, 185, 15, 125))  # the map: gap y 150..185
    true_boxes = ((190, 0, 15, 140), (190, 175, 15, 135))  # the room: gap y 140..175
    own = Truth(-50, -50, 350, 250,
                boxes=tuple((x - 50, y - 50, w, h) for x, y, w, h in true_boxes))
    body = Body(truth=own)
    pool = BufferPool(64)
    options = NavOptions()
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, options=options), "hider")
        await send_orders(system, pool, "hider", ORIGIN, {"x": 300.0, "y": 60.0, "heading": 270.0})
        await trio.sleep(0.5)
        await download(system, pool, "hider", room_map(Truth(0, 0, 400, 300, boxes=map_boxes)))
        assert await wait_for(lambda: body.frames("arrived") or body.frames("invalid_spot"),
                              300.0)
        assert body.frames("invalid_spot") == []
        nav = system.whereis("hider/nav").actor
        assert nav.counters["blocked"] >= 2
        assert nav.counters["nudges"] >= 2  # one side still hits the wall's end; the other passes
        true = body.pose
        assert math.dist((true.x + 50, true.y + 50), (300, 60)) <= 15.0


@pytest.mark.trio
async def test_a_tread_fault_in_a_turn_stops_it_holds_then_arrives_with_a_wider_drift(
        autojump_clock) -> None:
    """NAV_TREAD_FAULT (the right tread counts short) during a turn: MOTOR_STOP at once,
    no motion for the hold (``tread_hold_s``), then the route goes on and arrives; the
    drift estimate grows with every cm driven after the fault (the heading is doubted)."""
    async with hider_at_first("MOTOR_TURN", TURNING, speed=10.0) as (system, body, nav):
        drift0 = nav.drift_cm
        n = len(body.motor_log)
        await system.send("hider/nav", Message.uint(Cmd.NAV_TREAD_FAULT, int(TreadFault.short(1))))
        await trio.sleep(0.1)
        assert nav.tread_faults == 1 and nav.moving
        await trio.sleep(11.0)  # within the 12 s hold: nothing new commanded
        # (the fake motor logs the stop once its turn, slept through, is over)
        assert body.motor_log[n][0] == "MOTOR_STOP"
        assert not any(c in ("MOTOR_MOVE", "MOTOR_TURN") for c, _ in body.motor_log[n:])
        assert "counts short" in body.frames("status")[-1].data["detail"]
        assert await wait_for(lambda: body.frames("arrived"), 60.0)
        assert any(c == "MOTOR_MOVE" for c, _ in body.motor_log[n:])
        assert nav.drift_cm > drift0 + 0.04 * 100.0  # more than distance alone would add
        arrived = body.frames("arrived")[0].data
        assert math.dist((arrived["x"], arrived["y"]), (50, 150)) <= 5.0


@pytest.mark.trio
async def test_both_treads_silent_in_a_turn_holds_and_doubts_the_heading_more(
        autojump_clock) -> None:
    """NAV_TREAD_FAULT value 4 (both silent: Motor Control ended a turn without an Int E)
    holds like a single tread's report, but says "both"; the belief's heading doubt
    grows by the whole commanded turn's unseen part (both treads reported)."""
    async with hider_at_first("MOTOR_TURN", TURNING, speed=10.0) as (system, body, nav):
        n = len(body.motor_log)
        h0 = nav.spread.heading95_deg
        await system.send("hider/nav",
                          Message.uint(Cmd.NAV_TREAD_FAULT, int(TreadFault.BOTH_SILENT)))
        # Motor Control's drive model of the stopped turn: 5 cm a tread (44 deg)
        await system.send("hider/nav", length_pair(Cmd.NAV_TREAD_DRIVEN, -5.0, 5.0))
        await trio.sleep(0.1)
        assert nav.tread_faults == 1 and nav.moving
        await trio.sleep(11.0)  # within the hold: nothing new commanded
        assert nav.spread.heading95_deg > h0 + 5.0
        assert not any(c in ("MOTOR_MOVE", "MOTOR_TURN") for c, _ in body.motor_log[n:])
        assert "both treads do not count" in body.frames("status")[-1].data["detail"]
        assert await wait_for(lambda: body.frames("arrived"), 60.0)


def _reported(motion: Motion, value: int | None, left: float, right: float,
              driven: tuple[float, float] | None = None) -> object:
    """A hider's belief after ``motion``, which Motor Control counted as ``left`` /
    ``right`` [cm] of tread travel (its dead reckoning by the midpoint rule on a 13 cm
    track), with the tread fault ``value`` reported (None: none) and ``driven`` its drive
    model's travel of each tread (``NAV_TREAD_DRIVEN``; None: not sent)."""
    nav = scraped_nav(0.0, sigma_cm=1.0)
    believe(nav, 1.0, 1.0)
    nav.last_motion = motion
    if value is not None:
        nav.localiser.note_tread_fault(TreadFault(value))
    if driven is not None:
        nav.note_tread_driven(*driven)
    dtheta, ds = (right - left) / 13.0, 0.5 * (left + right)
    nav.pose = Pose(250.0 + ds * math.cos(0.5 * dtheta), 100.0 + ds * math.sin(0.5 * dtheta),
                    math.degrees(dtheta))
    nav.localiser.track_belief()
    return nav


def test_one_tread_silent_in_a_turn_turns_the_believed_heading_on() -> None:
    """Left silent in a turn (it counted nothing, the right tread 10 cm): the left tread
    went anywhere between 0 and as far as the right, so the belief's heading lies
    between the counted turn and twice it: its mean turns on in the turn's direction
    and its 95 % heading spread is tens of degrees. Unreported, the same counts leave
    the heading where counted, within a few degrees."""
    counted = math.degrees(10.0 / 13.0)
    quiet = _reported(Motion("turn", 90.0), None, 0.0, 10.0)
    assert quiet.map_pose.heading_deg == pytest.approx(counted, abs=2.0)
    assert quiet.spread.heading95_deg < 6.0
    silent = _reported(Motion("turn", 90.0), 0, 0.0, 10.0, (-10.0, 10.0))
    assert counted + 10.0 < silent.map_pose.heading_deg < 2.0 * counted
    assert silent.spread.heading95_deg > 15.0


def _heading_range(nav) -> tuple[float, float]:
    """The 2.5 % and 97.5 % quantiles of the belief's heading [deg]."""
    p, w = nav.localiser.belief.particles, nav.localiser.belief.weights
    order = np.argsort(p[:, 2])
    cum = np.cumsum(w[order])
    lo, hi = (p[order[np.searchsorted(cum, q)], 2] for q in (0.025, 0.975))
    return math.degrees(lo), math.degrees(hi)


def test_a_turn_on_two_stuck_encoders_is_believed_as_far_as_the_drive_model_went() -> None:
    """Both encoders stuck in a 23 deg turn: Motor Control ends it by its model, not the
    counts, after 4.5 cm a tread (40 deg), so the turn went beyond what was commanded.
    The belief's heading spans nothing counted to the model's 40 deg; were the command
    taken as the far end, the true turn would lie outside the belief."""
    turn = Motion("turn", -23.0)
    nav = _reported(turn, int(TreadFault.BOTH_SILENT), 0.0, 0.0, (4.5, -4.5))
    lo, hi = _heading_range(nav)
    assert lo < -36.0 and hi > -4.0


def test_a_turn_that_ended_blocked_unreported_doubts_both_treads() -> None:
    """A turn that ended blocked after counting some (1 cm a tread) with no report: a
    jammed rover and two encoders that stopped read the same, so Motor Control's model
    (5 cm a tread, NAV_TREAD_DRIVEN) is the far end of both treads' travel."""
    turn = Motion("turn", 60.0)
    counted = _reported(turn, None, -1.0, 1.0)
    doubted = _reported(turn, None, -1.0, 1.0, (-5.0, 5.0))
    assert counted.spread.heading95_deg < 5.0
    lo, hi = _heading_range(doubted)
    assert lo < 12.0 and hi > 38.0


def test_both_short_in_a_straight_move_keeps_the_heading() -> None:
    """Both treads short in a straight move (each counted 8 of 20 cm) share one draw
    (they err alike): the move's length is in doubt, the heading is not. One tread
    short (8 counted, the other 20) doubts the heading."""
    move = Motion("move", 20.0)
    both = _reported(move, int(TreadFault.BOTH_SHORT), 8.0, 8.0, (20.0, 20.0)).spread
    one = _reported(move, int(TreadFault.short(0)), 8.0, 20.0, (20.0, 20.0)).spread
    assert both.heading95_deg < 5.0 < 15.0 < one.heading95_deg
    assert both.radius95_cm > 5.0  # 8 to 20 cm driven: the length is in doubt by 6


@pytest.mark.trio
async def test_a_tread_fault_in_a_move_ends_it_as_blocked(autojump_clock) -> None:
    """NAV_TREAD_FAULT (the left tread silent) during a straight move: a tread stalled
    against a wall reports the same, so no hold: the move ends as blocked and the
    route backs off at once. (A short count holds:
    see below.)"""
    async with hider_at_first("MOTOR_MOVE", STRAIGHT_ON) as (system, body, nav):
        n = len(body.motor_log)
        await system.send("hider/nav", Message.uint(Cmd.NAV_TREAD_FAULT, int(TreadFault.silent(0))))
        assert await wait_for(lambda: any(c == "MOTOR_MOVE" and v < 0
                                          for c, v in body.motor_log[n:]), 4.0)
        assert body.motor_log[n][0] == "MOTOR_STOP"
        assert nav.tread_faults == 1
        assert await wait_for(lambda: body.frames("arrived"), 60.0)


@pytest.mark.trio
async def test_a_short_count_in_a_move_holds_and_both_short_adds_no_heading_doubt(
        autojump_clock) -> None:
    """A tread (value 2) or both (value 6) counting short during a straight move: a
    slipping encoder or a weak motor, which a hold lets pass (ended as blocked, each
    back-off on the slip would go 3 times its count). MOTOR_STOP, nothing new
    for the hold, then the route goes on (what each does to the belief: see
    `test_both_short_in_a_straight_move_keeps_the_heading`)."""
    for value in (2, 6):
        async with hider_at_first("MOTOR_MOVE", STRAIGHT_ON) as (system, body, nav):
            n = len(body.motor_log)
            await system.send("hider/nav", Message.uint(Cmd.NAV_TREAD_FAULT, value))
            await trio.sleep(0.1)
            assert nav.tread_faults == 1 and nav.moving
            await trio.sleep(11.0)  # within the 12 s hold: nothing new commanded
            assert body.motor_log[n][0] == "MOTOR_STOP"
            assert not any(c in ("MOTOR_MOVE", "MOTOR_TURN") for c, _ in body.motor_log[n:])
            assert "holding" in body.frames("status")[-1].data["detail"]
            assert await wait_for(lambda: body.frames("arrived"), 60.0)
            assert nav.counters["blocked"] == 0


@pytest.mark.trio
async def test_both_short_in_a_move_where_a_wall_may_touch_is_a_slide_not_held(
        autojump_clock) -> None:
    """Both treads short in a straight move while a mapped wall lies within the body's
    radius plus the pose's doubt (``drift_cm``): the rover may be sliding along that
    wall, which counts short just like two slipping encoders. The move
    is not stopped, nothing is held, the route arrives unblocked. The same report
    with the walls beyond that reach holds (see above)."""
    async with hider_at_first("MOTOR_MOVE", STRAIGHT_ON) as (system, body, nav):
        believe(nav, 25.0)  # a long drive: 60 cm of doubt reaches the walls 50 cm off
        n = len(body.motor_log)
        await system.send("hider/nav",
                          Message.uint(Cmd.NAV_TREAD_FAULT, int(TreadFault.BOTH_SHORT)))
        await trio.sleep(0.1)
        assert nav.moving
        assert not any(c == "MOTOR_STOP" for c, _ in body.motor_log[n:])
        assert not any("holding" in f.data.get("detail", "") for f in body.frames("status"))
        # the fake motor is exact: a belief as narrow as that lets the route go on as it is
        believe(nav, 1.0)
        assert await wait_for(lambda: body.frames("arrived"), 30.0)
        assert nav.counters["blocked"] == 0


@pytest.mark.trio
async def test_a_tread_fault_while_standing_is_ignored(autojump_clock) -> None:
    """A report arriving after the motion ended (nothing in flight) starts no hold."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await trio.sleep(2.0)
        await system.send("hider/nav", Message.uint(Cmd.NAV_TREAD_FAULT, int(TreadFault.silent(0))))
        await trio.sleep(0.5)
        nav = system.whereis("hider/nav").actor
        assert nav.tread_faults == 0 and not nav.moving


@pytest.mark.trio
async def test_a_spot_inside_a_wall_moves_to_the_nearest_place_that_fits(autojump_clock) -> None:
    """A spot on the wall's middle (its map says obstacle): the hider hides at the nearest
    place within ``hide_within_cm`` where it fits, reports ``arrived`` with where it is,
    and says so in its status; a spot with nothing that fits near it is refused."""
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await begin(system, pool, {"x": 150.0, "y": 50.0, "heading": 0.0})
        assert await wait_for(lambda: body.frames("arrived"), 120.0)
        a = body.frames("arrived")[0].data
        assert 20.0 <= math.dist((a["x"], a["y"]), (150, 50)) <= 30.0
        assert a["x"] < 140.0  # this side of the wall: the nearer place is the one reached
        assert body.frames("invalid_spot") == []
        details = [f.data.get("detail", "") for f in body.frames("status")]
        assert any("does not fit (obstacle" in d for d in details)
        nav = system.whereis("hider/nav").actor
        assert nav.behaviour.near_spots(900.0, 50.0, 0.0) == []  # off the map: nothing near


@pytest.mark.trio
@pytest.mark.parametrize("dest, hidden", [({"x": 70.0, "y": 50.0, "heading": 0.0}, True),
                                          ({"x": 120.0, "y": 50.0, "heading": 0.0}, False)],
                         ids=["20-cm-off", "70-cm-off"])
async def test_a_hider_blocked_for_good_near_its_spot_hides_where_it_stands(
        autojump_clock, monkeypatch, dest, hidden) -> None:
    """Every move blocked, back-offs too (wedged by something the map does not show): the
    route is given up after ``REPLAN_LIMIT`` blocks where the rover started. 20 cm from
    the spot the hider hides where it stands (``arrived``, its own pose); 70 cm from it,
    it refuses as before."""
    import tests.test_nav_common as common

    class WedgedMotor(common.FakeMotor):
        async def handle(self, message: Message) -> None:
            if message.command == Cmd.MOTOR_MOVE:
                self.body.motor_log.append((Cmd(message.command).name, float(message.value)))
                await trio.sleep(0.2)
                self.ctx.send_nowait(self.nav, Message.float(Cmd.NAV_MOTION_BLOCKED, 0.0))
                return
            await super().handle(message)

    monkeypatch.setattr(common, "FakeMotor", WedgedMotor)
    body = Body(truth=own_truth())
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool), "hider")
        await begin(system, pool, dest)
        assert await wait_for(lambda: body.frames("arrived") or body.frames("invalid_spot"),
                              300.0)
        if hidden:
            a = body.frames("arrived")[0].data
            assert math.dist((a["x"], a["y"]), (50.0, 50.0)) <= 1.0  # where it stands
            assert body.frames("status")[-1].data["state"] == "hidden"
        else:
            assert body.frames("arrived") == []
            reason = body.frames("invalid_spot")[0].data["reason"]
            assert reason.startswith("cannot reach the spot")


def test_near_enough_needs_the_spot_in_sight_on_the_map(autojump_clock) -> None:
    """Within ``hide_within_cm`` but with the wall between (on the map): not near."""
    from actors.firmware.nav.factory import make_nav
    from server.protocol.pose import Pose as P

    nav = make_nav("hider", pool=BufferPool(4))
    nav.map = room_map(TRUTH_MAP)
    nav.origin = P(0.0, 0.0, 0.0)
    nav.pose = P(125.0, 50.0, 0.0)  # 15 cm before the wall's face (x 140..160)
    nav.goal = (145.0, 50.0)
    assert not nav.behaviour.near_enough()
    nav.goal = (125.0, 75.0)
    assert nav.behaviour.near_enough()
    nav.goal = (125.0, 90.0)
    assert not nav.behaviour.near_enough()  # 40 cm: too far
