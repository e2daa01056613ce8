"""Navigation's recovery when a route is blocked: back off, weigh the pose belief by the contact,
nudge the route sideways, probe a narrow passage, hold for a stalled tread.

Most tests drive the real navigation actor among the fakes of `tests.test_nav_common`
and assert on what it sends (motor commands, pose and status frames). The rest check
the nudge and contact geometry on a navigation that is not started.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
import trio

from actors import BufferPool, open_actor_system
from actors.firmware.drivers.tread_monitor import TreadFault, silent_reach_cm
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.nudge import (
    MAX_NUDGES,
    NUDGE_STEP_MAX_CM,
    Nudge,
    at_mouth,
    in_passage,
    near_block,
    nudge_step,
    nudged_route,
    progress,
    series_offset,
)
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.place import SAME_PLACE_CM
from actors.firmware.nav.recovery import REPLAN_LIMIT
from actors.firmware.nav.route import Motion
from server.protocol.pose import Pose
from tests.test_nav_common import (
    Body,
    Truth,
    believe,
    room_map,
    rover_spec,
    send_route,
    wait_for,
)

# ---------------------------------------------------------------- blocked in a corridor
# A hider sent from map (50, 50) (its own (0, 0)) to (600, 150) through a 30 cm corridor
# (x 250..450, walls y < 135 and y > 165). The fake motor drives exactly, except where
# the test scripts a block: the move ends blocked where the script says, the rover
# turned by the script's yaw. What navigation does about it is read from what it
# sends: its motor commands and the frames it reports to the server.

NARROW = NavOptions(motion=MotionNoise(encoder_sigma=0.005, turn_sigma=0.05))
"""A motion model that trusts the counts (the fake motor is exact): the belief stays a
few cm wide, so the probes step ``nudge_step_cm`` (4 cm)."""
CORRIDOR = Truth(0, 0, 700, 300, boxes=((250, 0, 200, 135), (250, 165, 200, 135)))
CORRIDOR_ORIGIN = {"x": 50.0, "y": 50.0, "heading": 0.0}
CORRIDOR_GOAL = {"x": 600.0, "y": 150.0, "heading": None}
OPEN_ROOM = Truth(0, 0, 700, 300)
"""The corridor's room without its walls: no wall near the route explains a block."""


class Blocks:
    """The script: forward moves that reach own-frame x ``at`` end there blocked, turned by
    ``yaw``, one entry per block in order; ``reverse`` scripts the end of the back-off
    that follows the last block (``(done cm, yaw deg)``, and a tread report Motor Control
    sends in it if a third item; None: as commanded)."""

    def __init__(self, *blocks: tuple[float, float],
                 reverse: tuple[float, ...] | None = None) -> None:
        self.todo = list(blocks)
        self.reverse = reverse
        self.at: list[tuple[float, int, int]] = []  # (time, len(sent), len(motor_log))
        self.body: Body | None = None

    def __call__(self, pose: Pose, cm: float) -> tuple[float, ...] | None:
        assert self.body is not None
        if cm < 0 and self.reverse is not None and not self.todo and self.at:
            done, *rest = self.reverse
            self.reverse = None
            return -done, *rest
        if cm > 0 and self.todo and pose.x + cm * math.cos(pose.heading_rad) >= self.todo[0][0]:
            at, yaw = self.todo.pop(0)
            self.at.append((trio.current_time(), len(self.body.sent), len(self.body.motor_log)))
            return max(0.0, (at - pose.x) / math.cos(pose.heading_rad)), yaw
        return None


async def drive_corridor(blocks: Blocks, *, options: NavOptions | None = None,
                         after_s: float = 20.0, crash: bool = False,
                         room: Truth = CORRIDOR) -> Body:
    """Send the hider through the corridor (or another ``room``, mapped whole) with
    ``blocks`` scripted; return its body once the last block is ``after_s`` past
    (navigation crashed and restarted then if ``crash``)."""
    body = Body(script=blocks)
    blocks.body = body
    options = options or NARROW
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=NavMemory(),
                                                 options=options), "hider")
        await send_route(system, pool, "hider", CORRIDOR_ORIGIN, CORRIDOR_GOAL,
                         room_map(room))
        n = len(blocks.todo)
        assert await wait_for(lambda: len(blocks.at) == n, 120.0)
        await trio.sleep(after_s)
        if crash:
            system.inject_crash("hider/nav")
            await trio.sleep(3.0)
    return body


async def drive_until_answered(body: Body, goal_x: float, room: Truth) -> None:
    """Send the hider from map (50, 50) to (``goal_x``, 150) in ``room`` (mapped whole)
    and play until it answered (``arrived`` or ``invalid_spot``)."""
    pool = BufferPool(64)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("hider", body, pool, memory=NavMemory(),
                                                 options=NARROW), "hider")
        await send_route(system, pool, "hider", CORRIDOR_ORIGIN,
                         {"x": goal_x, "y": 150.0, "heading": None}, room_map(room))
        assert await wait_for(lambda: body.frames("arrived") or body.frames("invalid_spot"),
                              600.0)


def poses_after(body: Body, k: int, blocks: Blocks) -> list[tuple[float, float, float]]:
    """The map-frame poses navigation reported after block ``k`` (x, y, heading)."""
    return [(f.data["x"], f.data["y"], f.data["heading"])
            for f in [o for _, o in body.sent[blocks.at[k][1]:]] if f.cmd == "pose"]


def dead_reckoned_after_back_off(body: Body, k: int, blocks: Blocks) -> Pose:
    """The pose Motor Control reported once the back-off after block ``k`` ended, in the
    map frame (the hider's own frame starts at map (50, 50) @ 0)."""
    t_back, command, cm = motions_after(body, k, blocks)[0]
    assert command == "MOTOR_MOVE" and cm < 0
    end = t_back + abs(cm) / body.speed
    p = next(p for t, p in body.published if t >= end - 1e-9)
    return Pose(p.x + CORRIDOR_ORIGIN["x"], p.y + CORRIDOR_ORIGIN["y"], p.heading_deg)


def motions_after(body: Body, k: int, blocks: Blocks) -> list[tuple[float, str, float]]:
    """The turns and moves navigation commanded after block ``k``: (time, command, amount)."""
    start = blocks.at[k][2]
    return [(t, c, v) for t, (c, v) in zip(body.motor_at[start:], body.motor_log[start:],
                                           strict=True) if c in ("MOTOR_TURN", "MOTOR_MOVE")]


@pytest.mark.trio
async def test_a_scrape_moves_the_reported_pose_to_the_wall_on_the_stalled_side(
        autojump_clock) -> None:
    """Blocked mid-corridor having yawed 3 deg left: the left side touches the wall at
    y = 165, so the pose navigation reports moves up to it (from y 149.3); Motor Control
    is told nothing of it (its dead reckoning stays continuous), and a restarted
    navigation reports the corrected pose still (the retained memory keeps it)."""
    blocks = Blocks((250.0, 3.0))
    body = await drive_corridor(blocks, after_s=1.0, crash=True)
    x, y, _ = poses_after(body, 0, blocks)[0]
    assert 154.0 <= y <= 162.0 and x == pytest.approx(300.0 - 6.0, abs=3.0)  # backed off
    assert y - dead_reckoned_after_back_off(body, 0, blocks).y > 4.0
    assert {c for c, _ in body.motor_log} <= {"MOTOR_STOP", "MOTOR_GET_POSE", "MOTOR_TURN",
                                             "MOTOR_MOVE"}
    assert 154.0 <= poses_after(body, 0, blocks)[-1][1] <= 162.0  # after the restart
    assert "restarted" in [f.data["state"] for f in body.frames("status")]


@pytest.mark.trio
async def test_a_block_either_side_explains_leaves_the_pose_on_the_axis(autojump_clock) -> None:
    """No yaw: left and right explain the block alike; the belief keeps both and the
    reported pose stays near where dead reckoning put it (y 149.3) as the rover backs
    off."""
    blocks = Blocks((250.0, 0.0))
    body = await drive_corridor(blocks, after_s=1.0)
    x, y, _ = poses_after(body, 0, blocks)[0]
    assert y == pytest.approx(149.3, abs=2.5) and x == pytest.approx(294.0, abs=3.0)


@pytest.mark.trio
async def test_a_block_the_map_does_not_explain_leaves_the_reported_pose_on_dead_reckoning(
        autojump_clock) -> None:
    """Blocked in the open room having yawed 3 deg, far from any wall: something the map
    does not show stopped it (another rover), so the contact is not used: the pose
    navigation reports after backing off is where Motor Control's dead reckoning puts
    it (the same block in the corridor moves it to the wall)."""
    blocks = Blocks((250.0, 3.0))
    body = await drive_corridor(blocks, room=OPEN_ROOM, after_s=1.0)
    x, y, heading = poses_after(body, 0, blocks)[0]
    dr = dead_reckoned_after_back_off(body, 0, blocks)
    assert math.dist((x, y), (dr.x, dr.y)) < 1.0
    assert heading == pytest.approx(dr.heading_deg, abs=0.5)


@pytest.mark.trio
async def test_a_block_in_a_narrow_passage_probes_sideways_and_gets_through(
        autojump_clock) -> None:
    """Blocked moving forward mid-corridor (walls both sides within 40 cm), twice at one
    place and once 50 cm on: each time the rover backs off the short 6 cm (nothing is
    learned as an obstacle, which would close the corridor), the first time it probes
    4 cm to the left (a turn under 45 deg: the narrow belief's step, joined at a slant),
    and in the end it drives on through the corridor."""
    blocks = Blocks((250.0, 0.0), (250.0, 0.0), (300.0, 0.0))
    body = await drive_corridor(blocks, after_s=12.0)
    for k in range(3):
        assert motions_after(body, k, blocks)[0][1:] == ("MOTOR_MOVE", -6.0)
    first = next(v for _, c, v in motions_after(body, 0, blocks)[1:] if c == "MOTOR_TURN")
    assert 0.0 < first < 45.0
    assert max(x for x, _, _ in poses_after(body, 2, blocks)) > 450.0


@pytest.mark.trio
async def test_a_nudge_mid_corridor_shifts_the_route_left_and_drives_on(autojump_clock) -> None:
    """Blocked mid-corridor with no waypoint near the block: after the back-off the rover
    turns a little left (toward the route shifted 4 cm that way) and drives on to the
    end of the corridor, left of where dead reckoning had it at the block (the pose it
    reports is the belief's, which the contact split across the corridor). The split's
    left part may slide along the left wall on the way (the counts cannot tell a slide
    at a few degrees from a free move) and the rover step sideways when it weighs more."""
    blocks = Blocks((250.0, 0.0))
    body = await drive_corridor(blocks, after_s=10.0)
    motions = [(c, v) for _, c, v in motions_after(body, 0, blocks)]
    assert motions[0] == ("MOTOR_MOVE", -6.0)
    assert motions[1][0] == "MOTOR_TURN" and 0.0 < motions[1][1] < 45.0
    track = poses_after(body, 0, blocks)
    assert track[-1][0] > 400.0
    blocked_at = dead_reckoned_after_back_off(body, 0, blocks)
    assert body.published[-1][1].y + CORRIDOR_ORIGIN["y"] > blocked_at.y + 2.0


@pytest.mark.trio
async def test_a_back_off_blocked_without_turning_backs_off_again_at_once(
        autojump_clock) -> None:
    """A back-off that moved 2 cm and ended blocked without turning (the rear against
    something): no stall hold, it backs off again straight away."""
    blocks = Blocks((250.0, 0.0), reverse=(2.0, 0.0))
    body = await drive_corridor(blocks, after_s=3.0)
    motions = motions_after(body, 0, blocks)
    assert motions[1][1] == "MOTOR_MOVE" and motions[1][2] < 0
    assert motions[1][0] - motions[0][0] < 1.0


@pytest.mark.trio
async def test_a_back_off_that_did_not_move_replans_instead_of_reversing_again(
        autojump_clock) -> None:
    """Wedged: a back-off ended blocked without moving (reversing again and again leaves
    the rover stuck diagonally in a gap). The route is planned again from where the
    rover stands and driven on, not reversed once more."""
    blocks = Blocks((250.0, 0.0), reverse=(0.0, 0.0))
    body = await drive_corridor(blocks, after_s=3.0)
    motions = motions_after(body, 0, blocks)
    assert motions[0][1:] == ("MOTOR_MOVE", -6.0)
    after = motions[1:]
    assert after and not any(c == "MOTOR_MOVE" and v < 0 for _, c, v in after[:3])
    assert any(c == "MOTOR_MOVE" and v > 0 for _, c, v in after[:3])


@pytest.mark.trio
async def test_a_back_off_with_a_silent_tread_holds_though_the_pose_hardly_turned(
        autojump_clock) -> None:
    """A back-off ends blocked with the right tread reported silent and the rover turned
    only 4 deg (the belief follows a stalled tread's pivot by half): backing away over
    the ground just driven, a silent tread is the motor's, not a wall's, so navigation
    holds ``tread_hold_s`` instead of reversing again."""
    blocks = Blocks((250.0, 0.0), reverse=(2.0, 4.0, TreadFault.silent(1)))
    body = await drive_corridor(blocks, after_s=20.0)
    assert "a tread stalls; holding 12 s" in [f.data.get("detail")
                                               for f in body.frames("status")]
    motions = motions_after(body, 0, blocks)
    assert motions[1][0] >= motions[0][0] + NavOptions().tread_hold_s
    assert not (motions[1][1] == "MOTOR_MOVE" and motions[1][2] < 0)


@pytest.mark.trio
async def test_a_back_off_that_did_not_move_on_open_ground_holds_for_a_stalled_motor(
        autojump_clock) -> None:
    """Blocked in the open room, then a back-off that did not move at all, no wall
    anywhere near: nothing but the rover's own motor stops a reverse there, so it holds
    (beside a mapped wall the same back-off is wedged and replans at once)."""
    blocks = Blocks((250.0, 0.0), reverse=(0.0, 0.0))
    body = await drive_corridor(blocks, room=OPEN_ROOM, after_s=20.0)
    assert "a tread stalls; holding 12 s" in [f.data.get("detail")
                                               for f in body.frames("status")]
    motions = motions_after(body, 0, blocks)
    assert motions[1][0] >= motions[0][0] + NavOptions().tread_hold_s


class StalledMotor:
    """Every motion between ``t0`` and ``t0 + duration_s`` [s] ends blocked where it
    started: both treads stalled (nothing counts, nothing moves). A turn so ended is
    reported `TreadFault.BOTH_SILENT` when ``report_turns`` (as Motor Control does)."""

    def __init__(self, t0: float, duration_s: float, report_turns: bool = False) -> None:
        self.t0, self.t1 = t0, t0 + duration_s
        self.report_turns = report_turns
        self.blocked = 0

    def _stalled(self) -> bool:
        stalled = self.t0 <= trio.current_time() < self.t1
        self.blocked += stalled
        return stalled

    def move(self, pose: Pose, cm: float) -> tuple[float, float] | None:
        return (0.0, 0.0) if self._stalled() else None

    def turn(self, pose: Pose, deg: float) -> float | tuple[float, TreadFault] | None:
        if not self._stalled():
            return None
        return (0.0, TreadFault.BOTH_SILENT) if self.report_turns else 0.0


@pytest.mark.trio
async def test_a_motor_stalled_for_half_a_minute_is_waited_out_not_given_up(
        autojump_clock) -> None:
    """Both treads stalled for 30 s on open ground while the hider drives to its spot:
    each motion ends blocked without moving. Those blocks are the motor's, so they do
    not use up ``REPLAN_LIMIT``: the hider holds, tries again, and arrives once the
    motor runs again."""
    stall = StalledMotor(3.0, 30.0)
    body = Body(script=stall.move, turn_script=stall.turn)
    await drive_until_answered(body, 600.0, OPEN_ROOM)
    assert stall.blocked >= 2
    assert body.frames("invalid_spot") == [], body.frames("invalid_spot")
    assert body.frames("arrived")


@pytest.mark.trio
async def test_after_a_turn_on_silent_treads_a_short_move_checks_them_before_turning_again(
        autojump_clock) -> None:
    """The motor stalls for 30 s as the hider makes its first turn (both treads reported
    silent). Turning again while the fault is on would add as much heading doubt once
    more, so after each hold it checks the treads with a short straight move, holds again
    (24 s) while that ends blocked, and drives on only once the check passes; it
    arrives."""
    stall = StalledMotor(0.0, 30.0, report_turns=True)
    body = Body(script=stall.move, turn_script=stall.turn)
    await drive_until_answered(body, 600.0, OPEN_ROOM)
    motions = [(t, c, v) for t, (c, v) in zip(body.motor_at, body.motor_log, strict=True)
               if c in ("MOTOR_TURN", "MOTOR_MOVE")]
    assert motions[0][1] == "MOTOR_TURN"  # the turn the stall stops
    hold = NavOptions().tread_hold_s
    # the message carries a float32
    check = pytest.approx(silent_reach_cm(HardwareSpec.bench("hider").cm_per_interrupt))
    assert motions[1][1:] == ("MOTOR_MOVE", check)
    assert motions[1][0] >= motions[0][0] + hold
    assert motions[2][1:] == ("MOTOR_MOVE", check)  # the first check ended blocked
    assert motions[2][0] >= motions[1][0] + 2.0 * hold
    assert motions[2][0] >= stall.t1  # the second check passed: the route goes on
    assert "the treads still do not count; holding 24 s" in [
        f.data.get("detail") for f in body.frames("status")]
    assert body.frames("arrived")


@pytest.mark.trio
async def test_a_tread_check_that_counted_before_a_block_passes_and_the_route_takes_the_block(
        autojump_clock) -> None:
    """The first turn reports the right tread silent; the check after the hold counts
    1.5 cm and then ends blocked: the treads count, so the fault is over and the block is
    something in the way. No second hold: the route's block handling backs off at once."""
    turns = [(0.0, TreadFault.silent(1))]
    moves = [(1.5, 0.0)]
    body = Body(script=lambda pose, cm: moves.pop(0) if moves else None,
                turn_script=lambda pose, deg: turns.pop(0) if turns else None)
    await drive_until_answered(body, 600.0, OPEN_ROOM)
    motions = [(t, c, v) for t, (c, v) in zip(body.motor_at, body.motor_log, strict=True)
               if c in ("MOTOR_TURN", "MOTOR_MOVE")]
    # the message carries a float32
    check = pytest.approx(silent_reach_cm(HardwareSpec.bench("hider").cm_per_interrupt))
    assert motions[1][1:] == ("MOTOR_MOVE", check)
    assert motions[2][1:] == ("MOTOR_MOVE", -NavOptions().backoff_cm)
    assert motions[2][0] - motions[1][0] < 2.0
    assert not any("still do not count" in f.data.get("detail", "")
                   for f in body.frames("status"))
    assert body.frames("arrived")


@pytest.mark.parametrize("x, heading, sign", [(680.0, 0.0, -1.0), (680.0, 180.0, 1.0),
                                               (350.0, 0.0, 1.0)],
                         ids=["facing-the-wall", "back-to-the-wall", "open-floor"])
def test_the_tread_check_moves_away_from_the_nearer_mapped_wall(
        x: float, heading: float, sign: float) -> None:
    """The straight move that checks the treads after a turn on a silent tread goes in
    reverse when the nearest mapped wall is ahead (the turn may have jammed on it, and a
    check into it would end blocked with the treads well), else forward."""
    nav = make_nav("hider", pool=BufferPool(4), options=NARROW)
    nav.map = nav.work_map = room_map(OPEN_ROOM)
    nav.origin = Pose(0.0, 0.0, 0.0)
    nav.pose = Pose(x, 150.0, heading)
    believe(nav, 2.0)
    assert nav.check_sign() == sign


def scraped_nav(yaw_deg: float, sigma_cm: float = 4.0, memory: NavMemory | None = None,
                **options: Any) -> Any:
    """A hider navigation (not started) mid-corridor by dead reckoning (map (300, 150) @ 0,
    own frame (250, 100) @ 0), whose last forward move ended blocked after yawing
    ``yaw_deg``; its belief is ``sigma_cm`` wide round that pose (``memory``: its
    retained `NavMemory`)."""
    nav = make_nav("hider", pool=BufferPool(4), options=NavOptions(**options), memory=memory)
    nav.map = nav.work_map = room_map(
        Truth(0, 0, 700, 300, boxes=((250, 0, 200, 135), (250, 165, 200, 135))))
    nav.origin = Pose(50.0, 50.0, 0.0)
    nav.pose = Pose(250.0, 100.0, yaw_deg)
    nav.last_motion = Motion("move", 20.0)
    nav.motion_from = Pose(280.0, 150.0, 0.0)
    return believe(nav, sigma_cm)


def commands_of(nav: Any, monkeypatch: pytest.MonkeyPatch) -> list[Motion]:
    """The motions navigation ``nav`` (not started) commands from now on, recorded
    instead of sent to Motor Control."""
    commands: list[Motion] = []

    async def command(motion: Motion) -> None:
        commands.append(motion)

    monkeypatch.setattr(nav, "command", command)
    return commands


def lateral_cm(nav: Any) -> float:
    """The standard deviation of navigation's believed y [cm] (the corridor's cross axis)."""
    return math.sqrt(float(nav.spread.covariance[1, 1]))


@pytest.mark.trio
async def test_a_contact_either_side_explains_is_kept_as_two_hypotheses(
        autojump_clock, monkeypatch) -> None:
    """No yaw: the left side on the upper wall and the right side on the lower wall
    explain the block alike. The belief keeps both instead of discarding the contact:
    the contact counts, the pose navigation reports stays on the corridor's axis, and
    the lateral doubt grows (its weight each side of the axis, little on it; discarded
    it would stay as it was, one side taken would narrow it). A stalled turn says
    nothing: the reported pose stays. Either way the rover backs off."""
    nav = scraped_nav(0.0, sigma_cm=5.0)
    commands, before = commands_of(nav, monkeypatch), lateral_cm(nav)
    await nav.blocked_route("blocked")
    assert commands == [Motion("move", -nav.o.backoff_cm)]
    assert nav.counters["contacts"] == 1
    assert nav.pose_data()["y"] == pytest.approx(150.0, abs=2.5)
    assert lateral_cm(nav) > before + 1.5
    nav = scraped_nav(3.0)
    nav.last_motion = Motion("turn", 20.0)
    commands, before = commands_of(nav, monkeypatch), nav.pose_data()
    await nav.blocked_route("blocked")
    assert nav.counters["contacts"] == 0 and nav.pose_data() == before


def test_the_doubt_grows_with_driving_and_more_with_a_tread_report() -> None:
    """The belief's 95 % radius (``drift_cm``) grows as Motor Control's pose moves on;
    the same counts with the left tread reported short (it counted 4 cm of 20 driven)
    widen it far more: that tread's travel is anywhere between its count and its drive,
    and the heading doubt follows over the track width, with no degrees added by hand."""
    def driven(report: bool) -> float:
        nav = scraped_nav(0.0, sigma_cm=1.0)
        nav.pose = Pose(100.0, 100.0, 0.0)  # map (150, 150): the open room
        believe(nav, 1.0, 1.0)
        start = nav.drift_cm
        nav.last_motion = Motion("move", 20.0)
        if report:
            nav.localiser.note_tread_fault(TreadFault.short(0))
        dtheta = (20.0 - 4.0) / nav.spec.track_width_cm if nav.spec else 16.0 / 13.0
        ds = 12.0
        x, y = 100.0 + ds * math.cos(dtheta / 2), 100.0 + ds * math.sin(dtheta / 2)
        nav.pose = Pose(x, y, math.degrees(dtheta))
        nav.on_pose_at_rest()
        for _ in range(4):
            nav.last_motion = Motion("move", 20.0)
            x, y = x + 20.0 * math.cos(dtheta), y + 20.0 * math.sin(dtheta)
            nav.pose = Pose(x, y, math.degrees(dtheta))
            nav.on_pose_at_rest()
        return nav.drift_cm - start
    healthy, reported = driven(False), driven(True)
    assert healthy > 0.0
    assert reported > healthy + 10.0


def gap_blocked_nav(sigma_cm: float) -> Any:
    """A hider navigation (not started) stopped 5 cm into the gap of a 15 cm wall at x 400
    (gap y 300..335) by dead reckoning, 5 cm above its lower edge, with a belief
    ``sigma_cm`` wide: the lower edge explains the stop nearby; the upper wall's face
    does 20 cm up."""
    nav = make_nav("hider", pool=BufferPool(4))
    nav.map = nav.work_map = room_map(
        Truth(0, 0, 700, 450, boxes=((400, 0, 15, 300), (400, 335, 15, 115))))
    nav.origin = Pose(0.0, 0.0, 0.0)
    nav.pose = Pose(395.0, 312.5, 0.0)
    nav.last_motion = Motion("move", 20.0)
    nav.motion_from = Pose(375.0, 312.5, 0.0)
    return believe(nav, sigma_cm)


@pytest.mark.trio
async def test_a_gap_edge_contact_moves_the_belief_to_the_edge_and_keeps_the_far_face(
        autojump_clock, monkeypatch) -> None:
    """A narrow belief: the lower edge is the only likely explanation, the pose
    navigation reports moves down. A wide one (after a long drive): the upper face
    explains it too, and the belief keeps that hypothesis beside the lower edge's."""
    nav = gap_blocked_nav(3.0)
    commands = commands_of(nav, monkeypatch)
    await nav.blocked_route("blocked")
    assert nav.counters["contacts"] == 1 and nav.pose_data()["y"] < 311.0
    assert commands == [Motion("move", -nav.o.backoff_cm)]
    nav = gap_blocked_nav(12.0)
    commands_of(nav, monkeypatch)
    await nav.blocked_route("blocked")
    ys = [c.pose.y for c in nav.spread.clusters]
    assert any(y < 305.0 for y in ys) and any(y > 318.0 for y in ys)


# ---------------------------------------------------------------- the sideways search's geometry
# Pure functions of `nav.nudge`: a block (x, y, heading), an offset, the route, the map.

CORRIDOR_MAP = room_map(CORRIDOR)
"""The corridor of the scripted tests as a map: walls y < 135 and y > 165 for x 250..450."""
LONG_CORRIDOR_MAP = room_map(
    Truth(0, 0, 600, 300, boxes=((100, 0, 300, 135), (100, 165, 300, 135))))
"""A 30 cm corridor for x 100..400 (walls y < 135 and y > 165)."""
TOL_CM = NavOptions().waypoint_tol_cm


def test_nudge_shifts_only_waypoints_near_the_block_and_never_the_goal() -> None:
    """Blocked heading +x at (200, 150): the waypoint 30 cm on moves 6 cm sideways (+y);
    one farther on, and the goal even when near, stay."""
    nudge = Nudge((200.0, 150.0, 0.0), 6.0)
    pts = [(230.0, 150.0), (420.0, 150.0), (500.0, 60.0)]
    assert nudged_route(pts, nudge, LONG_CORRIDOR_MAP, drift_cm=0.0) == \
        [(230.0, 156.0), (420.0, 150.0), (500.0, 60.0)]
    assert nudged_route([(240.0, 150.0)], nudge, LONG_CORRIDOR_MAP, drift_cm=0.0) == \
        [(240.0, 150.0)]


def test_a_nudge_into_the_corridor_wall_or_backwards_is_refused() -> None:
    """No waypoint near the block: a point 50 cm ahead of it, shifted, is driven to first.
    A shift into the corridor's wall (20 cm off its axis) is refused (None); a route
    whose goal lies behind the block is left as it is."""
    pts = [(420.0, 150.0), (500.0, 60.0)]

    def nudged(block: tuple[float, float, float], off: float) -> Any:
        return nudged_route(pts, Nudge(block, off), LONG_CORRIDOR_MAP, drift_cm=0.0)

    assert nudged((250.0, 150.0, 0.0), -6.0) == [(300.0, 144.0), *pts]
    assert nudged((250.0, 150.0, 0.0), 20.0) is None
    assert nudged((250.0, 150.0, 180.0), 6.0) == pts  # ahead is backwards


def test_a_nudge_within_the_doubt_may_enter_a_mapped_wall() -> None:
    """A 20 cm shift into the corridor's wall, refused while the pose's doubt is a few cm,
    is tried once the doubt (``drift_cm``) is wider than the shift: the pose may be that
    far off, so the wall may be where the rover can pass."""
    pts = [(420.0, 150.0), (500.0, 60.0)]
    nudge = Nudge((250.0, 150.0, 0.0), 20.0)
    assert nudged_route(pts, nudge, LONG_CORRIDOR_MAP, drift_cm=3.0) is None
    assert nudged_route(pts, nudge, LONG_CORRIDOR_MAP, drift_cm=24.0) == [(300.0, 170.0), *pts]


def test_the_search_steps_wider_with_the_doubt_alternating_sides() -> None:
    """The step is ``nudge_step_cm`` (4) while the doubt is small, a third of the doubt
    after a long drive, and at most ``NUDGE_STEP_MAX_CM``; the offsets alternate sides,
    the first on the side asked for, growing by a step every second one."""
    assert nudge_step(4.0, 6.0) == 4.0
    assert nudge_step(4.0, 30.0) == pytest.approx(10.0)
    assert nudge_step(4.0, 60.0) == NUDGE_STEP_MAX_CM
    assert [series_offset(k, 4.0, 1.0) for k in range(MAX_NUDGES)] == \
        [4.0, -4.0, 8.0, -8.0, 12.0, -12.0]
    assert [series_offset(k, 10.0, -1.0) for k in range(3)] == [-10.0, 10.0, -20.0]


def test_a_probe_sidesteps_across_before_joining_the_shifted_line() -> None:
    """Backed off to (300, 150) after a block at (320, 150) heading +x, probing 10 cm to
    the right: the route starts with the point beside the rover on the shifted line
    (a sidestep square to the heading), then the shifted waypoint near the block;
    a shift within the waypoint tolerance needs no sidestep, nor a route without it."""
    pts = [(340.0, 150.0), (600.0, 150.0)]
    right = Nudge((320.0, 150.0, 0.0), -10.0)
    assert nudged_route(pts, right, CORRIDOR_MAP, drift_cm=5.0) == \
        [(340.0, 140.0), (600.0, 150.0)]  # no sidestep asked
    out = nudged_route(pts, right, CORRIDOR_MAP, drift_cm=5.0, sidestep_from=(300.0, 150.0),
                       tol_cm=TOL_CM)
    assert out is not None
    assert [q for p in out for q in p] == pytest.approx([300.0, 140.0, 340.0, 140.0, 600.0, 150.0])
    small = Nudge((320.0, 150.0, 0.0), -4.0)
    assert nudged_route(pts, small, CORRIDOR_MAP, drift_cm=5.0, sidestep_from=(300.0, 150.0),
                        tol_cm=TOL_CM) == [(340.0, 146.0), (600.0, 150.0)]


def test_progress_is_measured_along_the_heading_of_the_first_block() -> None:
    """A nudged route blocked 32 cm beside the series' first block (and 6 cm short of it,
    as a contact fix may leave it) made no progress: 32.6 cm away in a straight line, but
    -6 cm along the heading, so the series goes on. A block 50 cm on starts a new one."""
    first = (300.0, 150.0, 0.0)
    assert math.dist(first[:2], (294.0, 182.0)) > SAME_PLACE_CM
    assert progress(first, 294.0, 182.0) == pytest.approx(-6.0)
    assert progress(first, 350.0, 150.0) > SAME_PLACE_CM
    assert progress((300.0, 150.0, 90.0), 294.0, 182.0) == pytest.approx(32.0)


def test_a_block_short_of_the_mouth_is_near_the_series_but_not_in_a_passage() -> None:
    """Dead reckoning 10 cm short of the corridor's mouth (map (230, 162), the nose at
    x 240): no passage at the body or the nose, yet near the series' first block
    (232, 150), so during a series it is the next probe; 132 cm back in the room it is
    not. At the mouth (the nose in the gap) and inside it, it is a passage."""
    assert not in_passage(CORRIDOR_MAP, Pose(230.0, 162.0, 0.0), 10.0)
    assert near_block((232.0, 150.0, 0.0), 230.0, 162.0)
    assert not near_block((232.0, 150.0, 0.0), 100.0, 162.0)
    assert in_passage(CORRIDOR_MAP, Pose(245.0, 150.0, 0.0), 10.0)
    assert in_passage(CORRIDOR_MAP, Pose(300.0, 150.0, 0.0), 10.0)
    assert not in_passage(room_map(OPEN_ROOM), Pose(300.0, 150.0, 0.0), 10.0)


def test_a_gap_whose_walls_are_close_is_a_passage() -> None:
    """A 35 cm gap in a 15 cm wall at x 400 (gap y 300..335): a rover stopped 5 cm into
    it, off its middle, is in a passage, as is one whose nose just reached the mouth."""
    gap = gap_blocked_nav(3.0).map
    assert in_passage(gap, Pose(395.0, 312.5, 0.0), 10.0)
    assert in_passage(gap, Pose(392.0, 317.5, 0.0), 10.0)
    assert not in_passage(gap, Pose(300.0, 317.5, 0.0), 10.0)


# ---------------------------------------------------------------- a corridor's mouth
def own_pose_at_block(body: Body, k: int, blocks: Blocks) -> Pose:
    """Motor Control's pose (the rover's own frame) when block ``k`` ended its move."""
    t = blocks.at[k][0]
    return next(p for tp, p in body.published if tp >= t - 1e-9)


class Mouth(Blocks):
    """A mouth the rover meets off its believed place: a forward move whose centre
    crosses own x ``face`` is blocked there unless it crosses with own y in ``passes``
    (the lateral band from which the body gets through); other moves go as commanded."""

    def __init__(self, face: float, passes: tuple[float, float]) -> None:
        super().__init__()
        self.face, self.passes = face, passes

    def __call__(self, pose: Pose, cm: float) -> tuple[float, float] | None:
        assert self.body is not None
        c, sn = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
        if cm <= 0 or c <= 1e-6 or pose.x >= self.face or pose.x + cm * c < self.face:
            return None
        done = (self.face - pose.x) / c
        lo, hi = self.passes
        if lo <= pose.y + done * sn <= hi:
            return None
        self.at.append((trio.current_time(), len(self.body.sent), len(self.body.motor_log)))
        return done, 0.0


@pytest.mark.trio
async def test_a_rover_off_a_corridors_mouth_probes_both_sides_and_gets_through(
        autojump_clock) -> None:
    """The mouth lies right of where the rover believes: it passes only from own y 88 to
    96, and it arrives on y 99 and meets the face beside the mouth at own x 190 (map
    240). Nothing is learned as an obstacle (every back-off is the short 6 cm: an
    obstacle would close the mouth); the rover tries the left of the place it met the
    face first (the side the belief's contact fix and the series start with), then the
    right, and gets through and drives on down the corridor."""
    mouth = Mouth(190.0, (88.0, 96.0))
    body = await drive_corridor(mouth, after_s=60.0)  # no scripted blocks: the mouth's
    assert any(p.x > 400.0 for _, p in body.published)
    blocks = [own_pose_at_block(body, k, mouth) for k in range(len(mouth.at))]
    first = blocks[0]
    assert first.x == pytest.approx(190.0, abs=1.0) and first.y == pytest.approx(99.2, abs=1.0)
    assert any(b.y > first.y + 2.0 for b in blocks[1:])
    through = next(p for _, p in body.published if p.x > 200.0)
    assert 88.0 <= through.y <= 96.0
    assert all(v == -6.0 for c, v in body.motor_log if c == "MOTOR_MOVE" and v < 0)
    assert len(blocks) <= 6


async def ended(nav: Any, commands: list[Motion], own: Pose) -> None:
    """The last motion navigation commanded ended where Motor Control's dead reckoning
    says ``own`` (own frame): navigation decides its next step from there."""
    nav.last_motion, nav.motion_from = commands[-1], nav.map_pose
    nav.pose = own
    await nav.after_motion(False, commands[-1].amount)


@pytest.mark.trio
async def test_probe_points_are_held_in_the_rovers_own_frame(autojump_clock,
                                                              monkeypatch) -> None:
    """The hider is blocked twice at own (190, 100) (map (240, 150), 10 cm before the
    corridor's mouth) and backs off to own (184, 100) each time. The contacts move its
    belief: the origin (map -> own frame) shifts over 5 cm across the corridor, so the
    pose it reports is that far off dead reckoning. The second block starts a probe of
    the mouth drawn from the first block, held in the rover's own frame: a sidestep
    square to the block's heading (turn 90, move the series' first offset of 12 cm, turn
    back) and on along the shifted line through the mouth. Held in the map frame, the
    probe would have moved with the belief, and the sidestep with it."""
    nav = scraped_nav(0.0, sigma_cm=5.0)
    commands = commands_of(nav, monkeypatch)

    async def set_state(state: str, detail: str | None = None) -> None:
        pass

    monkeypatch.setattr(nav, "set_state", set_state)
    nav.pose = Pose(150.0, 100.0, 0.0)
    assert await nav.goto((600.0, 150.0), None)
    for _ in range(2):
        nav.pose, nav.last_motion = Pose(190.0, 100.0, 0.0), Motion("move", 20.0)
        nav.motion_from = Pose(220.0, 150.0, 0.0)
        await nav.blocked_route("blocked")
        assert commands[-1] == Motion("move", -nav.o.backoff_cm)
        await ended(nav, commands, Pose(184.0, 100.0, 0.0))
    assert abs(nav.pose_data()["y"] - 150.0) > 5.0  # the belief moved across
    assert commands[-1] == Motion("turn", pytest.approx(90.0))
    await ended(nav, commands, Pose(184.0, 100.0, 90.0))
    assert commands[-1] == Motion("move", pytest.approx(12.0))
    await ended(nav, commands, Pose(184.0, 112.0, 90.0))
    assert commands[-1] == Motion("turn", pytest.approx(-90.0))
    await ended(nav, commands, Pose(184.0, 112.0, 0.0))
    assert commands[-1] == Motion("move", 20.0)
    await ended(nav, commands, Pose(204.0, 112.0, 0.0))
    assert commands[-1] == Motion("move", 20.0)  # on the line: through the mouth
    assert at_mouth(nav.map, Pose(240.0, 150.0, 0.0), 10.0)
    assert not at_mouth(nav.map, Pose(300.0, 150.0, 0.0), 10.0)  # inside: not a mouth


LONG_CORRIDOR = Truth(0, 0, 1000, 300, boxes=((150, 0, 650, 135), (150, 165, 650, 135)))
"""A 6.5 m corridor (map x 150..800), 30 cm wide like the short one."""


@pytest.mark.trio
async def test_scrapes_all_along_a_long_passage_do_not_use_up_the_route(autojump_clock) -> None:
    """Blocked every 45 cm along a 6.5 m passage (a scrape of its side wall, 3 deg yaw
    each): 13 blocks, more than `REPLAN_LIMIT`, but each after the route got nearer its
    goal, so the count starts afresh and the hider drives out of the far end and
    arrives; the same blocks at one place would give the route up."""
    scrapes = [(120.0 + 45.0 * k, 3.0 if k % 2 else -3.0) for k in range(13)]
    assert len(scrapes) > REPLAN_LIMIT
    blocks = Blocks(*scrapes)
    body = Body(script=blocks)
    blocks.body = body
    await drive_until_answered(body, 900.0, LONG_CORRIDOR)
    assert len(blocks.at) == len(scrapes)
    assert body.frames("invalid_spot") == [], body.frames("invalid_spot")
    assert body.frames("arrived")
