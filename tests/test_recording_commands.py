"""Recording from the command line and the console: ``hideseek play --record``, ``R``
(tui/live.py), ``hideseek campaign --record-failures``."""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

import pytest
import trio
from textual import events

from supervisors.harness.campaign import game_from_ref, play_campaign_game
from supervisors.recording.fork import ForkError, plan_fork
from supervisors.recording.reading import read_recording
from tui import cmd_campaign
from tui.app import ConsoleApp
from tui.fake import FakeSystem
from tui.live import LiveSystem
from tui.snapshot import CommandResult
from world.scenario import load_scenario


def _record_twice(live: LiveSystem, first: str | None, second: str | None, *, for_s: float,
                  mapping: bool = False) -> list[CommandResult]:
    """Run ``live`` (virtual time): ``record(first)`` at 1 s (after start mapping when
    ``mapping``), ``record(second)`` ``for_s`` later; the command results published."""
    results: list[CommandResult] = []

    def publish(item: Any) -> None:
        if isinstance(item, CommandResult):
            results.append(item)

    async def main() -> None:
        send, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(live.run, publish, receive)
            await trio.sleep(1.0)
            if mapping:
                live.start_mapping()
            live.record(first)
            await trio.sleep(for_s)
            live.record(second)
            await trio.sleep(0.5)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=live.clock)
    return results


def test_the_live_system_records_between_two_record_commands(tmp_path: Any) -> None:
    """``record`` starts a recording of the running game and ``record`` again closes it; the
    file is a console recording, which a fork refuses (a person's choices are not in it)."""
    path = tmp_path / "live.mcap"
    live = LiveSystem(load_scenario("empty"), speed=None, log_messages=False)
    results = _record_twice(live, str(path), None, for_s=20.0, mapping=True)
    assert [r.status for r in results if r.command == "record"] == ["ok", "ok"]
    assert live.recording is None
    rec = read_recording(path)
    assert rec.run.operator == "console" and rec.run.scenario_ref == "builtin:empty"
    assert 15.0 < rec.end_s - rec.start_s < 25.0
    assert rec.topic("/map/working") and rec.topic("/actors/messages")
    with pytest.raises(ForkError, match="recorded from the console"):
        plan_fork(rec, rec.start_s + 1.0)


def test_record_into_a_folder_names_the_file_there(tmp_path: Any) -> None:
    """``R`` passes the export folder: the recording gets a name of its own inside it,
    not in the working directory."""
    live = LiveSystem(load_scenario("empty"), speed=None, log_messages=False)
    results = _record_twice(live, str(tmp_path), str(tmp_path), for_s=2.0)
    assert [r.status for r in results if r.command == "record"] == ["ok", "ok"]
    (made,) = tmp_path.iterdir()
    assert made.name.startswith("hideseek-empty-seed1-") and made.suffix == ".mcap"
    assert read_recording(made).run.operator == "console"


def test_play_record_writes_from_the_start(tmp_path: Any) -> None:
    """``LiveSystem(record=...)``: the recording starts with the system; the file is closed
    when the console ends."""
    path = tmp_path / "start.mcap"
    live = LiveSystem(load_scenario("empty"), speed=None, log_messages=False, record=str(path))

    async def main() -> None:
        send, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(live.run, lambda item: None, receive)
            await trio.sleep(5.0)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=live.clock)
    rec = read_recording(path)
    assert rec.start_s < 0.5 and rec.end_s > 4.0
    assert rec.summary["skipped"] == "0"


def test_the_record_key_on_a_system_that_cannot_record_says_so() -> None:
    """``R`` on the fake system: a warning, no traceback."""
    app = ConsoleApp(FakeSystem(seed=3))

    async def go() -> None:
        async with app.run_test(size=(120, 40), notifications=True):
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 10.0
            app.post_message(events.Key("R", "R"))
            while not any("cannot be recorded" in n.message for n in app._notifications):
                assert loop.time() < deadline, "no warning"
                await asyncio.sleep(0.02)

    asyncio.run(go())


def _failing_worker(ref: str, **kwargs: Any) -> dict[str, Any]:
    """A real campaign game, declared failed (so --record-failures has one to record)."""
    result = play_campaign_game(ref, **kwargs)
    result["outcome"], result["reason"] = "failed", "declared failed by the test"
    return result


def test_campaign_record_failures_records_each_failed_game_as_it_was(
        tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """``--record-failures DIR`` plays each failed game again by its reference, recorded;
    the recording is the campaign's game (same trace hash) and rebuilds its faults."""
    parser = argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    folder = tmp_path / "failed"
    args = parser.parse_args(["-n", "1", "--workers", "0", "--scenarios", "empty",
                              "--replay-every", "0", "--out", str(tmp_path / "c.sqlite"),
                              "--no-progress", "--record-failures", str(folder)])
    assert cmd_campaign.run(args, worker=_failing_worker) == 1
    out = capsys.readouterr().out
    assert f"game 0: {folder / 'game-0.mcap'} (" in out and "the campaign's game)" in out
    rec = read_recording(folder / "game-0.mcap", topics=["/faults"])
    assert rec.run.scenario_ref.startswith("campaign:1:0")
    assert rec.run.scenario().faults == game_from_ref(rec.run.scenario_ref[9:])[0].faults


def test_campaign_record_failures_into_a_file_is_bad_input(
        tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """A --record-failures path that is a file: exit 2 before any game."""
    parser = argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    (tmp_path / "f").write_text("x")
    args = parser.parse_args(["-n", "1", "--workers", "0", "--out", str(tmp_path / "c.sqlite"),
                              "--record-failures", str(tmp_path / "f")])
    assert cmd_campaign.run(args, worker=_failing_worker) == 2
    assert capsys.readouterr().err.startswith("hideseek campaign: --record-failures")
