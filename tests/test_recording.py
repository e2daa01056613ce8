"""Recording a game as MCAP, reading it back, and forking it (supervisors/recording)."""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np
import pytest
import trio
from mcap.reader import make_reader

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import GameReport, run_game
from supervisors.recording import CHANNELS, SCHEMAS, Recorder, RunInfo
from supervisors.recording.fork import ForkDiverged, ForkError, fork_game, plan_fork
from supervisors.recording.reading import RecordingReadError, read_recording
from supervisors.recording.runinfo import scenario_text
from tui.cli import main
from world.scenario import load_scenario

SCENARIO = "empty"
SEED = 1


class Capture:
    """A run observer keeping the game's own counters at its end."""

    def started(self, system: Any) -> None:
        self.messages_at_start = system.messages()

    def finished(self, system: Any, report: GameReport) -> None:
        self.rovers = {v.id: v.stats for v in system.server.snapshot().rovers}
        self.lidar_samples = system.world.lidar.samples
        self.samples_per_rev = system.world.lidar.p.lidar_samples_per_rev
        self.upload = system.server.game.map


def play(path: Any = None, *, info: RunInfo | None = None) -> tuple[GameReport, Capture]:
    scenario = load_scenario(SCENARIO)
    capture = Capture()
    observers: list[Any] = [capture]
    if path is not None:
        info = info or RunInfo.for_scenario(scenario, SEED)
        observers.insert(0, Recorder(path, info, scenario_toml=scenario_text(scenario)))
    seed_trio_scheduler(SEED)
    report = trio.run(lambda: run_game(scenario, SEED, observers=observers),
                      clock=virtual_clock())
    return report, capture


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[GameReport, Capture, Any]:
    path = tmp_path_factory.mktemp("rec") / "game.mcap"
    report, capture = play(path)
    return report, capture, path


@pytest.fixture(scope="module")
def faulted(recorded: Any, tmp_path_factory: pytest.TempPathFactory) -> tuple[GameReport, Any]:
    """A fork of the recorded game at 60 s with the mapper's navigation crashed, recorded."""
    out = tmp_path_factory.mktemp("fork") / "fork.mcap"
    report, _ = fork_game(recorded[2], 60.0, faults=[("mapper/nav", "crash", 0.0)], record=out)
    return report, out


def test_recording_does_not_change_the_game(recorded: Any) -> None:
    """A recorded game has the trace hash of the same game unrecorded."""
    plain, _ = play()
    assert recorded[0].trace_hash == plain.trace_hash
    assert recorded[0].outcome == plain.outcome == "found"


def test_every_channel_is_json_with_its_json_schema(recorded: Any) -> None:
    """The mcap reader finds every channel, JSON encoded, with the schema it names."""
    with open(recorded[2], "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topics = {}
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        assert ch.message_encoding == "json"
        assert schema.encoding == "jsonschema"
        assert json.loads(schema.data) == SCHEMAS[schema.name]
        topics[ch.topic] = schema.name
    assert topics == {c.topic: c.schema for c in CHANNELS}
    for name in ("foxglove.Grid", "foxglove.PoseInFrame", "foxglove.PosesInFrame",
                 "foxglove.LaserScan", "foxglove.Log"):
        assert name in topics.values()


def test_message_counts_match_the_games_counters(recorded: Any) -> None:
    """Each channel holds as many messages as the game's own counters say."""
    report, cap, path = recorded
    rec = read_recording(path)
    rows = [m for _, batch in rec.topic("/actors/messages") for m in batch["messages"]]
    assert len(rows) == report.messages - cap.messages_at_start
    assert rows[0].keys() == {"t", "queue", "command", "type", "value", "depth"}
    assert len(rec.topic("/actors/drops")) == report.dropped == 0
    assert len(rec.topic("/faults")) == report.faults == 0
    assert len(rec.topic("/mapper/scan")) == cap.lidar_samples // cap.samples_per_rev
    for role, stats in cap.rovers.items():
        frames = [m for _, m in rec.topic(f"/{role}/link")]
        assert sum(m["direction"] == "up" for m in frames) == stats.frames_in
        down = sum(m["direction"] == "down" for m in frames)
        assert 0 <= stats.frames_out - down <= 2  # the last frames may still be queued
        poses = len(rec.topic(f"/{role}/pose/true"))
        assert abs(poses - report.sim_seconds / 0.2) <= 2
    seconds = len(rec.topic("/checkpoints"))
    assert abs(seconds - report.sim_seconds) <= 2
    kinds = {"phase", "report", "refused", "map", "link_down", "link_up"}
    logged = [log for _, log in rec.topic("/game/events") if log["name"] in kinds]
    phases = [e.split("phase=")[1].split()[0] for e in report.events if " phase " in e]
    assert [log["message"].split()[0] for log in logged if log["name"] == "phase"] == [
        f"phase={p}" for p in phases]
    assert len(rec.topic("/map/uploaded")) == 1
    counts = json.loads(rec.summary["channel_counts"])
    assert counts == {c.topic: len(rec.topic(c.topic)) for c in CHANNELS}


def test_the_uploaded_grid_decodes_to_the_servers_map(recorded: Any) -> None:
    """foxglove.Grid data is the map's int8 cells, row-major, in metres."""
    _, cap, path = recorded
    (_, grid), = read_recording(path, topics=["/map/uploaded"]).topic("/map/uploaded")
    cells = np.frombuffer(base64.b64decode(grid["data"]), np.int8).reshape(
        -1, grid["column_count"])
    assert np.array_equal(cells, np.asarray(cap.upload.cells, np.int8))
    assert grid["cell_size"]["x"] == pytest.approx(cap.upload.resolution_cm / 100)
    assert grid["pose"]["position"]["x"] == pytest.approx(cap.upload.origin_cm[0] / 100)


def test_metadata_makes_a_recording_self_describing(recorded: Any) -> None:
    """Scenario text, seed, budget, code version and the final summary are in the file."""
    report, _, path = recorded
    rec = read_recording(path, topics=[])
    assert rec.run.scenario_ref == f"builtin:{SCENARIO}" and rec.run.seed == SEED
    assert rec.run.budget_s == 1200.0 and rec.run.code
    assert rec.scenario_toml == scenario_text(load_scenario(SCENARIO))
    assert rec.summary["trace_hash"] == report.trace_hash
    assert rec.summary["outcome"] == "found"
    assert rec.end_s == pytest.approx(report.sim_seconds, abs=0.5)


@pytest.mark.parametrize("at_s", [0.0, 90.0])
def test_a_fork_with_no_change_plays_the_recorded_game(recorded: Any, at_s: float) -> None:
    """Forked at any time with no change, the game ends with the recording's trace hash."""
    report, checker = fork_game(recorded[2], at_s)
    assert report.trace_hash == recorded[0].trace_hash
    assert checker.compared == int(at_s)


def _before_after(path: Any, at_s: float) -> tuple[list, list]:
    rec = read_recording(path, topics=["/game/events", "/actors/events", "/actors/messages"])
    events = [(t, topic, json.dumps(m, sort_keys=True)) for topic in rec.messages
              for t, m in rec.topic(topic)]
    return sorted(e for e in events if e[0] < at_s), sorted(e for e in events if e[0] >= at_s)


def test_a_fork_with_a_fault_differs_only_after_the_fork(recorded: Any, faulted: Any) -> None:
    """The same events before T, different ones after; the fault and its restart recorded."""
    report, path = faulted
    before, after = _before_after(recorded[2], 60.0)
    fork_before, fork_after = _before_after(path, 60.0)
    assert fork_before == before
    assert fork_after != after
    rec = read_recording(path, topics=["/faults", "/actors/events"])
    (t, fault), = rec.topic("/faults")
    assert t >= 60.0 and fault["message"] == "crash on mapper/nav"
    restarts = [log for _, log in rec.topic("/actors/events") if log["name"] == "restart"]
    assert len(restarts) == report.restarts >= 1
    assert rec.run.extra_faults[0].at_s == 60.0


def test_a_fork_of_a_fork_plays_the_fork(faulted: Any) -> None:
    """A forked recording names its changes, so forking it again plays the same game."""
    report, path = faulted
    again, _ = fork_game(path, 100.0)
    assert again.trace_hash == report.trace_hash


def test_a_fork_that_leaves_the_recording_stops_with_a_clear_error(tmp_path: Any) -> None:
    """A recording whose metadata does not make its game (here: another seed) stops the fork."""
    scenario = load_scenario(SCENARIO)
    path = tmp_path / "wrong.mcap"
    play(path, info=RunInfo.for_scenario(scenario, SEED + 1))
    with pytest.raises(ForkDiverged, match=r"left the recording at t=\d+\.\d+ s .* other code or "
                                           "options play another game"):
        fork_game(path, 50.0)


def test_fork_refuses_what_it_cannot_do(recorded: Any) -> None:
    """A time outside the recording, or a hide spot after the hider was sent, is refused."""
    rec = read_recording(recorded[2], topics=["/game/events"])
    with pytest.raises(ForkError, match="--fork-at must be within the recording"):
        plan_fork(rec, 10_000.0)
    with pytest.raises(ForkError, match="--hide: the recorded game sent the hider at"):
        plan_fork(rec, 150.0, hide=(100.0, 100.0, 0.0))
    assert plan_fork(rec, 10.0, hide=(100.0, 100.0, 0.0)).hide_at == (100.0, 100.0, 0.0)
    with pytest.raises(ForkError, match="--fault: .*bogus"):
        plan_fork(rec, 10.0, faults=[("mapper/lidar", "bogus", 5.0)])


def test_reading_a_file_that_is_not_a_recording_fails_clearly(tmp_path: Any) -> None:
    """Not MCAP: one clear error."""
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"not mcap at all")
    with pytest.raises(RecordingReadError, match="x.mcap: not a readable recording"):
        read_recording(bad)


def test_cli_fork_of_a_missing_file_is_bad_input(tmp_path: Any,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """``hideseek run --replay`` of a missing file: exit 2 and one line."""
    assert main(["run", "--replay", str(tmp_path / "none.mcap"), "--fork-at", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot read" in err[0]
    assert main(["run", "--scenario", SCENARIO, "--fork-at", "5"]) == 2


def test_recording_does_not_change_a_game_with_a_crash_and_a_restart(recorded: Any,
                                                                     faulted: Any) -> None:
    """The faulted fork, played again unrecorded, has the recorded fork's trace hash."""
    report, _ = fork_game(recorded[2], 60.0, faults=[("mapper/nav", "crash", 0.0)])
    assert report.trace_hash == faulted[0].trace_hash and report.restarts >= 1


def test_the_package_exports_its_public_names() -> None:
    """Every name in supervisors.recording.__all__ exists."""
    import supervisors.recording as recording  # noqa: PLC0415

    assert all(hasattr(recording, name) for name in recording.__all__)
