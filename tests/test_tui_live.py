"""The console's live system: the truth overlay's registration, attached rovers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio
import trio.testing

from server.links import parse_link
from server.protocol import Pose, inverse
from server.protocol import compose as compose_pose
from tui.activity import fault_text
from tui.live import LiveSystem
from tui.snapshot import FREE, OCCUPIED, GridView
from tui.widgets.map_pixels import classify
from world.scenario import load_scenario

_MISSED, _FALSE = 6, 7  # map_view classes: obstacle mapped free, free mapped occupied


def _one_cell_room(tmp_path, heading: float):
    """A room whose only obstacle is exactly one 5 cm truth cell: x 200..205, y 150..155."""
    path = tmp_path / "cell.toml"
    path.write_text(f"""
name = "cell"
[room]
size_cm = [400, 300]
[[obstacles]]
box = [200, 150, 5, 5]
[rovers]
mapper = [100, 50, {heading}]
hider = [50, 250, 0]
seeker = [350, 250, 0]
""")
    return load_scenario(str(path))


@pytest.mark.parametrize("heading", [0, 90, 180, 270])
def test_truth_overlay_puts_an_obstacle_on_the_mappers_cell_for_it(tmp_path, heading) -> None:
    """The mapper's occupied cell for a one-cell obstacle and the truth's cell coincide:
    same grid cell, and on screen no pixel reads "obstacle mapped free" or "free mapped
    occupied" (a one-cell offset would show both)."""
    scenario = _one_cell_room(tmp_path, heading)
    live = LiveSystem(scenario)
    s = scenario.starts["mapper"]
    live._mapper_room = Pose(s.x, s.y, s.heading_deg)
    res, origin = 5.0, (-400.0, -400.0)
    cells = np.full((160, 160), FREE, np.int8)
    centre = compose_pose(inverse(live._mapper_room), Pose(202.5, 152.5, 0.0))  # map frame
    row = math.floor((centre.y - origin[1]) / res)
    col = math.floor((centre.x - origin[0]) / res)
    cells[row, col] = OCCUPIED
    grid = GridView(cells, res, origin)

    truth = live._truth_view(grid)

    assert truth is not None and truth.shape == grid.shape and truth.origin_cm == origin
    near = np.zeros(grid.shape, bool)  # 7 x 7 cells around it, all inside the room
    near[row - 3:row + 4, col - 3:col + 4] = True
    assert np.argwhere((truth.cells == OCCUPIED) & near).tolist() == [[row, col]]
    # the screen: sample 4 points per cell around the obstacle, as the map view does
    xs, ys = np.meshgrid(origin[0] + (np.arange(col - 5, col + 6 + 0.01, 0.25)) * res,
                         origin[1] + (np.arange(row - 5, row + 6 + 0.01, 0.25)) * res)
    cls = classify(grid, truth, xs + 0.01, ys + 0.01)
    assert not np.isin(cls, [_MISSED, _FALSE]).any()


def test_attached_rover_links_are_checked() -> None:
    """A remote rover's ID is its role; tcp and udp need a listen address of their kind."""
    scenario = load_scenario("empty")
    with pytest.raises(ValueError, match="--rover m1: the ID of an attached rover is its role"):
        LiveSystem(scenario, remote={"m1": parse_link("tcp")})
    with pytest.raises(ValueError, match="a rover on tcp needs --listen tcp:HOST:PORT"):
        LiveSystem(scenario, remote={"mapper": parse_link("tcp")})
    with pytest.raises(ValueError, match=r"--rover ROLE=LINK must be tcp \(.*got 'sim'"):
        LiveSystem(scenario, remote={"mapper": parse_link("sim")})
    with pytest.raises(ValueError, match="--auto plays the simulated game"):
        LiveSystem(scenario, remote={"mapper": parse_link("/dev/ttyUSB0")}, auto=True)
    live = LiveSystem(scenario, remote={"mapper": parse_link("tcp:10.0.0.2:2000")})
    assert live.remote["mapper"].kind == "tcp_out"  # the console connects out to it
    with pytest.raises(ValueError, match="a rover on udp needs --listen udp:HOST:PORT"):
        LiveSystem(scenario, remote={"mapper": parse_link("udp")},
                   listen=[parse_link("tcp:127.0.0.1:7878")])
    live = LiveSystem(scenario, remote={"mapper": parse_link("udp")},
                      listen=[parse_link("udp:127.0.0.1:7878")])
    assert [s.kind for s in live.listen] == ["udp_in"]


def test_fault_events_read_as_sentences() -> None:
    """The world's fault trace details become one readable line each; others are left."""
    injected = ("fault_injected [('duration_s', 60.0), ('id', 1), ('kind', 'slipping'), "
                "('params', {'ratio': 0.5})]")
    assert fault_text("hider/encoder", injected) == (
        "slipping on hider/encoder ratio=0.5 for 60 s (w1)")
    scheduled = ("fault_injected [('duration_s', 0.0), ('id', 2), ('kind', 'dead'), "
                 "('params', {}), ('scheduled', True)]")
    assert fault_text("mapper/lidar", scheduled) == (
        "dead on mapper/lidar until cleared, scheduled (w2)")
    cleared = "fault_cleared [('id', 1), ('kind', 'slipping'), ('reason', 'expired')]"
    assert fault_text("hider/encoder", cleared) == "slipping on hider/encoder cleared (expired, w1)"
    assert fault_text("mapper/nav", "crash") == ""
    assert fault_text("mapper/nav", "fault_injected [broken") == ""


def test_with_an_attached_rover_time_is_real_and_speed_is_refused() -> None:
    """Speed and pause are refused with a reason while a rover is attached; x1 stays."""
    scenario = load_scenario("empty")
    live = LiveSystem(scenario, speed=16.0, remote={"mapper": parse_link("serial:/dev/x,9600")})
    assert live.clock.rate == 1.0
    results = []
    live._publish = results.append
    live._event = lambda kind, text: None

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(live._command_loop)
            live.set_speed(4.0)
            live.pause()
            await trio.testing.wait_all_tasks_blocked()
            nursery.cancel_scope.cancel()

    live._system = object()  # the refusals come before the system is touched
    trio.run(main)
    assert [(r.command, r.status) for r in results] == [
        ("set_speed", "refused"), ("pause", "refused")]
    assert results[0].reason == ("mapper attached over a link: simulated time runs at real "
                                 "time only (x1), no pause")
    assert live.clock.rate == 1.0


def test_world_lag_is_within_a_tick_when_the_machine_keeps_up() -> None:
    """In virtual time the world steps exactly on the clock: lag stays within one tick."""
    from server.store import Store
    from supervisors.system import open_sim_system

    lags = []

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_sim_system(load_scenario("empty"), seed=1, store=store) as system:
                for _ in range(20):
                    await trio.sleep(0.37)
                    lags.append(system.world_lag())

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert all(0.0 <= lag <= 0.05 + 1e-9 for lag in lags), lags


def test_message_log_decodes_the_latest_lines_when_a_snapshot_asks() -> None:
    """Tapped sends become decoded log lines, numbered in order, at most MAX_LOG_LINES,
    DROP marked; lines scrolled out before a snapshot are never decoded."""
    from actors import EventKind, Message, TraceEvent
    from actors.firmware.commands import Cmd
    from tui.snapshot import MAX_LOG_LINES

    live = LiveSystem(load_scenario("empty"))
    moves = [Message.float(Cmd.MOTOR_MOVE, float(i)) for i in range(MAX_LOG_LINES + 10)]
    for m in moves:
        live.activity.on_message(1.0, EventKind.SEND, "hider/motor", m, 1)
    lines = live.activity.log_lines()
    assert len(lines) == MAX_LOG_LINES
    assert [ln.seq for ln in lines] == list(range(11, MAX_LOG_LINES + 11))
    assert lines[-1].text == f"MOTOR_MOVE distance={MAX_LOG_LINES + 9} cm"
    live.activity.on_trace(TraceEvent(2.0, EventKind.DROP, "mapper/map", "mapper/map",
                                       repr(Message.int(Cmd.NOOP, 0))))
    lines = live.activity.log_lines()
    assert lines[-1].seq == MAX_LOG_LINES + 11 and lines[-1].text == "DROP overflow NOOP"
    assert lines[-2].text == f"MOTOR_MOVE distance={MAX_LOG_LINES + 9} cm"


def test_message_log_shows_other_objects_as_their_repr_and_only_new_lines_are_decoded() -> None:
    """A tapped object that is not a firmware Message is shown as its repr (cut to 80
    characters); lines decoded once are not decoded again."""
    from actors import EventKind, Message
    from actors.firmware.commands import Cmd

    live = LiveSystem(load_scenario("empty"))
    live.activity.on_message(1.0, EventKind.SEND, "server/game", ("report", "x" * 100), 0)
    first = live.activity.log_lines()
    assert first[-1].text == repr(("report", "x" * 100))[:80] and first[-1].actor == "server/game"
    live.activity.on_message(2.0, EventKind.SEND, "seeker/ir", Message.int(Cmd.NOOP, 3), 0)
    second = live.activity.log_lines()
    assert [ln.seq for ln in second] == [1, 2] and second[0] is first[0]
    assert (second[1].time_s, second[1].text) == (2.0, "NOOP value=3")


def test_a_serial_port_unplugged_and_reopened_shows_on_the_timeline() -> None:
    """The server's link_error (a port hung up) and link_open reach the console's timeline,
    naming the port."""
    from server.views import ServerEvent
    from tui.activity import ActivityLog

    log = ActivityLog(lambda: 12.0)
    send, receive = trio.open_memory_channel(8)
    send.send_nowait(ServerEvent(11.0, "link_error", data={
        "link": "serial:/dev/ttyUSB0,115200", "retry_s": 0.25,
        "error": "serial port /dev/ttyUSB0 hung up (device unplugged)"}))
    send.send_nowait(ServerEvent(12.0, "link_open", data={
        "link": "serial:/dev/ttyUSB0,115200", "detail": "serial port /dev/ttyUSB0 open"}))
    log.drain_server_events(receive)
    assert [(e.kind, e.text) for e in log.timeline()] == [
        ("link", "serial port /dev/ttyUSB0 hung up (device unplugged)"),
        ("link", "serial port /dev/ttyUSB0 open")]
