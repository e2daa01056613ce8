"""A recording started mid-game (the console's ``R``) begins with the game as it stood:
its phase, hide spot, guesses, map, poses and faults in force (``/game/state``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import trio

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import run_game
from supervisors.recording import Recorder, RunInfo
from supervisors.recording.fork import ForkError, fork_game, plan_fork
from supervisors.recording.reading import read_recording
from supervisors.recording.runinfo import scenario_text
from tui.live import LiveSystem
from tui.replay import ReplayIndex, ReplaySystem
from tui.replay.index import grid_view
from world.scenario import load_scenario

SCENARIO = "empty"


def _known(grid: Any) -> int:
    return int((np.asarray(grid.cells) != -1).sum())


def _known_part(grid: Any) -> tuple[np.ndarray, tuple[float, float]]:
    """The grid's known cells (its unknown border cut off) and their origin [cm]."""
    rows, cols = np.nonzero(grid.cells != -1)
    r0, c0 = rows.min(), cols.min()
    cells = grid.cells[r0:rows.max() + 1, c0:cols.max() + 1]
    return cells, (grid.origin_cm[0] + c0 * grid.resolution_cm,
                   grid.origin_cm[1] + r0 * grid.resolution_cm)


@pytest.fixture(scope="module")
def console_game(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One console game of the empty room played by hand: recorded for 5 s in the middle
    of mapping, and for 5 s after the hider was found with a LIDAR fault in force; what
    the console showed as each recording began."""
    folder = tmp_path_factory.mktemp("midgame")
    scenario = load_scenario(SCENARIO)
    start = scenario.starts["mapper"]
    live = LiveSystem(scenario, speed=None, log_messages=False)
    seen: dict[str, Any] = {}

    async def until(phases: tuple[str, ...], limit_s: float) -> str:
        with trio.fail_after(limit_s):
            while (phase := live.snapshot().phase) not in phases:
                await trio.sleep(0.5)
        return phase

    async def record(name: str) -> None:
        live.record(str(folder / f"{name}.mcap"))
        await trio.sleep(0.01)  # the command runs
        seen[name] = live.snapshot()
        await trio.sleep(5.0)
        live.record(None)
        await trio.sleep(0.01)

    async def main() -> None:
        send, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(live.run, lambda item: None, receive)
            await trio.sleep(1.0)
            live.start_mapping()
            await trio.sleep(15.0)
            await record("mapping")
            await until(("map_ready",), 600)
            hide = scenario.hide_at
            live.hide_at(hide.x - start.x, hide.y - start.y, hide.heading_deg)
            await until(("hidden",), 600)
            for x, y in scenario.seek_at:
                live.seek_at(x - start.x, y - start.y)
                await trio.sleep(1.0)
                if await until(("found", "not_found"), 900) == "found":
                    break
            live.inject_fault("mapper/lidar", "noisy", 60.0, {})
            await trio.sleep(2.0)
            await record("found")
            nursery.cancel_scope.cancel()

    trio.run(main, clock=live.clock)
    return {"folder": folder, "seen": seen}


def _replay(console_game: dict[str, Any], name: str) -> tuple[Any, ReplaySystem]:
    rec = read_recording(console_game["folder"] / f"{name}.mcap")
    return rec, ReplaySystem(rec, speed=1.0)


def test_a_recording_started_after_found_replays_with_phase_found_and_the_guesses(
        console_game: dict[str, Any]) -> None:
    """Started after the seeker found the hider: the replay's first frame shows phase
    found, the hide spot and every guess the console showed, not idle and none."""
    seen = console_game["seen"]["found"]
    rec, replay = _replay(console_game, "found")
    snap = replay.snapshot()
    assert snap.time_s == pytest.approx(seen.time_s, abs=0.05)
    assert (snap.phase, snap.guesses) == ("found", seen.guesses) and seen.guesses >= 1
    np.testing.assert_allclose(snap.seek_guesses, seen.seek_guesses)
    assert snap.hide_spot is not None and seen.hide_spot is not None
    assert (snap.hide_spot.x_cm, snap.hide_spot.y_cm) == pytest.approx(
        (seen.hide_spot.x_cm, seen.hide_spot.y_cm))
    assert [e.text for e in snap.timeline] == ["found (when the recording began)"]


def test_a_recording_begins_when_it_was_started_with_the_faults_in_force(
        console_game: dict[str, Any]) -> None:
    """A fault injected before the recording does not pull its start back to the
    fault's time; it is shown in force from the recording's first frame."""
    seen = console_game["seen"]["found"]
    rec, replay = _replay(console_game, "found")
    assert rec.start_s == pytest.approx(seen.time_s, abs=0.05)
    assert rec.topic("/faults") == []
    (fault,) = replay.snapshot().faults
    (live_fault,) = seen.faults
    assert (fault.target, fault.kind) == ("mapper/lidar", "noisy")
    assert fault.started_s == pytest.approx(seen.time_s - 2.0, abs=0.05)
    assert fault.until_s == pytest.approx(fault.started_s + 60.0)
    assert fault.id == live_fault.id


def test_a_recording_started_mid_game_shows_the_map_and_poses_the_console_showed(
        console_game: dict[str, Any]) -> None:
    """The first frame has the console's map (the mapper's working grid) and each
    rover's pose."""
    seen = console_game["seen"]["found"]
    rec, replay = _replay(console_game, "found")
    snap = replay.snapshot()
    assert snap.map is not None and seen.map is not None
    (cells, origin), (want, want_origin) = _known_part(snap.map), _known_part(seen.map)
    np.testing.assert_array_equal(cells, want)
    assert origin == pytest.approx(want_origin)
    assert all(r.true_pose is not None for r in snap.rovers)


def test_a_recording_started_mid_mapping_shows_the_partial_map(
        console_game: dict[str, Any]) -> None:
    """Started while the mapper explores: phase mapping and the map known so far, less
    than the map the mapper uploaded at the end."""
    seen = console_game["seen"]["mapping"]
    rec, replay = _replay(console_game, "mapping")
    snap = replay.snapshot()
    assert snap.phase == "mapping" and seen.phase == "mapping"
    assert snap.map is not None and seen.map is not None
    final, _ = _replay(console_game, "found")
    uploaded = grid_view(final.topic("/map/uploaded")[0][1])
    assert 0 < _known(snap.map) < _known(uploaded)
    assert abs(_known(snap.map) - _known(seen.map)) <= 0.1 * _known(seen.map)
    assert snap.rovers[0].pose is not None  # the mapper's believed pose


def test_a_console_recording_started_mid_game_refuses_a_fork_clearly(
        console_game: dict[str, Any]) -> None:
    """A console recording cannot be forked (a person's choices are not in it): one
    clear error, whenever it began."""
    rec = read_recording(console_game["folder"] / "found.mcap")
    with pytest.raises(ForkError, match="recorded from the console"):
        plan_fork(rec, rec.start_s + 1.0)


@pytest.fixture(scope="module")
def headless_midgame(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, Any]:
    """A headless game of the empty room recorded from t = 60 s (a recorder started by
    hand, as the console starts one), and its report."""
    scenario = load_scenario(SCENARIO)
    path = tmp_path_factory.mktemp("midgame-headless") / "late.mcap"
    recorder = Recorder(path, RunInfo.for_scenario(scenario, 1),
                        scenario_toml=scenario_text(scenario))

    class StartLate:
        def started(self, system: Any) -> None:
            self.tap = system.actors.trace.tap_messages(
                lambda time, *rest: self._maybe_start(system, time))

        def _maybe_start(self, system: Any, time: float) -> None:
            if time >= 60.0 and not recorder.recording:
                self.tap.close()
                recorder.start(system)

        def finished(self, system: Any, report: Any) -> None:
            recorder.finished(system, report)

    seed_trio_scheduler(1)
    report = trio.run(lambda: run_game(scenario, 1, observers=[StartLate()]),
                      clock=virtual_clock())
    return path, report


def test_a_fork_of_a_recording_started_mid_game_plays_the_recorded_game(
        headless_midgame: tuple[Any, Any]) -> None:
    """Forked with no change after it began, a recording started mid-game plays the
    recorded game (same trace hash), its checkpoints compared from its start; a fork
    before its start is refused with the reason."""
    path, report = headless_midgame
    rec = read_recording(path)
    assert 60.0 <= rec.start_s < 60.1 and ReplayIndex(rec).phase(rec.start_s) != "idle"
    with pytest.raises(ForkError, match="started mid-game"):
        plan_fork(rec, 30.0)
    forked, checker = fork_game(path, 70.0)
    assert forked.trace_hash == report.trace_hash
    assert checker.compared >= 9
