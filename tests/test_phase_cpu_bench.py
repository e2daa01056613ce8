"""benchmarks.phase_cpu: CPU charged to the phases of the same game `hideseek run` plays."""

from __future__ import annotations

import trio

from actors import seed_trio_scheduler, virtual_clock
from benchmarks.phase_cpu import main, measure
from supervisors.harness.headless import run_game
from world.scenario import load_scenario


def test_watching_the_phases_keeps_the_game_and_charges_each_phase():
    report, cpu = measure("empty", 3)
    seed_trio_scheduler(3)
    plain = trio.run(lambda: run_game(load_scenario("empty"), 3), clock=virtual_clock())
    assert report.trace_hash == plain.trace_hash
    assert [p for p in cpu if p in ("mapping", "hiding", "seeking")] == [
        "mapping", "hiding", "seeking"]
    assert all(cpu[p] > 0 for p in ("mapping", "hiding", "seeking"))


def test_unknown_room_is_one_error_line_and_status_2(capsys):
    assert main(["--scenario", "nowhere"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("phase_cpu: unknown room")
