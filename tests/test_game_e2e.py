"""Whole games: simulated rovers, firmware actors, server, in virtual time."""

from __future__ import annotations

import dataclasses
import json
import math

import shapely
import trio

from actors import seed_trio_scheduler, virtual_clock
from benchmarks.game import play_one, truth_map, truth_nav_factory
from server.store import Store
from supervisors.harness.headless import Budget, GameReport, finish_report, play_game, run_game
from supervisors.system import open_sim_system
from tui.cli import main
from world.scenario import ScheduledFault, load_scenario


def play(scenario, seed: int = 1) -> GameReport:
    seed_trio_scheduler(seed)
    return trio.run(lambda: run_game(scenario, seed), clock=virtual_clock())


def test_whole_game_on_the_empty_room_finds_the_hider() -> None:
    """The mapper completes its map by itself, the hider hides, the seeker finds it."""
    report = play(load_scenario("empty"))
    assert report.outcome == "found", report.reason
    assert report.coverage is not None and report.coverage > 0.95
    assert report.accuracy is not None and report.accuracy > 0.85
    assert set(report.phases) == {"mapping", "hiding", "seeking"}
    assert report.guesses >= 1
    assert report.messages > 10_000
    reports = [e for e in report.events if "report=" in e]
    assert "report=arrived" in reports[0] and "report=found" in reports[-1]  # the last too


def test_when_every_guess_fails_the_operator_searches_wider_round_the_last() -> None:
    """Both guesses 130 cm from the hide spot: each is ``not_found``; the headless operator
    then asks for a wider search round the last guess (``within`` 120 cm) and it finds the
    hider. With the wider search off the game ends ``not_found`` after two guesses."""
    base = load_scenario("empty")  # hide at (330, 240)
    off = dataclasses.replace(base, seek_at=((200, 150), (200, 240)))
    seed_trio_scheduler(1)
    report = trio.run(lambda: run_game(off, 1), clock=virtual_clock())
    assert (report.outcome, report.guesses, report.wider_search) == ("found", 3, True)
    reports = [e.split("reason=")[1] for e in report.events if "report=not_found" in e]
    # each guess's own scan, and a ring round it once the seeker's belief is wider than
    # what that scan sees past IR range
    assert len(reports) == 2
    assert all(r.startswith("the IR sensor saw nothing there") for r in reports)
    seed_trio_scheduler(1)
    plain = trio.run(lambda: run_game(off, 1, budget=Budget(wider_within_cm=None)),
                     clock=virtual_clock())
    assert (plain.outcome, plain.guesses, plain.wider_search) == ("not_found", 2, False)


def test_a_hider_that_cannot_hide_is_sent_once_more_then_the_game_fails() -> None:
    """A spot in the middle of a 1 m box: the hider answers ``invalid_spot``; the headless
    operator sends it again (`Budget.hide_attempts` 2), then gives up with the hider's
    reason; with one attempt it gives up after the first answer."""
    base = load_scenario("empty")
    boxed = dataclasses.replace(base, obstacles=(shapely.box(170, 100, 270, 200),),
                                hide_at=base.hide_at._replace(x=220.0, y=150.0))
    for attempts in (2, 1):
        seed_trio_scheduler(1)
        report = trio.run(lambda n=attempts: run_game(boxed, 1, budget=Budget(hide_attempts=n)),
                          clock=virtual_clock())
        assert (report.outcome, report.hide_attempts) == ("failed", attempts)
        assert report.reason.startswith("hider did not hide: unknown ground")
        assert sum("report=invalid_spot" in e for e in report.events) == attempts


def test_same_seed_gives_the_same_game_event_for_event() -> None:
    """Determinism: two runs of one scenario and seed have the same trace hash."""
    scenario = load_scenario("empty")
    a, b = play(scenario, 3), play(scenario, 3)
    assert a.trace_hash == b.trace_hash
    assert a.events == b.events
    assert a.messages == b.messages


def test_actor_crash_and_hang_mid_game_are_recovered() -> None:
    """A navigation crash while mapping and a motor hang while hiding: restarted, still found."""
    base = load_scenario("empty")
    faults = (
        ScheduledFault(at_s=30.0, target="mapper/nav", kind="crash"),
        ScheduledFault(at_s=40.0, target="mapper/lidar", kind="crash"),
        ScheduledFault(at_s=115.0, target="hider/motor", kind="hang", duration_s=3.0),
    )
    report = play(dataclasses.replace(base, faults=faults))
    assert report.outcome == "found", report.reason
    assert report.restarts >= 3
    assert report.faults == 3


def test_crash_and_hang_injected_in_each_phase_are_recovered_and_the_hider_found() -> None:
    """Faults timed by the game's phase, not the clock: a mapper/nav crash while mapping,
    a hider/motor hang while the hider drives, a seeker/nav crash while seeking. Each
    restarts its actor (watchdog for the hang), and the game still ends found."""
    scenario = load_scenario("empty")
    plan = {"mapping": [(20.0, "mapper/nav", "crash", 0.0)],
            "hiding": [(3.0, "hider/motor", "hang", 3.0)],
            "seeking": [(4.0, "seeker/nav", "crash", 0.0)]}
    injected: list[tuple[str, str, str]] = []
    exits: dict[str, str] = {}  # how each target's last incarnation exited

    async def inject_by_phase(system) -> None:
        done: set[str] = set()
        while True:
            phase = str(system.server.game.phase)
            if phase in plan and phase not in done:
                done.add(phase)
                for delay, target, kind, seconds in plan[phase]:
                    await trio.sleep(delay)
                    system.inject_fault(target, kind, seconds)
                    injected.append((str(system.server.game.phase), target, kind))
            await trio.sleep(0.2)

    async def main() -> GameReport:
        report = GameReport(scenario.name, 1)
        with Store(":memory:") as store:
            async with open_sim_system(scenario, seed=1, store=store) as system:
                t0 = trio.current_time()
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(inject_by_phase, system)
                    await play_game(system, report, Budget())
                    nursery.cancel_scope.cancel()
                finish_report(report, system, t0)
                for name in ("mapper/nav", "hider/motor", "seeker/nav"):
                    exits[name] = str(system.actors.whereis(name).last_exit.kind)
        return report

    seed_trio_scheduler(1)
    report = trio.run(main, clock=virtual_clock())
    assert injected == [("mapping", "mapper/nav", "crash"), ("hiding", "hider/motor", "hang"),
                        ("seeking", "seeker/nav", "crash")]
    assert report.outcome == "found", report.reason
    assert report.restarts >= 3
    assert report.faults == 3
    assert exits == {"mapper/nav": "crash", "hider/motor": "hung", "seeker/nav": "crash"}


def play_on_truth(scenario, seed: int = 1) -> tuple[GameReport, dict]:
    """A whole game whose map is the ground truth; also the hider's true pose on arrival."""
    nav_factory = truth_nav_factory(truth_map(scenario))
    seen: dict = {}

    async def watch_hider(system) -> None:
        while system.server.game.hider_pose is None:
            await trio.sleep(0.25)
        seen["true"] = system.world.true_pose("hider")
        seen["reported"] = system.server.game.hider_pose

    async def main() -> GameReport:
        report = GameReport(scenario.name, seed)
        with Store(":memory:") as store:
            async with open_sim_system(scenario, seed=seed, store=store,
                                       nav_factory=nav_factory) as system:
                t0 = trio.current_time()
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(watch_hider, system)
                    await play_game(system, report, Budget(mapping=60.0))
                    nursery.cancel_scope.cancel()
                finish_report(report, system, t0)
        return report

    seed_trio_scheduler(seed)
    return trio.run(main, clock=virtual_clock()), seen


def test_a_benchmark_row_is_the_game_hideseek_run_plays() -> None:
    """`benchmarks.game` watches the hider without changing the game: its row has
    the trace hash of the same scenario and seed played as `hideseek run` does."""
    row = play_one(("empty", 2, 1200.0, False))
    assert row["trace_hash"] == play(load_scenario("empty"), 2).trace_hash
    assert row["hider_true_cm"] is not None and row["hider_dr_cm"] is not None


def test_hider_through_the_gap_and_seeker_find_it_on_a_true_map() -> None:
    """Gap room with a perfect map: the hider drives through the 35 cm gap into the
    alcove and reports the spot within 5 cm / 5 deg (dead reckoning); the seeker's
    second guess (the spot) finds it."""
    scenario = load_scenario("gap")
    report, seen = play_on_truth(scenario)
    assert report.outcome == "found", report.reason
    spot = scenario.hide_at
    reported = seen["reported"]  # map frame = room frame shifted by the mapper's start
    start = scenario.starts["mapper"]
    assert math.dist((reported.x + start.x, reported.y + start.y), (spot.x, spot.y)) <= 5.0
    assert abs((reported.heading_deg - spot.heading_deg + 180) % 360 - 180) <= 5.0
    true = seen["true"]
    assert true.x > 415.0  # really behind the wall, in the alcove
    assert math.dist((true.x, true.y), (spot.x, spot.y)) <= 40.0  # dead-reckoning drift


def test_run_command_prints_json_and_exits_by_outcome(capsys) -> None:
    """``hideseek run --json``: one JSON object with the documented keys; 0 when found."""
    status = main(["run", "--scenario", "empty", "--seed", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert status == (0 if out["outcome"] == "found" else 1)
    for key in ("scenario", "seed", "outcome", "sim_seconds", "wall_seconds", "real_time_factor",
                "coverage", "accuracy", "t90_s", "t99_s", "path_cm", "phases", "guesses",
                "restarts", "faults", "dropped", "resent", "messages", "trace_hash"):
        assert key in out


def test_run_command_refuses_a_bad_scenario_with_status_2(tmp_path, capsys) -> None:
    """A bad scenario file is a clear message and exit status 2, not a traceback."""
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[room]\nsize_cm = [100]\n')
    assert main(["run", "--scenario", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "Traceback" not in err


def test_a_seeker_whose_ir_sensor_is_stuck_high_reports_no_hider() -> None:
    """An IR sensor pinned at the ADC's top rail from the start: the seeker says it cannot
    tell at every guess (``not_found`` naming the sensor), never ``found`` with the hider
    elsewhere; the game ends ``not_found``."""
    base = load_scenario("empty")
    stuck = dataclasses.replace(base, faults=(
        ScheduledFault(at_s=0.0, target="seeker/ir", kind="stuck_high"),))
    report = play(stuck)
    assert report.outcome == "not_found", report.reason
    reasons = [e.split("reason=")[1] for e in report.events if "report=not_found" in e]
    assert reasons and all("pinned at an ADC rail" in r for r in reasons)
    assert not any("report=found" in e for e in report.events)


def test_a_seeker_waits_for_an_ir_sensor_pinned_for_a_while_and_then_finds_the_hider() -> None:
    """The IR sensor stuck high for 40 s from before the first look: the seeker holds its
    look (no ``found`` from the pinned sensor, no guess spent on it) and, once the sensor
    reads again, finds the hider truly in view."""
    base = load_scenario("empty")
    stuck = dataclasses.replace(base, faults=(
        ScheduledFault(at_s=40.0, target="seeker/ir", kind="stuck_high", duration_s=40.0),))
    report = play(stuck)
    assert report.outcome == "found", report.reason
    assert not any("pinned" in e for e in report.events if "report=not_found" in e)
