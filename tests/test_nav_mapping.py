"""Mapping navigation: explores to completion by itself, stops, uploads; stop and stall cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from actors import BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import LidarHealth
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.mapper import MappingNav, MappingOptions
from actors.firmware.origin_wire import length_pair
from server.protocol.grid_map import FREE, OCCUPIED, UNKNOWN, GridMap
from tests.test_nav_common import Body, Truth, net, rover_spec, wait_for

# own frame = map frame; the rover starts at (0, 0) in a 4.5 x 2.5 m room split by a wall
# (x 150..165) with a 60 cm doorway at the top, and a box in the far half
ROOM = dict(x0=-50, y0=-50, x1=400, y1=200, boxes=((150, -50, 15, 190), (260, 20, 40, 40)))


def coverage(grid: GridMap, truth: Truth) -> float:
    """Share of free truth cells (more than 15 cm from any wall) the map knows."""
    ny, nx = truth.solid.shape
    rows, cols = np.nonzero(~truth.solid)
    xs = truth.origin[0] + (cols + 0.5) * truth.res
    ys = truth.origin[1] + (rows + 0.5) * truth.res
    keep = np.array([truth.clear(x, y, 15.0) for x, y in zip(xs, ys, strict=True)])
    known = 0
    for x, y in zip(xs[keep], ys[keep], strict=True):
        r, c = grid.world_to_cell(x, y)
        known += grid.contains(r, c) and grid.cells[r, c] != UNKNOWN
    return known / int(keep.sum())


@pytest.mark.trio
async def test_mapper_explores_detects_completion_and_uploads(autojump_clock) -> None:
    """Start -> LIDAR on -> exploring -> complete by itself -> home -> motor and LIDAR
    stop -> map."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    farthest = [0.0]

    async def watch_x() -> None:
        while True:
            farthest[0] = max(farthest[0], body.pose.x)
            await trio.sleep(0.5)

    async with open_actor_system(seed=1) as system, trio.open_nursery() as nursery:
        nursery.start_soon(watch_x)
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "origin", {"x": 0.0, "y": 0.0, "heading": 0.0})
        await net(system, pool, "mapper", "start")
        assert await wait_for(lambda: any(c == "WIFLY_SEND_MAP" for c, _ in body.sent), 600.0)
        t_done = trio.current_time()
        nursery.cancel_scope.cancel()
        grid = next(o for c, o in body.sent if c == "WIFLY_SEND_MAP")
        assert body.lidar_log[0] == "LIDAR_START" and body.lidar_log[-1] == "LIDAR_STOP"
        assert body.motor_log[-1][0] == "MOTOR_STOP"
        assert coverage(grid, truth) >= 0.95
        assert farthest[0] > 165.0  # it went through the doorway to see the far half
        assert math.hypot(body.pose.x, body.pose.y) <= 20.0  # and came back to its start
        states = [f.data["state"] for f in body.frames("status")]
        assert states[-4:] == ["exploring", "homing", "uploading", "mapped"]
        assert "map is stable" in body.frames("status")[-1].data["detail"]
        assert t_done < 600.0


@pytest.mark.trio
async def test_homing_disabled_uploads_where_the_mapper_stands(autojump_clock) -> None:
    """``home_budget_s=0``: completion uploads at once, the rover stays where it was."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    options = MappingOptions(home_budget_s=0.0)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool, mapping=options),
                                      "mapper")
        await net(system, pool, "mapper", "start")
        assert await wait_for(lambda: any(c == "WIFLY_SEND_MAP" for c, _ in body.sent), 600.0)
        states = [f.data["state"] for f in body.frames("status")]
        assert "homing" not in states and states[-2:] == ["uploading", "mapped"]
        assert math.hypot(body.pose.x, body.pose.y) > 50.0
        # the map marks the mapper's body where it stays parked, though no scan saw it
        grid = next(o for c, o in body.sent if c == "WIFLY_SEND_MAP")
        assert grid.cells[grid.world_to_cell(body.pose.x, body.pose.y)] == OCCUPIED


def _motions(body: Body) -> int:
    return sum(c in ("MOTOR_MOVE", "MOTOR_TURN") for c, _ in body.motor_log)


@pytest.mark.trio
async def test_stalled_lidar_never_reads_as_complete(autojump_clock) -> None:
    """No scans arriving (LIDAR dead): no upload even though the map does not change, and
    the rover holds still (no Command A) saying the LIDAR is silent."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "start")
        assert await wait_for(lambda: body.frames("status")
                              and body.frames("status")[-1].data["state"] == "exploring", 30.0)
        body.lidar_on = False  # the LIDAR stalls: no more scans
        await trio.sleep(5.0)  # silence is noticed, a motion in flight ends
        moved = _motions(body)
        await trio.sleep(50.0)
        assert not any(c == "WIFLY_SEND_MAP" for c, _ in body.sent)
        assert _motions(body) == moved
        last = body.frames("status")[-1].data
        assert last["state"] == "lidar_fault" and "silent" in last["detail"]


@pytest.mark.trio
async def test_a_lidar_dead_after_the_room_was_seen_still_lets_the_map_complete(
        autojump_clock) -> None:
    """A room one spot sees whole, the LIDAR dead after its first scans: the rover holds
    while it is silent; once the hold gives up (``lidar_pause_s``) its map, with no useful
    frontier left, is complete and uploads. A silent LIDAR never completes a map while
    navigation holds for it."""
    truth = Truth(x0=-50, y0=-60, x1=150, y1=60)
    body = Body(truth=truth)
    pool = BufferPool(256)
    options = MappingOptions(lidar_pause_s=15.0, home_budget_s=0.0)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool, mapping=options),
                                      "mapper")
        await net(system, pool, "mapper", "start")
        assert await wait_for(lambda: body.frames("status")
                              and body.frames("status")[-1].data["state"] == "exploring", 30.0)
        await trio.sleep(4.0)  # a few revolutions from where it stands
        body.lidar_on = False
        await trio.sleep(4.0)  # silent, and held: no upload while it holds
        assert not any(c == "WIFLY_SEND_MAP" for c, _ in body.sent)
        assert await wait_for(lambda: any(c == "WIFLY_SEND_MAP" for c, _ in body.sent), 120.0)
        details = [f.data.get("detail", "") for f in body.frames("status")]
        assert any("driving on" in d for d in details)
        grid = next(o for c, o in body.sent if c == "WIFLY_SEND_MAP")
        assert coverage(grid, truth) >= 0.9


@pytest.mark.trio
async def test_silent_lidar_pause_ends_when_scans_return(autojump_clock) -> None:
    """A LIDAR silent for 10 s: the rover holds still, then explores on to an upload."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "start")
        await trio.sleep(8.0)
        body.lidar_on = False
        await trio.sleep(3.0)
        moved = _motions(body)
        await trio.sleep(7.0)
        assert _motions(body) == moved
        body.lidar_on = True
        assert await wait_for(lambda: any(c == "WIFLY_SEND_MAP" for c, _ in body.sent), 600.0)
        assert _motions(body) > moved
        details = [f.data.get("detail", "") for f in body.frames("status")]
        assert any(d.startswith("LIDAR recovered after") for d in details)


@pytest.mark.trio
async def test_lidar_fault_verdict_holds_the_rover_until_healthy(autojump_clock) -> None:
    """NAV_LIDAR_HEALTH stuck: no Command A while it lasts (scans still counted), and
    exploring goes on after NAV_LIDAR_HEALTH ok."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "start")
        await trio.sleep(8.0)
        await system.send("mapper/nav", Message.int(Cmd.NAV_LIDAR_HEALTH, LidarHealth.STUCK))
        await trio.sleep(3.0)
        moved = _motions(body)
        assert body.frames("status")[-1].data["detail"].startswith("LIDAR stuck")
        await trio.sleep(20.0)
        assert _motions(body) == moved
        await system.send("mapper/nav", Message.int(Cmd.NAV_LIDAR_HEALTH, LidarHealth.OK))
        await trio.sleep(5.0)
        assert _motions(body) > moved


@pytest.mark.trio
async def test_lidar_fault_outlasting_the_pause_is_driven_through(autojump_clock) -> None:
    """A fault longer than ``lidar_pause_s``: the rover holds that long, then drives on."""
    truth = Truth(**ROOM)
    body = Body(truth=truth)
    pool = BufferPool(256)
    options = MappingOptions(lidar_pause_s=20.0)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool, mapping=options),
                                      "mapper")
        await net(system, pool, "mapper", "start")
        await trio.sleep(8.0)
        await system.send("mapper/nav", Message.int(Cmd.NAV_LIDAR_HEALTH, LidarHealth.NOISY))
        await trio.sleep(3.0)
        moved = _motions(body)
        await trio.sleep(15.0)
        assert _motions(body) == moved
        await trio.sleep(10.0)
        assert _motions(body) > moved
        details = [f.data.get("detail", "") for f in body.frames("status")]
        assert "LIDAR still faulty after 20 s: driving on" in details


@pytest.mark.trio
async def test_server_stop_uploads_what_is_known(autojump_clock) -> None:
    """``stop`` mid-exploration: motor and LIDAR stop and the partial map is uploaded."""
    body = Body(truth=Truth(**ROOM))
    pool = BufferPool(256)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "start")
        await trio.sleep(5.0)
        await net(system, pool, "mapper", "stop")
        assert await wait_for(lambda: any(c == "WIFLY_SEND_MAP" for c, _ in body.sent), 5.0)
        assert body.lidar_log[-1] == "LIDAR_STOP"
        assert "stopped by the server" in body.frames("status")[-1].data["detail"]


def test_futile_trips_count_whole_visits_and_end_exploration(monkeypatch) -> None:
    """A trip runs until its target is reached or given up, whatever the frontiers chosen on
    the way; after ``FUTILE_TRIPS`` visits that together made fewer than
    ``FUTILE_TRIPS * MIN_GAIN_CELLS`` cells known, exploration counts the frontiers left
    as not useful."""
    from actors.firmware.nav import exploration

    monkeypatch.setattr(exploration, "FUTILE_TRIPS", 3)
    nav = make_nav("mapper", pool=BufferPool(4))
    assert exploration.MIN_GAIN_CELLS == 30
    cells = np.full((40, 40), UNKNOWN, dtype=np.int8)
    known = [0]

    def show(n: int) -> None:  # the map now knows n cells
        c = cells.copy()
        c.reshape(-1)[:n] = 0
        nav.grid = GridMap(c, 5.0, (0.0, 0.0))
        known[0] = n

    show(100)
    for gain in (500, 10, 20):
        nav.ex.trip_known = known[0]
        show(known[0] + gain // 2)
        show(known[0] + gain - gain // 2)  # the map grows while the rover drives...
        nav.ex.target = (1.0, 2.0)
        nav.explorer.blacklist((1.0, 2.0))  # ...and the visit ends (given up)
    assert nav.ex.gains == [500, 10, 20]
    assert not exploration.futile(nav.ex.gains, known[0])  # the 500-cell visit counts
    nav.ex.trip_known = known[0]
    show(known[0] + 5)
    nav.ex.target = (3.0, 4.0)
    nav.explorer.blacklist((9.0, 9.0))  # another point: the visit goes on...
    assert nav.ex.gains == [500, 10, 20]  # ...(ended, its 5 cells would push the 500 out)
    nav.explorer.blacklist((3.0, 4.0))
    assert nav.ex.gains == [10, 20, 5]
    assert exploration.futile(nav.ex.gains, known[0])  # 35 cells: fewer than 3 x 30



def test_the_least_useful_gain_grows_with_the_map(monkeypatch) -> None:
    """In a big map a visit must reveal 0.3 % of what is known to count: 60 cells of
    30000 known is futile, though more than ``MIN_GAIN_CELLS``."""
    from actors.firmware.nav import exploration

    monkeypatch.setattr(exploration, "FUTILE_TRIPS", 2)
    assert exploration.min_gain(30000) == 90.0
    assert exploration.futile([60, 60], 30000)
    assert not exploration.futile([60, 60], 3000)  # a small map: 60 cells count
    assert not exploration.futile([60, 120], 30000)
    assert not exploration.futile([60], 30000)  # one visit is no window yet


def test_one_visit_just_above_the_limit_does_not_restart_the_futile_count() -> None:
    """The window is judged on its sum: visits of 21, 7, 4 and 34 cells
    (limit 32: 34 alone is above it) are futile together, so mapping ends."""
    from actors.firmware.nav import exploration

    assert exploration.FUTILE_TRIPS == 4
    assert exploration.futile([21, 7, 4, 34], 10785)
    assert exploration.futile([500, 21, 7, 4, 34], 10785)  # the window: the last four
    assert not exploration.futile([21, 7, 4, 120], 10785)  # a visit that found an opening


def _walled_room(gaps: dict[str, int], known_outside: int = 0) -> GridMap:
    """A 3 x 3 m free room around the origin walled in, with openings to the unknown:
    ``gaps`` maps a side ("west", "east") to an opening's length [cells];
    ``known_outside`` cells far outside the walls are known (occupied)."""
    cells = np.full((80, 80), UNKNOWN, dtype=np.int8)
    cells.reshape(-1)[:known_outside] = OCCUPIED  # the first rows, south of the walls
    cells[10:70, 10:70] = OCCUPIED
    cells[11:69, 11:69] = FREE
    for side, n in gaps.items():
        col = 10 if side == "west" else 69
        cells[40 - n // 2:40 - n // 2 + n, col] = FREE  # a gap, unknown beyond it
    return GridMap(cells, 5.0, (-200.0, -200.0))


@pytest.mark.trio
async def test_after_futile_visits_only_viewpoints_worth_the_whole_window_count(
        autojump_clock, monkeypatch) -> None:
    """Futile visits raise the least gain to what the futile window together should have
    shown: after two visits given up with nothing made known, a small opening is
    dismissed, a big one (a room's unseen part) still chosen, and a fruitful visit lets
    the small one count again."""
    from actors.firmware.nav import exploration

    monkeypatch.setattr(exploration, "FUTILE_TRIPS", 2)
    monkeypatch.setattr(exploration, "MIN_GAIN_CELLS", 200)
    nav = make_nav("mapper", pool=BufferPool(4))
    small = _walled_room({"west": 8})  # viewpoints reveal about 290 cells
    both = _walled_room({"west": 8, "east": 40})  # the east opening: about 700
    nav.grid = small
    assert nav.explorer.choose(keep=False) and nav.ex.target[0] < 0.0  # it counts
    nav.grid = both
    for _ in range(2):  # two visits given up, the map unchanged
        assert nav.explorer.choose(keep=False)
        nav.explorer.blacklist(nav.ex.target)
    assert nav.ex.gains == [0, 0]
    assert all(b[0] > -100.0 for b in nav.ex.blacklist)  # the small opening's not among them
    nav.grid = small
    assert not nav.explorer.choose(keep=False) and nav.ex.no_frontier  # less than 2 x 200
    nav.grid = both
    assert nav.explorer.choose(keep=False) and nav.ex.target[0] > -100.0
    nav.grid = _walled_room({"west": 8, "east": 40}, known_outside=500)
    nav.explorer.blacklist(nav.ex.target)  # a fruitful visit...
    assert nav.ex.gains == [0, 500]
    nav.grid = small
    assert nav.explorer.choose(keep=False) and nav.ex.target[0] < 0.0  # ...counts it again


@pytest.mark.trio
async def test_map_stability_counts_net_growth_not_edge_flicker(autojump_clock,
                                                                 monkeypatch) -> None:
    """Cells flickering between unknown and known (scan matching's jitter at rest) leave the
    map stable; the known area growing is a change."""
    from actors.firmware.nav import mapper

    monkeypatch.setattr(mapper, "CHANGE_SHARE", 0.0)  # the threshold: CHANGE_CELLS (3)
    assert mapper.CHANGE_CELLS == 3
    nav = make_nav("mapper", pool=BufferPool(4))
    base = _walled_room({})
    await nav.on_map_update(base)
    t0 = nav.changed_at
    await trio.sleep(5.0)
    for k in range(6):  # ten edge cells go unknown and ten others come back, each time
        cells = base.cells.copy()
        cells[11:21, 11 + k] = UNKNOWN
        cells[0, 10 * k:10 * k + 10] = FREE
        await nav.on_map_update(GridMap(cells, 5.0, base.origin_cm))
    assert nav.changed_at == t0
    grown = base.cells.copy()
    grown[0:5, 0:10] = FREE  # 50 new cells known
    await nav.on_map_update(GridMap(grown, 5.0, base.origin_cm))
    assert nav.changed_at == t0 + 5.0


@pytest.mark.trio
@pytest.mark.parametrize(("value", "hold", "text"), [
    (1, 3.0, "the right tread is driven but does not count"),
    (2, 2.0, "the left tread counts short"),
    (6, 2.0, "both treads count short"),
    (4, 3.0, "both treads are driven but do not count")],
    ids=["right-silent", "left-short", "both-short", "both-silent"])
async def test_a_tread_fault_from_motor_stops_and_holds_the_rover(autojump_clock, monkeypatch,
                                                                   value, hold, text) -> None:
    """NAV_TREAD_FAULT during a move (Motor Control: the right tread is driven but does
    not count; the left, or both, count short): MOTOR_STOP at once, though the pose shows
    nothing yet, no Command A for the hold (``ODO_HOLD_S``; ``SHORT_HOLD_S`` for counting
    short), an ``odometry_fault`` status naming the fault, then exploring goes on. Every
    report is relayed to Map Management with Motor Control's drive model of the stopped
    motion (MAP_TREAD_FAULT: its pose belief widens by it)."""
    import tests.test_nav_common as common

    class StuckEncoderMotor(common.FakeMotor):
        faults = 1

        async def handle(self, message: Message) -> None:
            if message.command == Cmd.MOTOR_MOVE and StuckEncoderMotor.faults > 0:
                StuckEncoderMotor.faults -= 1
                self.body.motor_log.append((Cmd(message.command).name, float(message.value)))
                self.ctx.send_nowait(self.nav, Message.uint(Cmd.NAV_TREAD_FAULT, value))
                return  # the move never ends by itself: only the stop ends it
            if message.command == Cmd.MOTOR_STOP:  # its drive model of the stopped move
                self.ctx.send_nowait(self.nav, length_pair(Cmd.NAV_TREAD_DRIVEN, 5.0, 5.0))
            await super().handle(message)

    monkeypatch.setattr(common, "FakeMotor", StuckEncoderMotor)
    body = Body(truth=Truth(**ROOM))
    pool = BufferPool(256)
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(rover_spec("mapper", body, pool), "mapper")
        await net(system, pool, "mapper", "start")
        assert await wait_for(lambda: StuckEncoderMotor.faults == 0, 120.0)
        t_fault = trio.current_time()
        assert await wait_for(lambda: body.frames("status")[-1].data["state"]
                              == "odometry_fault", 0.5)
        assert await wait_for(lambda: body.motor_log[-1][0] == "MOTOR_STOP", 0.5)
        moved = _motions(body)
        await trio.sleep(t_fault + hold - 0.5 - trio.current_time())
        assert _motions(body) == moved  # holding
        assert await wait_for(lambda: _motions(body) > moved, 10.0)
        details = [f.data.get("detail", "") for f in body.frames("status")]
        assert any(d.startswith(f"{text}; holding {hold:.0f} s") for d in details)
        assert "odometry hold over: driving on" in details
        assert "MAP_TREAD_FAULT" in body.map_msgs


def test_turning_away_from_an_obstacle_again_and_again_blacklists_the_target(
        monkeypatch) -> None:
    """A route the obstacle check refuses to drive (the rover would turn toward it, be
    refused and turn away for minutes): after ``OBSTACLE_TURNS`` turns away toward
    one target the target is blacklisted and the trip ends (its 10 cells count as a
    visit: with a window of one visit, exploration turns futile); another target
    starts over."""
    from actors.firmware.nav import exploration

    assert exploration.OBSTACLE_TURNS == 3
    monkeypatch.setattr(exploration, "FUTILE_TRIPS", 1)
    nav = make_nav("mapper", pool=BufferPool(4))
    cells = np.full((40, 40), UNKNOWN, dtype=np.int8)
    cells.reshape(-1)[:100] = 0
    nav.grid = GridMap(cells, 5.0, (0.0, 0.0))
    nav.ex.trip_known = 90
    nav.ex.target = (462.5, -32.5)
    assert not nav.explorer.turned_away() and not nav.explorer.turned_away()
    nav.ex.target = (100.0, 100.0)  # another frontier: the count starts over
    assert not nav.explorer.turned_away()
    nav.ex.target = (462.5, -32.5)
    assert not nav.explorer.turned_away() and not nav.explorer.turned_away()
    assert nav.ex.gains == []  # the trip goes on
    nav.ex.target = (460.0, -30.0)  # the same frontier, its target moved a little
    assert nav.explorer.turned_away()  # blacklisted
    assert nav.ex.gains == [10]  # the visit ended...
    assert exploration.futile(nav.ex.gains, 100)  # ...with 10 cells, fewer than 30


def test_the_mapper_steers_and_plans_home_from_its_map_frame_pose() -> None:
    """Odometry at its start (0, 0) @ 0, the origin (scan matching's correction) putting
    the rover at (40, 0) in the map: the obstacle check sees the wall 30 cm ahead in the
    map (a 30 cm move is cut to 10; odometry alone would see it 70 cm off and drive all
    30), and homing finds a route back to the map's (0, 0) (odometry alone would say it
    is home: no route)."""
    from actors.firmware.nav.route import Motion
    from server.protocol.pose import Pose

    nav = make_nav("mapper", pool=BufferPool(4))
    cells = np.full((40, 60), FREE, dtype=np.int8)  # x -100..200, y -100..100
    cells[:, 34] = OCCUPIED  # the wall x 70..75
    nav.grid = GridMap(cells, 5.0, (-100.0, -100.0))
    nav.pose, nav.pose_known = Pose(0.0, 0.0, 0.0), True
    nav.set_origin(Pose(40.0, 0.0, 0.0))
    assert nav.memory.origin == (40.0, 0.0, 0.0)
    shortened = nav.explorer.mind_the_obstacle(Motion("move", 30.0))
    assert shortened.amount == pytest.approx(10.0, abs=2.6)
    assert nav.homing.plan_home()
    nav.set_origin(Pose(0.0, 0.0, 0.0))
    assert not nav.homing.plan_home()  # at the map's (0, 0): home


def test_the_mapper_drives_a_passage_mapped_four_cells_wide() -> None:
    """A 25-30 cm passage maps as four free cells (each wall's face lies in a cell marked
    occupied); the narrowest tier routes along one of the middle two, 7.5 cm from one
    wall's cells. A move along it, and one 2 cm nearer that wall, is driven in full; a
    wall across the passage ahead still shortens the move."""
    from actors.firmware.nav.route import Motion
    from server.protocol.pose import Pose

    nav = make_nav("mapper", pool=BufferPool(4))
    cells = np.full((40, 60), FREE, dtype=np.int8)  # x -100..200, y -100..100
    cells[:20, 20:40] = OCCUPIED  # y < 0, x 0..100
    cells[24:, 20:40] = OCCUPIED  # y >= 20: free cells y 0..20 between
    nav.grid = GridMap(cells, 5.0, (-100.0, -100.0))
    nav.pose, nav.pose_known = Pose(-20.0, 7.5, 0.0), True
    nav.set_origin(Pose(0.0, 0.0, 0.0))
    assert nav.explorer.mind_the_obstacle(Motion("move", 30.0)) == Motion("move", 30.0)
    nav.pose = Pose(30.0, 5.5, 0.0)  # inside, 2 cm off the route toward the wall
    assert nav.explorer.mind_the_obstacle(Motion("move", 30.0)) == Motion("move", 30.0)
    cells[20:24, 32] = OCCUPIED  # a wall across the passage at x 60..65, 32.5 cm ahead
    nav.grid = GridMap(cells, 5.0, (-100.0, -100.0))
    assert nav.explorer.mind_the_obstacle(Motion("move", 30.0)) == Motion("move", 12.5)


def _homing_nav() -> MappingNav:
    """A mapper going home at (0, 0) @ 0 on free floor (x, y -100..100, 5 cm cells)."""
    from server.protocol.pose import Pose

    nav = make_nav("mapper", pool=BufferPool(4))
    _set_column(nav, None, FREE)
    nav.pose, nav.pose_known = Pose(0.0, 0.0, 0.0), True
    nav.set_origin(Pose(0.0, 0.0, 0.0))
    nav.state = "homing"
    return nav


def _set_column(nav: MappingNav, col: int | None, value: int) -> None:
    """The mapper's map with one column of cells (``col``, x from -100 + 5 col) set to
    ``value`` (None: every cell)."""
    cells = np.full((40, 40), FREE, dtype=np.int8) if nav.grid is None else \
        nav.grid.cells.copy()
    if col is None:
        cells[:] = value
    else:
        cells[:, col] = value
    nav.grid = GridMap(cells, 5.0, (-100.0, -100.0))


def test_a_move_blocked_with_nothing_mapped_at_its_leading_edge_is_blocked_in_the_open(
) -> None:
    """Both encoders stuck end a move blocked as a wall would: the map tells them apart. A
    move (forward or back) blocked with free floor and no mapped obstacle within
    ``CONTACT_CELLS`` of its leading edge met nothing; a wall there, or unknown cells
    there, may have stopped it. A turn that counted nothing is blocked in the open, one
    that counted some turning is not."""
    from actors.firmware.nav.route import Motion
    from actors.firmware.nav.sensor_watch import CONTACT_CELLS

    assert CONTACT_CELLS == 2
    nav = _homing_nav()
    nav.last_motion = Motion("move", 20.0)
    assert nav.watch.blocked_in_the_open(12.0)
    _set_column(nav, 23, OCCUPIED)  # a wall x 15..20: 5 cm before the front (x 10)
    assert not nav.watch.blocked_in_the_open(12.0)
    nav.last_motion = Motion("move", -6.0)  # backing off: the rear is the leading edge
    assert nav.watch.blocked_in_the_open(0.0)
    _set_column(nav, 16, UNKNOWN)  # x -20..-15, just behind the rear (x -10)
    assert not nav.watch.blocked_in_the_open(0.0)
    _set_column(nav, 16, FREE)
    _set_column(nav, 23, FREE)
    _set_column(nav, 25, OCCUPIED)  # x 25..30: 15 cm before the front, out of reach
    nav.last_motion = Motion("move", 20.0)
    assert nav.watch.blocked_in_the_open(12.0)
    nav.last_motion = Motion("turn", 30.0)
    assert nav.watch.blocked_in_the_open(0.0)
    assert not nav.watch.blocked_in_the_open(4.0)


@pytest.mark.trio
async def test_homing_holds_for_odometry_instead_of_counting_a_block_in_the_open(
        autojump_clock, monkeypatch) -> None:
    """Going home, a move blocked in the open holds (an odometry fault) instead of backing
    off blind and counting toward ``HOME_BLOCKS``: with both encoders stuck, three such
    blocks would upload the map from wherever the mapper stands. A block at a mapped
    wall backs off and counts as before; once the holds have doubled to the longest, a
    block in the open counts too. Observed through what navigation says and commands."""
    from actors.firmware.nav.homing import HOME_BLOCKS
    from actors.firmware.nav.route import Motion
    from actors.firmware.nav.sensor_watch import ODO_HOLD_S

    nav = _homing_nav()
    said: list[tuple[str, str | None]] = []
    commands: list[Motion] = []

    async def status(state: str, detail: str | None = None, **extra: object) -> None:
        said.append((state, detail))

    async def stop_motor() -> None:
        pass

    async def command(motion: Motion) -> None:
        commands.append(motion)

    def holds() -> int:
        return sum(state == "odometry_fault" for state, _ in said)

    monkeypatch.setattr(nav, "status", status)
    monkeypatch.setattr(nav, "stop_motor", stop_motor)
    async def finish(reason: str, **_: object) -> None:
        said.append(("finish", reason))

    monkeypatch.setattr(nav, "command", command)
    monkeypatch.setattr(nav, "finish", finish)
    nav.last_motion = Motion("move", 20.0)
    await nav.after_motion(True, 14.0)
    assert holds() == 1 and commands == []  # held: no back-off, not counted
    await trio.sleep(ODO_HOLD_S + 0.1)  # the hold ends
    _set_column(nav, 23, OCCUPIED)  # a wall at the front: a real block
    await nav.after_motion(True, 14.0)
    backoff = Motion("move", -nav.o.backoff_cm)
    assert holds() == 1 and commands == [backoff]  # backed off: counted
    _set_column(nav, 23, FREE)
    for strike in (2, 3, 4):  # more blocks in the open: each hold twice the last
        await nav.after_motion(True, 14.0)
        assert holds() == strike and commands == [backoff]
        await trio.sleep(ODO_HOLD_S * 2 ** (strike - 1) + 0.1)
    await nav.after_motion(True, 14.0)  # held the longest already: it counts
    assert holds() == 4 and commands == [backoff, backoff]
    assert HOME_BLOCKS == 3 and not [d for s, d in said if s == "finish"]
    await nav.after_motion(True, 14.0)  # the third block counted: home is given up
    assert said[-1] == ("finish", f"{nav.finish_reason}; home blocked")
