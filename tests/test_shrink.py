"""Shrinking failing fault schedules: ddmin, the four steps on a stand-in game, real games, CLI."""

from __future__ import annotations

import argparse
import json
import pathlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supervisors.harness import shrink as shrink_pkg
from supervisors.harness.campaign import play_campaign_game
from supervisors.harness.headless import Budget
from supervisors.harness.shrink import (
    Failure,
    Played,
    ShrinkError,
    ddmin,
    play_scenario,
    scenario_toml,
    shrink_schedule,
)
from tests.test_campaign import fake_worker
from tui import cli, cmd_campaign
from world.scenario import ScheduledFault, generate_scenario, load_scenario, parse_scenario

_LOST = Failure("failed", ("liveness.ended",))
_FOUND = Failure("found", ())


def test_the_package_exports_its_public_names():
    assert all(hasattr(shrink_pkg, name) for name in shrink_pkg.__all__)


# ---------------------------------------------------------------------------- ddmin

def test_ddmin_isolates_one_culprit_among_many():
    asked = []

    def fails(xs):
        asked.append(list(xs))
        return 13 in xs

    assert ddmin(list(range(32)), fails) == [13]
    assert len(asked) <= 2 * 6  # about two tests per halving


def test_ddmin_keeps_both_elements_of_a_pair_that_fails_only_together():
    assert ddmin(list(range(10)), lambda xs: 2 in xs and 7 in xs) == [2, 7]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 30), min_size=1, max_size=12, unique=True),
       st.sets(st.integers(0, 30), min_size=1, max_size=3))
def test_ddmin_result_is_1_minimal_and_still_fails(items, needed):
    needed = needed & set(items) or {items[0]}

    def fails(xs):
        return needed <= set(xs)

    got = ddmin(items, fails)
    assert fails(got)
    assert all(not fails(got[:i] + got[i + 1:]) for i in range(len(got)))
    assert got == [x for x in items if x in got]  # order kept


# ------------------------------------------------------------------ the steps, on a stand-in game

def _active(f: ScheduledFault, t: float) -> bool:
    end = f.at_s + f.duration_s if f.duration_s > 0 else float("inf")
    return f.at_s <= t < end


def _stand_in(rule):
    """A stand-in game of 300 s: fails (mapping not done) when ``rule(faults)``; counts plays."""
    plays = []

    def play(faults):
        plays.append(faults)
        return Played(_LOST if rule(faults) else _FOUND, 300.0)

    return play, plays


_HARMLESS = (ScheduledFault(5.0, "hider/wifly", "latency", 10.0, {"added_s": 0.1}),
             ScheduledFault(30.0, "seeker/motor", "weak", 5.0, {"strength": 0.8}))
_FATAL = ScheduledFault(20.0, "mapper/lidar", "dead", 100.0, {})


def test_one_fatal_fault_among_harmless_ones_is_kept_alone_and_shortened():
    # fails when the LIDAR is dead (no milder kind) at any moment within 60..62 s
    play, _ = _stand_in(lambda fs: any(f.target == "mapper/lidar" and f.kind == "dead"
                                       and _active(f, 61.0) for f in fs))
    out = shrink_schedule((_HARMLESS[0], _FATAL, _HARMLESS[1]), play, resolution_s=0.5)
    assert [(f.target, f.kind) for f in out.shrunk] == [("mapper/lidar", "dead")]
    (f,) = out.shrunk
    assert 60.0 <= f.at_s <= 61.0 and f.at_s + f.duration_s > 61.0
    assert f.duration_s <= 1.5  # from 100 s: only the moment that matters is left
    assert out.failure == _LOST and not out.exhausted


def test_a_failure_that_needs_two_faults_keeps_both():
    def rule(fs):
        lidar = any(f.target == "mapper/lidar" and _active(f, 50.0) for f in fs)
        link = any(f.target == "mapper/wifly" and _active(f, 50.0) for f in fs)
        return lidar and link

    play, _ = _stand_in(rule)
    faults = (ScheduledFault(40.0, "mapper/lidar", "dead", 30.0, {}), *_HARMLESS,
              ScheduledFault(45.0, "mapper/wifly", "down", 20.0, {}))
    out = shrink_schedule(faults, play)
    assert sorted(f.target for f in out.shrunk) == ["mapper/lidar", "mapper/wifly"]


def test_a_device_fault_becomes_the_mildest_kind_that_still_fails():
    # any LIDAR fault but noise breaks it: dead becomes stuck, the mildest that fails
    play, _ = _stand_in(lambda fs: any(f.target == "mapper/lidar" and f.kind != "noisy"
                                       for f in fs))
    out = shrink_schedule((_FATAL,), play)
    assert [f.kind for f in out.shrunk] == ["stuck"]
    assert out.shrunk[0].params == {}
    assert any("stuck instead of dead" in s for s in out.steps)


def test_a_failure_without_faults_shrinks_to_no_faults():
    play, _ = _stand_in(lambda fs: True)
    out = shrink_schedule((_FATAL, *_HARMLESS), play)
    assert out.shrunk == () and out.runs == 2


def test_a_schedule_that_does_not_fail_is_refused():
    play, _ = _stand_in(lambda fs: False)
    with pytest.raises(ShrinkError, match="does not fail"):
        shrink_schedule((_FATAL,), play)


def test_a_different_failure_is_not_the_same_failure():
    # without the LIDAR fault the game fails differently (an invariant): that is no shrink
    def play(fs):
        if any(f.target == "mapper/lidar" for f in fs):
            return Played(_LOST, 300.0)
        return Played(Failure("found", ("no_loss.exactly_once",)), 300.0)

    out = shrink_schedule((_FATAL, *_HARMLESS), play)
    assert [f.target for f in out.shrunk] == ["mapper/lidar"]


def test_runs_are_bounded_and_what_is_left_still_fails():
    rule = lambda fs: any(f.target == "mapper/lidar" and _active(f, 61.0) for f in fs)  # noqa: E731
    play, plays = _stand_in(rule)
    out = shrink_schedule((_HARMLESS[0], _FATAL, _HARMLESS[1]), play, max_runs=4)
    assert out.exhausted and out.runs == 4 == len(plays)
    assert rule(out.shrunk)


def test_no_schedule_is_played_twice_and_the_search_is_deterministic():
    rule = lambda fs: any(f.target == "mapper/lidar" and _active(f, 61.0) for f in fs)  # noqa: E731
    play, plays = _stand_in(rule)
    first = shrink_schedule((_HARMLESS[0], _FATAL, _HARMLESS[1]), play)
    keys = [tuple((f.at_s, f.target, f.kind, f.duration_s) for f in p) for p in plays]
    assert len(keys) == len(set(keys))
    play2, _ = _stand_in(rule)
    second = shrink_schedule((_HARMLESS[0], _FATAL, _HARMLESS[1]), play2)
    assert (first.shrunk, first.runs, first.steps) == (second.shrunk, second.runs, second.steps)


# ---------------------------------------------------------------------------- scenario files

@pytest.mark.parametrize("scenario", [load_scenario("furniture"), generate_scenario(3, 1)],
                         ids=["furniture", "generated"])
def test_a_written_scenario_reads_back_as_the_same_room(scenario):
    fault = ScheduledFault(12.5, "mapper/lidar", "noisy", 3.25, {"sigma_cm": 7.0})
    back = parse_scenario(scenario_toml(scenario, faults=[fault], header=["a comment"]), "x")
    assert [list(o.exterior.coords) for o in back.obstacles] == \
        [list(o.exterior.coords) for o in scenario.obstacles]
    assert (back.room_size, back.starts, back.hide_at, back.seek_at, back.devices) == \
        (scenario.room_size, scenario.starts, scenario.hide_at, scenario.seek_at,
         scenario.devices)
    assert back.faults == (fault,)


# ---------------------------------------------------------------------------- real games

_ROOM = """name = "empty-with-faults"
[room]
size_cm = [400, 300]
[rovers]
mapper = [50, 50, 0]
hider = [50, 110, 0]
seeker = [50, 170, 0]
[game]
hide_at = [330, 240, 90]
seek_at = [[200, 150], [330, 240]]
"""
_FAULTS = """
[[faults]]
at_s = 5
target = "hider/wifly"
kind = "latency"
duration_s = 10
params = { added_s = 0.1 }
[[faults]]
at_s = 5
target = "mapper/lidar"
kind = "dead"
[[faults]]
at_s = 20
target = "seeker/motor"
kind = "weak"
duration_s = 5
params = { strength = 0.8 }
"""


def test_shrinking_a_real_game_keeps_the_fatal_fault_shortened_and_the_file_reproduces(
        tmp_path: pathlib.Path, capsys):
    """A permanent LIDAR death before the mapper saw the room among two harmless faults
    (mapping budget 120 s, seed 7)."""
    src = tmp_path / "three.toml"
    src.write_text(_ROOM + _FAULTS)
    out = tmp_path / "shrunk.toml"
    status = cli.main(["shrink", "--scenario", str(src), "--seed", "7", "--budget", "120",
                       "--out", str(out), "--resolution", "30", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 0 and report["reproduces"] and report["same_trace"]
    assert report["failure"] == "failed, broke liveness.ended"
    (kept,) = report["shrunk_faults"]
    assert kept["target"] == "mapper/lidar"
    assert 0 < kept["duration_s"] < 120  # was: until cleared
    assert report["runs"] <= 100 and not report["exhausted"]
    shrunk = load_scenario(str(out))
    assert len(shrunk.faults) == 1
    again = play_scenario(shrunk, 7, Budget(mapping=120.0), 600.0)
    assert again.failure == Failure("failed", ("liveness.ended",))
    assert cli.main(["run", "--scenario", str(out), "--seed", "7", "--budget", "120",
                     "--json"]) == 1
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["outcome"] == "failed"


# ---------------------------------------------------------------------------- bad input

def _shrink_status(args: list[str], capsys) -> tuple[int, str]:
    status = cli.main(["shrink", *args])
    return status, capsys.readouterr().err.strip()


def test_no_such_campaign_reference_is_one_line_and_status_2(tmp_path, capsys):
    status, err = _shrink_status(["--campaign", "seven", "--out", str(tmp_path / "x.toml")],
                                 capsys)
    assert status == 2 and err.count("\n") == 0 and "SEED:INDEX" in err


def test_a_missing_scenario_file_is_one_line_and_status_2(tmp_path, capsys):
    status, err = _shrink_status(["--scenario", str(tmp_path / "none.toml"), "--out",
                                  str(tmp_path / "x.toml")], capsys)
    assert status == 2 and err.count("\n") == 0 and "no such scenario" in err


def test_an_out_file_in_no_folder_is_refused_before_any_game(tmp_path, capsys):
    status, err = _shrink_status(["--campaign", "1:0", "--out",
                                  str(tmp_path / "no" / "x.toml")], capsys)
    assert status == 2 and "--out" in err


def test_a_scenario_that_does_not_fail_is_one_line_and_status_2(tmp_path, capsys):
    src = tmp_path / "calm.toml"
    src.write_text(_ROOM)
    status, err = _shrink_status(["--scenario", str(src), "--seed", "7", "--out",
                                  str(tmp_path / "x.toml")], capsys)
    assert status == 2 and err.count("\n") == 0 and "does not fail" in err
    assert not (tmp_path / "x.toml").exists()


# ---------------------------------------------------------------------------- campaign --shrink

#: game 11 of this campaign fails for real (mapping not done in 60 s: the mapper's LIDAR
#: sends garbage for 14 s, then goes dead for 17 s)
_FAILING = ("--seed", "6", "--mode", "overlapping", "--scenarios", "empty", "--faults",
            "lidar,motor,encoder", "--budget", "60", "--window", "5-40")


def _only_game_11_real(ref: str, *, determinism: bool = False,
                      wall_timeout_s: float | None = None) -> dict:
    if ref.startswith("6:11,"):
        return play_campaign_game(ref, baseline=False, wall_timeout_s=wall_timeout_s)
    return fake_worker(ref, determinism=determinism, wall_timeout_s=wall_timeout_s)


def test_campaign_shrink_writes_each_failure_as_a_scenario_that_fails_alike(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    args = parser.parse_args([*_FAILING, "-n", "12", "--workers", "0", "--replay-every", "0",
                              "--shrink", "--shrink-dir", str(tmp_path), "--shrink-runs", "2",
                              "--out", ":memory:", "--json", "--no-progress"])
    assert cmd_campaign.run(args, worker=_only_game_11_real) == 1
    summary = json.loads(capsys.readouterr().out)
    assert [f["index"] for f in summary["failures"]] == [11]
    (shrunk,) = summary["shrunk"]
    assert shrunk["index"] == 11 and shrunk["exhausted"] and shrunk["reproduces"]
    assert shrunk["runs"] == 3  # two for the search (its budget), one for the file
    assert shrunk["file"] == str(tmp_path / "campaign-6-11.toml")
    # the file holds faults of the game's own (two search runs need not drop any of three)
    kept = load_scenario(shrunk["file"]).faults
    game = summary["failures"][0]["faults"]
    assert 1 <= len(kept) <= len(game)
    assert {f"{f.target} {f.kind} at {f.at_s:g} s" for f in kept} <= {
        g.split(" for ")[0] for g in game}
