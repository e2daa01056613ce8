"""``hideseek replay``: a recording in the console (tui/replay), read from the file."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest
import trio
from textual import events
from textual.widgets import Input

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import run_game
from supervisors.recording import Recorder, RunInfo
from supervisors.recording.reading import read_recording
from supervisors.recording.runinfo import scenario_text
from tui.cli import main
from tui.replay import ReplayIndex, ReplaySystem
from tui.replay.app import ReplayApp
from tui.replay.seek_dialog import SeekDialog, parse_seek
from world.scenario import load_scenario

TIMEOUT_S = 10.0


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


def test_parse_seek_takes_a_time_or_an_event_kind() -> None:
    """``120``, ``120 s`` and ``fault`` are understood; anything else is refused clearly."""
    assert parse_seek("120") == 120.0 == parse_seek("120 s")
    assert parse_seek("Fault") == "fault"
    with pytest.raises(ValueError, match="seek to a time"):
        parse_seek("tomorrow")


def press(app: ReplayApp, key: str, char: str | None = None) -> None:
    app.post_message(events.Key(key, char if char is not None else
                                (key if len(key) == 1 else None)))


async def until(cond: Callable[[], object], what: str) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + TIMEOUT_S
    while not cond():
        if loop.time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


def test_the_replay_console_seeks_steps_and_goes_to_the_next_event(recording: Any) -> None:
    """In the console: seek to a time, step back, go to the next phase; game commands refused."""
    rec, report = recording
    system = ReplaySystem(rec, paused=True)
    app = ReplayApp(system)
    mapped = report.phases["mapping"]

    def at(t: float) -> Callable[[], bool]:
        return lambda: app.snapshot is not None and abs(app.snapshot.time_s - t) < 1e-6

    async def go() -> None:
        async with app.run_test(size=(120, 40), notifications=True) as pilot:
            await until(lambda: app.snapshot is not None, "the first snapshot")
            assert app.snapshot.phase == "idle" and app.snapshot.paused
            press(app, "t")
            await until(lambda: isinstance(app.screen, SeekDialog), "the seek dialog")
            app.screen.query_one(Input).value = "100"
            await pilot.press("enter")
            await until(at(100.0), "t = 100 s")
            assert app.snapshot.phase == ix.phase(100.0) and app.snapshot.map is not None
            press(app, "comma", ",")
            await until(at(99.0), "a step back to 99 s")
            await pilot.pause()
            press(app, "t")
            await until(lambda: isinstance(app.screen, SeekDialog), "the seek dialog again")
            app.screen.query_one(Input).value = "5"
            await pilot.press("enter")
            await until(at(5.0), "t = 5 s")
            press(app, "n")  # any event next: the map is ready
            await until(at(ix.next_event(5.0)), "the next event")
            assert app.snapshot.phase == "hiding" and app.snapshot.time_s == pytest.approx(
                mapped, abs=0.5)
            press(app, "t")
            await until(lambda: isinstance(app.screen, SeekDialog), "the seek dialog, kinds")
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
            press(app, "space", " ")
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
