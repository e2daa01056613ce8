"""`hideseek play --auto`: the console plays the headless game, event for event.

The console runs the system on a `GovernedClock` and builds its snapshots on its
own side of the thread, so the game it shows is the one `hideseek run` plays:
the same trace hash at x1 and as fast as possible. The x1 games are cut short by
the mapping budget (a failed game has a trace hash too), so they take seconds.
"""

from __future__ import annotations

import asyncio

import pytest
import trio

from actors import virtual_clock
from supervisors.harness.headless import Budget, run_game
from tui.app import ConsoleApp
from tui.live import LiveSystem
from world.scenario import load_scenario


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


@pytest.mark.parametrize("scenario", ["empty", "gap"])
def test_auto_game_as_fast_as_possible_has_the_headless_trace_hash(scenario: str) -> None:
    budget = Budget()
    want = headless_hash(scenario, 1, budget)
    assert want[1] == "found"
    assert console_hash(scenario, 1, None, budget) == want


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
