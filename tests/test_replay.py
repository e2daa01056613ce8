"""``hideseek replay``: a recording in the console (tui/replay), read from the file."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Any

import pytest
import trio
from textual.widgets import Input

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import Budget, run_game
from supervisors.recording import Recorder, RunInfo
from supervisors.recording.fork import ForkDiverged
from supervisors.recording.reading import read_recording
from supervisors.recording.runinfo import scenario_text
from tests.test_tui_app import press, until
from tui.cli import main
from tui.replay import ReplayIndex, ReplaySystem
from tui.replay.app import ReplayApp
from tui.replay.fork_live import ForkConsoleApp, ForkLiveSystem
from tui.replay.seek_dialog import SeekDialog, parse_seek
from tui.snapshot import Snapshot
from tui.widgets import FaultDialog
from world.scenario import load_scenario


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Any:
    scenario = load_scenario("empty")
    path = tmp_path_factory.mktemp("replay") / "game.mcap"
    recorder = Recorder(path, RunInfo.for_scenario(scenario, 1),
                        scenario_toml=scenario_text(scenario))
    seed_trio_scheduler(1)
    report = trio.run(lambda: run_game(scenario, 1, observers=[recorder]), clock=virtual_clock())
    return read_recording(path), report


def test_the_index_tells_the_game_at_any_time(recording: Any) -> None:
    """Phase, map, poses and the next event are read from the file at any time."""
    rec, report = recording
    ix = ReplayIndex(rec)
    mapped = report.phases["mapping"]
    assert ix.phase(0.0) == "idle" and ix.phase(mapped / 2) == "mapping"
    assert ix.phase(rec.end_s) == "found"
    assert ix.map(0.0) is None and ix.map(mapped / 2) is not None
    mapper = ix.rovers(mapped / 2)[0]
    assert mapper.pose is not None and mapper.true_pose is not None
    assert len(ix.lidar_points(mapped / 2)) > 100
    t = ix.next_event(mapped / 2, "phase")
    assert t == pytest.approx(mapped, abs=0.5)
    assert ix.phase(t) == "hiding"  # map_ready, then hiding at the same instant
    assert ix.next_event(rec.end_s, "phase") is None
    log = ix.log(mapped / 2)
    assert len(log) == 200 and log[-1].time_s <= mapped / 2


def test_the_replay_shows_the_hide_spot_and_guesses_in_the_map_frame(recording: Any) -> None:
    """The headless operator's room-frame choices, moved into the map frame."""
    rec, _ = recording
    scenario = load_scenario("empty")
    start, hide = scenario.starts["mapper"], scenario.hide_at
    assert start.heading_deg == 0.0  # so the map frame is the room frame moved by the start
    spot, guesses = ReplaySystem(rec).index.commands(rec.end_s)
    assert spot is not None
    assert (spot.x_cm, spot.y_cm, spot.heading_deg) == pytest.approx(
        (hide.x - start.x, hide.y - start.y, hide.heading_deg))
    assert guesses[0] == pytest.approx((scenario.seek_at[0][0] - start.x,
                                        scenario.seek_at[0][1] - start.y))


def test_parse_seek_takes_a_time_or_an_event_kind() -> None:
    """``120``, ``120 s`` and ``fault`` are understood; anything else is refused clearly."""
    assert parse_seek("120") == 120.0 == parse_seek("120 s")
    assert parse_seek("Fault") == "fault"
    with pytest.raises(ValueError, match="seek to a time"):
        parse_seek("tomorrow")


def test_the_replay_console_seeks_steps_and_goes_to_the_next_event(recording: Any) -> None:
    """In the console: seek to a time, step back, go to the next phase; game commands refused."""
    rec, report = recording
    system = ReplaySystem(rec, paused=True)
    app = ReplayApp(system)
    mapped = report.phases["mapping"]

    def dialog() -> bool:
        return isinstance(app.screen, SeekDialog) and bool(app.screen.query(Input))

    def at(t: float) -> Callable[[], bool]:
        return lambda: app.snapshot is not None and abs(app.snapshot.time_s - t) < 1e-6

    async def go() -> None:
        async with app.run_test(size=(120, 40), notifications=True) as pilot:
            await until(lambda: app.snapshot is not None, "the first snapshot")
            assert app.snapshot.phase == "idle" and app.snapshot.paused
            press(app, "t")
            await until(dialog, "the seek dialog")
            app.screen.query_one(Input).value = "100"
            await pilot.press("enter")
            await until(at(100.0), "t = 100 s")
            assert app.snapshot.phase == ix.phase(100.0) and app.snapshot.map is not None
            press(app, "comma")
            await until(at(99.0), "a step back to 99 s")
            await pilot.pause()
            press(app, "t")
            await until(dialog, "the seek dialog again")
            app.screen.query_one(Input).value = "5"
            await pilot.press("enter")
            await until(at(5.0), "t = 5 s")
            press(app, "n")  # any event next: the map is ready
            await until(at(ix.next_event(5.0)), "the next event")
            assert app.snapshot.phase == "hiding" and app.snapshot.time_s == pytest.approx(
                mapped, abs=0.5)
            press(app, "t")
            await until(dialog, "the seek dialog, kinds")
            app.screen.query_one(Input).value = "phase"
            target = ix.next_event(app.snapshot.time_s, "phase")
            await pilot.press("enter")
            await until(at(target), "the next phase")
            assert app.snapshot.phase == ix.phase(app.snapshot.time_s) != "hiding"
            system.start_mapping()
            await until(lambda: any(r.command == "start_mapping" for r in app.results),
                        "the refusal")
            assert app.results[-1].status == "refused"
            assert "nothing is simulated" in app.results[-1].reason
            press(app, "space")
            await until(lambda: not app.snapshot.paused, "playing")
            await until(lambda: app.snapshot.time_s > mapped + 0.05, "time running")

    ix = ReplayIndex(rec)
    asyncio.run(go())


def test_cli_replay_of_a_missing_file_is_bad_input(tmp_path: Any,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``hideseek replay`` of a file that is not there: exit 2 and one line."""
    assert main(["replay", str(tmp_path / "none.mcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hideseek replay:")


def _run_fork(live: ForkLiveSystem) -> list[Snapshot]:
    """Run a fork's Trio side as the console would, alone, until it stands paused at its
    time; then take one snapshot from the console's side (`LiveSystem.host_snapshot`)."""
    snaps: list[Snapshot] = []

    async def main() -> None:
        send, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(live.run, lambda item: None, receive)
            while not live.clock.paused:  # the fork pauses once it has reached its time
                await trio.testing.wait_all_tasks_blocked()
            snaps.append(live.host_snapshot())
            nursery.cancel_scope.cancel()

    try:
        trio.run(main, clock=live.clock)
    except BaseExceptionGroup as group:  # this test's nursery: the system's one error
        (error,) = group.exceptions
        raise error from None
    return snaps


def test_a_fork_into_the_live_console_follows_the_recording_to_its_time(
        recording: Any) -> None:
    """The console's fork plays the recorded game to T, a time while mapping (every second
    checked), then stands paused at T with the fault catalogue offered."""
    rec, report = recording
    t = float(math.floor(report.phases["mapping"] * 0.75))
    live = ForkLiveSystem(rec, t, log_messages=False)
    snaps = _run_fork(live)
    assert live.checker.compared == int(t) and live.checker.diverged is None
    (snap,) = snaps
    assert t <= snap.time_s < t + 0.1 and snap.paused and snap.speed == 1.0
    assert snap.phase == "mapping" and snap.catalogue
    assert any("forked" in e.text for e in snap.timeline)


def test_a_fork_into_the_console_that_leaves_the_recording_stops(tmp_path: Any) -> None:
    """A recording that does not make its game (another seed in its metadata): ForkDiverged."""
    scenario = load_scenario("empty")
    path = tmp_path / "wrong.mcap"
    recorder = Recorder(path, RunInfo.for_scenario(scenario, 2),
                        scenario_toml=scenario_text(scenario))
    seed_trio_scheduler(1)
    trio.run(lambda: run_game(scenario, 1, budget=Budget(mapping=6.0), observers=[recorder]),
             clock=virtual_clock())
    live = ForkLiveSystem(read_recording(path), 5.0, log_messages=False)
    with pytest.raises(ForkDiverged, match="left the recording"):
        _run_fork(live)


def test_the_fork_key_closes_the_replay_with_its_time(recording: Any) -> None:
    """``F`` in the replay: the app ends, naming the time to fork at."""
    rec, _ = recording
    app = ReplayApp(ReplaySystem(rec, paused=True, at=42.0))

    async def go() -> None:
        async with app.run_test(size=(120, 40)):
            await until(lambda: app.snapshot is not None, "the first snapshot")
            press(app, "F")
            await until(lambda: app.fork_at is not None, "the fork request")

    asyncio.run(go())
    assert app.fork_at == pytest.approx(42.0)


def test_the_replay_offers_none_of_the_games_commands() -> None:
    """The replay's keys are its own: no mapping, hide, seek or fault keys from the console."""
    actions = {b.action for bindings in ReplayApp._merge_bindings().key_to_bindings.values()
               for b in bindings}
    assert {"pause", "resume", "seek", "next_event", "fork", "quit"} <= actions
    assert not actions & {"start_mapping", "confirm", "faults", "new_game", "record"}


def test_the_forked_console_opens_the_fault_dialog_at_the_fork(recording: Any) -> None:
    """In the console (Trio as Textual's guest): the fork follows the recording to T, then
    the fault dialog is open."""
    rec, _ = recording
    live = ForkLiveSystem(rec, 20.0, log_messages=False)
    app = ForkConsoleApp(live)

    async def go() -> None:
        async with app.run_test(size=(120, 40)) as pilot:
            await until(lambda: (isinstance(app.screen, FaultDialog)
                                 and app.screen.query("Select")) or app.system_error,
                        "the fault dialog", timeout=120.0)  # 20 s of a game, on a busy machine
            await pilot.pause()
            assert app.system_error is None
            assert live.checker.compared == 20 and app.snapshot.paused

    asyncio.run(go())
