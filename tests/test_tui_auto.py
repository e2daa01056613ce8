"""`hideseek play --auto`: the console plays the headless game, event for event.

The console runs the system on a `GovernedClock` and builds its snapshots on its
own side of the thread, so the game it shows is the one `hideseek run` plays:
as fast as possible, the two commands print the same JSON on every built-in
room (but for the wall time); at x1 the same trace hash. The x1 games are cut
short by the mapping budget (a failed game has a trace hash too), so they take
seconds.
"""

from __future__ import annotations

import asyncio
import json
import pathlib
import subprocess
import sys

import pytest
import trio

from actors import virtual_clock
from supervisors.harness.headless import Budget, run_game
from tui.app import ConsoleApp
from tui.live import LiveSystem
from world.scenario import builtin_scenarios, load_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent
WALL = ("wall_seconds", "real_time_factor")  # the only figures that depend on the machine


def headless_hash(scenario: str, seed: int, budget: Budget) -> tuple[str, str, float]:
    report = trio.run(lambda: run_game(load_scenario(scenario), seed, budget=budget),
                      clock=virtual_clock())
    return report.trace_hash, report.outcome, report.sim_seconds


def console_hash(scenario: str, seed: int, speed: float | None,
                 budget: Budget) -> tuple[str, str, float]:
    system = LiveSystem(load_scenario(scenario), seed=seed, speed=speed, auto=True,
                        budget=budget)
    app = ConsoleApp(system)

    async def play() -> None:
        async with app.run_test(size=(120, 40)):
            for _ in range(1200):  # 120 s of wall time at most
                if system.report is not None or not app.is_running:
                    break
                await asyncio.sleep(0.1)

    asyncio.run(play())
    assert system.report is not None, "the auto game did not end"
    return system.report.trace_hash, system.report.outcome, system.report.sim_seconds


@pytest.mark.parametrize("scenario", builtin_scenarios())
def test_play_auto_at_max_speed_prints_the_json_of_hideseek_run(scenario: str) -> None:
    """The two commands, each in its own process, side by side: ``hideseek play --auto
    --json --speed max`` prints the JSON ``hideseek run --json`` prints, but the wall time."""
    cli = [sys.executable, "-m", "tui.cli"]
    procs = [subprocess.Popen([*cli, *argv, "--scenario", scenario, "--json"], cwd=ROOT,
                              stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
             for argv in (["run"], ["play", "--auto", "--speed", "max"])]
    (run_out, run_err), (play_out, play_err) = (p.communicate(timeout=600) for p in procs)
    assert [p.returncode for p in procs] == [0, 0], (run_err, play_err[-2000:])
    want, got = json.loads(run_out), json.loads(play_out)
    assert all(want.pop(k) > 0 and got.pop(k) > 0 for k in WALL)
    assert got == want
    assert want["scenario"] == scenario and want["trace_hash"]


@pytest.mark.parametrize("scenario", ["empty", "gap"])
def test_auto_game_at_x1_has_the_headless_trace_hash(scenario: str) -> None:
    budget = Budget(mapping=3.0)  # mapping fails at 3 s: a short game, paced at x1
    want = headless_hash(scenario, 2, budget)
    got = console_hash(scenario, 2, 1.0, budget)
    assert got == want
    assert got[2] > 3.0


def test_auto_game_refuses_operator_commands() -> None:
    system = LiveSystem(load_scenario("empty"), seed=1, auto=True)
    results = []
    system._publish = results.append  # noqa: SLF001 - what the console hands to run()
    system.start_mapping()
    assert results and results[0].status == "refused"
    assert "auto play" in results[0].reason
