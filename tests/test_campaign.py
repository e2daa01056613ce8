"""Fault campaigns: planner, game references, summary, store, pool and CLI (stand-in games)."""

from __future__ import annotations

import argparse
import json
import sqlite3
import subprocess
import sys
from collections import Counter

import pytest

from supervisors.harness.campaign import (
    ACTORS_BY_ROLE,
    FAULT_LABELS,
    CampaignConfig,
    CampaignError,
    CampaignStore,
    parse_game_ref,
    plan_game,
    run_campaign,
    select_kinds,
    summarize,
)
from tui import cmd_campaign
from world.faults import check_fault, is_actor_fault
from world.scenario import builtin_scenarios


def fake_worker(ref: str, *, determinism: bool = False,
                wall_timeout_s: float | None = None) -> dict:
    """A stand-in game: fails when an actor crash was drawn, finds the hider otherwise."""
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    crashed = "actor:crash" in spec.labels
    return {
        "index": index, "ref": spec.ref, "reproduce": spec.reproduce, "room": spec.room,
        "run_seed": spec.run_seed,
        "faults": [{"label": lab, "target": f.target, "kind": f.kind, "at_s": f.at_s,
                    "duration_s": f.duration_s, "params": dict(f.params)}
                   for lab, f in zip(spec.labels, spec.faults, strict=True)],
        "outcome": "failed" if crashed else "found",
        "reason": "mapping did not finish" if crashed else "",
        "violations": ["liveness.ended: mapping did not finish"] if crashed else [],
        "faults_fired": len(spec.faults), "restarts": 1, "resent": 2, "dropped": 0,
        "sim_s": 300.0, "wall_s": 0.01, "trace_hash": f"h{spec.run_seed}",
        "replay_hash": f"h{spec.run_seed}" if determinism else None, "events": {},
    }


# ---------------------------------------------------------------------------- planner

def test_game_is_a_pure_function_of_seed_and_index():
    """Planning game i twice gives the same game; another index or seed gives another."""
    config = CampaignConfig(7)
    assert plan_game(config, 3) == plan_game(config, 3)
    assert plan_game(config, 3).run_seed != plan_game(config, 4).run_seed
    assert plan_game(CampaignConfig(8), 3).run_seed != plan_game(config, 3).run_seed


def test_single_mode_draws_exactly_one_valid_fault_per_game():
    """Every game of a single-fault campaign has one fault, on a target that exists."""
    config = CampaignConfig(1, mode="single")
    seen = Counter()
    for i in range(300):
        spec = plan_game(config, i)
        assert len(spec.faults) == 1 and len(spec.labels) == 1
        f, label = spec.faults[0], spec.labels[0]
        seen[label] += 1
        lo, hi = config.window_s
        assert lo <= f.at_s <= hi
        role, name = f.target.split("/")
        if is_actor_fault(f.kind):
            assert label == f"actor:{f.kind}" and name in ACTORS_BY_ROLE[role]
        else:
            assert label.split(":")[1] == f.kind
            check_fault(f.target, f.kind, f.duration_s, dict(f.params))  # raises if invalid
    assert set(seen) == set(FAULT_LABELS)


def test_overlapping_mode_draws_zero_to_three_faults():
    """Overlapping games have 0..3 faults, and every count occurs."""
    counts = Counter(len(plan_game(CampaignConfig(2, mode="overlapping"), i).faults)
                     for i in range(200))
    assert set(counts) == {0, 1, 2, 3}


def test_none_mode_draws_no_faults():
    assert all(plan_game(CampaignConfig(2, mode="none"), i).faults == () for i in range(20))


def test_kinds_restrict_what_is_drawn():
    """Only the chosen fault kinds are drawn."""
    config = CampaignConfig(3, kinds=select_kinds("wifly,crash"))
    labels = {plan_game(config, i).labels[0] for i in range(100)}
    assert labels == {"wifly:down", "wifly:loss", "wifly:corrupt", "wifly:latency",
                      "actor:crash"}


def test_select_kinds_accepts_labels_devices_and_kinds():
    assert select_kinds(None) == FAULT_LABELS
    assert select_kinds("lidar:dead") == ("lidar:dead",)
    assert select_kinds("stuck") == ("lidar:stuck", "encoder:stuck")
    assert select_kinds("actor") == ("actor:crash", "actor:hang", "actor:flood")


def test_select_kinds_rejects_an_unknown_kind():
    with pytest.raises(CampaignError, match="unknown fault kind 'melted'"):
        select_kinds("wifly,melted")


def test_rooms_go_round_robin_or_are_generated():
    names = builtin_scenarios()
    config = CampaignConfig(1)
    assert [plan_game(config, i).room for i in range(len(names) + 1)] == names + names[:1]
    gen = plan_game(CampaignConfig(1, generated=True), 5)
    assert gen.room == "generated"
    assert gen.scenario().source == "generated:1/5"


def test_scenario_carries_the_fault_schedule():
    spec = plan_game(CampaignConfig(4, mode="overlapping", rooms=("empty",)), 11)
    scenario = spec.scenario()
    assert scenario.name == "empty"
    assert set(scenario.faults) == set(spec.faults)
    assert [f.at_s for f in scenario.faults] == sorted(f.at_s for f in scenario.faults)


# ---------------------------------------------------------------------------- references

def test_default_game_ref_is_seed_and_index():
    assert CampaignConfig(7).game_ref(42) == "7:42"
    assert plan_game(CampaignConfig(7), 42).reproduce == "hideseek run --campaign 7:42"


@pytest.mark.parametrize("config", [
    CampaignConfig(7),
    CampaignConfig(9, mode="overlapping", generated=True),
    CampaignConfig(0, mode="none", rooms=("empty", "gap")),
    CampaignConfig(3, kinds=("wifly:loss", "actor:hang"), window_s=(1.0, 50.0),
                   mapping_budget_s=300.0),
], ids=["default", "overlapping-generated", "none-rooms", "kinds-window-budget"])
def test_game_ref_round_trips(config):
    """A reference names the game and every non-default option."""
    assert parse_game_ref(config.game_ref(12)) == (config, 12)


@pytest.mark.parametrize("ref, message", [
    ("7", "must start with SEED:INDEX, got '7'"),
    ("7:x", "must start with SEED:INDEX"),
    ("7:-1", "game index must be within"),
    ("7:1,mode", "option must be key=value, got 'mode'"),
    ("7:1,mode=sometimes", "mode must be single, overlapping, none, got 'sometimes'"),
    ("7:1,colour=red", "unknown game reference option 'colour'"),
    ("7:1,rooms=attic", "unknown built-in room 'attic'"),
    ("7:1,window=9", "bad game reference option 'window=9'"),
    ("7:1,faults=melted", "unknown fault kind 'melted'"),
    ("", "got nothing"),
])
def test_bad_game_refs_are_refused_clearly(ref, message):
    with pytest.raises(CampaignError, match=message.replace("(", r"\(")):
        parse_game_ref(ref)


# ---------------------------------------------------------------------------- summary

def test_summary_counts_outcomes_fault_kinds_and_failures():
    """The summary's totals, per-kind counts and failure list follow the results."""
    config = CampaignConfig(5, kinds=("actor:crash", "wifly:loss"))
    results = [fake_worker(config.game_ref(i), determinism=i == 0) for i in range(40)]
    s = summarize(config, results, wall_s=30.0, workers=2)
    crashed = [r for r in results if r["outcome"] == "failed"]
    assert 0 < len(crashed) < 40
    assert s["games"] == 40 and s["found"] == 40 - len(crashed) and s["failed"] == len(crashed)
    assert s["success_rate"] == pytest.approx((40 - len(crashed)) / 40)
    assert s["fault_kinds"]["actor:crash"] == {"injected": len(crashed), "recovered": 0,
                                               "failed": len(crashed), "not_reached": 0}
    assert s["fault_kinds"]["wifly:loss"]["recovered"] == 40 - len(crashed)
    assert s["violations"] == {"liveness.ended": len(crashed)}
    assert [f["index"] for f in s["failures"]] == sorted(r["index"] for r in crashed)
    assert s["failures"][0]["reproduce"].startswith("hideseek run --campaign 5:")
    assert s["restarts"] == 40 and s["resent"] == 80
    assert s["determinism"] == {"replayed": 1, "mismatched": 0}
    assert s["games_per_wall_minute"] == 80.0


def test_summary_counts_games_the_operators_retries_found():
    """Found games that needed the wider search or a second hide are counted apart; a game
    that needed them and was still lost is not."""
    config = CampaignConfig(5, kinds=("wifly:loss",))
    results = [fake_worker(config.game_ref(i)) for i in range(6)]
    results[0].update(wider_search=True)
    results[1].update(hide_attempts=2)
    results[2].update(wider_search=True, hide_attempts=2, outcome="not_found")
    s = summarize(config, results, wall_s=30.0, workers=2)
    assert (s["found_by_wider_search"], s["found_after_second_hide"]) == (1, 1)


def test_summary_counts_faults_after_the_end_as_not_reached():
    config = CampaignConfig(5, kinds=("wifly:loss",))
    r = fake_worker(config.game_ref(0))
    r["sim_s"] = r["faults"][0]["at_s"] - 1.0
    s = summarize(config, [r], wall_s=1.0, workers=1)
    assert s["fault_kinds"]["wifly:loss"]["not_reached"] == 1
    assert s["fault_kinds"]["wifly:loss"]["injected"] == 0


def test_summary_flags_a_replay_with_another_hash():
    config = CampaignConfig(5, kinds=("wifly:loss",))
    r = fake_worker(config.game_ref(0), determinism=True)
    r["replay_hash"] = "other"
    assert summarize(config, [r], wall_s=1.0, workers=1)["determinism"]["mismatched"] == 1


# ---------------------------------------------------------------------------- running

def test_run_in_process_yields_every_game_once():
    results = list(run_campaign(CampaignConfig(1), 5, workers=0, worker=fake_worker))
    assert sorted(r["index"] for r in results) == [0, 1, 2, 3, 4]


def test_run_replays_every_kth_game():
    results = list(run_campaign(CampaignConfig(1), 7, workers=0, worker=fake_worker,
                                determinism_every=3))
    assert sorted(r["index"] for r in results if r["replay_hash"]) == [0, 3, 6]


def test_run_in_a_spawn_pool_gives_the_same_results_as_in_process():
    """Two worker processes play the same games as the calling process would."""
    config = CampaignConfig(11, mode="overlapping")
    local = sorted(run_campaign(config, 6, workers=0, worker=fake_worker),
                   key=lambda r: r["index"])
    pooled = sorted(run_campaign(config, 6, workers=2, worker=fake_worker),
                    key=lambda r: r["index"])
    assert pooled == local


@pytest.mark.parametrize("kwargs, message", [
    ({"games": 0}, "games must be within 1..1000000, got 0"),
    ({"games": 3, "workers": -1}, "workers must be within 0..256, got -1"),
    ({"games": 3, "determinism_every": -2}, "determinism_every must be >= 0, got -2"),
])
def test_run_refuses_bad_counts(kwargs, message):
    with pytest.raises(CampaignError, match=message):
        list(run_campaign(CampaignConfig(1), worker=fake_worker, **kwargs))


def test_store_keeps_every_game(tmp_path):
    path = str(tmp_path / "c.sqlite")
    config = CampaignConfig(2)
    with CampaignStore(path) as store:
        cid = store.new_campaign(config, 0.0)
        for i in (1, 0):
            store.add_game(cid, fake_worker(config.game_ref(i)))
        store.finish(cid, {"games": 2})
    with CampaignStore(path) as store:
        rows = store.games(cid)
    assert [(r[0], r[1]) for r in rows] == [(0, "found"), (1, "found")]
    db = sqlite3.connect(path)
    assert json.loads(db.execute("SELECT summary FROM campaigns").fetchone()[0]) == {"games": 2}


def test_store_refuses_an_unwritable_path(tmp_path):
    with pytest.raises(CampaignError, match="cannot open campaign store"):
        CampaignStore(str(tmp_path / "no" / "such" / "dir.sqlite"))


# ---------------------------------------------------------------------------- command line

def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_cli_json_summary_and_exit_status(tmp_path, capsys):
    """--json prints one JSON object with the failures and their reproduce commands."""
    out = str(tmp_path / "c.sqlite")
    status = cmd_campaign.run(_args("-n", "12", "--seed", "5", "--workers", "0",
                                    "--faults", "actor:crash,wifly:loss", "--json",
                                    "--out", out, "--no-progress"), worker=fake_worker)
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["games"] == 12
    assert status == (1 if summary["failures"] else 0)
    assert all(f["reproduce"].startswith("hideseek run --campaign 5:") and
               ",faults=wifly:loss+actor:crash" in f["reproduce"] for f in summary["failures"])
    assert len(sqlite3.connect(out).execute("SELECT * FROM campaign_games").fetchall()) == 12


def test_cli_table_and_no_progress_off_a_terminal(tmp_path, capsys):
    """The table on stdout; the progress bar (tui/progress.py) only on a terminal."""
    status = cmd_campaign.run(_args("--quick", "--workers", "0", "--faults", "wifly:loss",
                                    "--out", ":memory:"), worker=fake_worker)
    captured = capsys.readouterr()
    assert status == 0
    assert captured.err == ""
    assert "wifly:loss" in captured.out and "success rate 100.0 %" in captured.out


@pytest.mark.parametrize("argv, message", [
    (["--faults", "melted"], "unknown fault kind 'melted'"),
    (["--scenarios", "attic"], "unknown built-in room 'attic'"),
    (["-n", "0"], "-n must be within 1..1000000, got 0"),
    (["--window", "soon"], "--window must be A-B in seconds, got 'soon'"),
    (["--seed", "-3"], "seed must be an integer >= 0, got -3"),
    (["--max-wall", "0"], "--max-wall must be within (0, 1e6] minutes, got 0.0"),
])
def test_cli_bad_input_exits_2_with_a_message(argv, message, capsys):
    status = cmd_campaign.run(_args(*argv, "--out", ":memory:"), worker=fake_worker)
    assert status == 2
    assert capsys.readouterr().err.startswith(f"hideseek campaign: {message}")


def test_cli_quick_campaign_with_real_games_in_a_spawn_pool(tmp_path, capsys):
    """The CI-sized campaign: real games (short budget) in two worker processes.

    6 s cannot map a room, so every game fails with liveness.ended; what is
    checked is the plumbing: every game played and stored, the first replayed
    with the same hash, each failure with the command that reproduces it.
    """
    out = str(tmp_path / "c.sqlite")
    status = cmd_campaign.run(_args("--quick", "-n", "3", "--seed", "4", "--scenarios", "empty",
                                    "--faults", "actor:crash", "--window", "1-4",
                                    "--budget", "6", "--workers", "2", "--json",
                                    "--out", out, "--no-progress"))
    summary = json.loads(capsys.readouterr().out)
    assert status == 1
    assert (summary["games"], summary["failed"], summary["workers"]) == (3, 3, 2)
    assert summary["determinism"] == {"replayed": 1, "mismatched": 0}
    assert summary["fault_kinds"]["actor:crash"]["injected"] == 3
    assert [f["reproduce"] for f in summary["failures"]] == [
        f"hideseek run --campaign 4:{i},rooms=empty,faults=actor:crash,window=1-4,budget=6"
        for i in range(3)]
    assert all(f["violations"][0].startswith("liveness.ended: mapping did not finish")
               and f["without_faults"] == "failed" for f in summary["failures"])
    rows = sqlite3.connect(out).execute("SELECT idx, trace_hash FROM campaign_games").fetchall()
    assert sorted(i for i, _ in rows) == [0, 1, 2] and all(h for _, h in rows)


def test_cli_table_prints_each_failure_with_its_reproduce_command(capsys):
    status = cmd_campaign.run(_args("-n", "12", "--seed", "5", "--workers", "0",
                                    "--faults", "actor:crash,wifly:loss", "--out", ":memory:",
                                    "--no-progress"), worker=fake_worker)
    out = capsys.readouterr().out
    failed = [line for line in out.splitlines() if line.startswith("  FAILED game ")]
    commands = [line.strip() for line in out.splitlines() if "reproduce:" in line]
    assert status == 1 and failed and len(commands) == len(failed)
    index = int(failed[0].split()[2])
    assert commands[0] == (f"reproduce: hideseek run --campaign 5:{index},"
                           "faults=wifly:loss+actor:crash")


@pytest.mark.parametrize("ref, message", [
    ("1:x", "game reference must start with SEED:INDEX, got '1:x'"),
    ("1:2,faults=melted", "unknown fault kind 'melted'"),
])
def test_run_refuses_a_bad_campaign_reference_with_exit_2(ref, message, capsys):
    from tui.cli import main  # noqa: PLC0415

    assert main(["run", "--campaign", ref]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"hideseek run: {message}")
    assert "Traceback" not in captured.err


def test_cli_max_wall_stops_and_summarises_the_games_done(capsys):
    """Out of wall time after the first game: the summary covers it and says why, exit 130."""
    status = cmd_campaign.run(_args("-n", "5", "--workers", "0", "--faults", "wifly:loss",
                                    "--max-wall", "1e-9", "--json", "--out", ":memory:",
                                    "--no-progress"), worker=fake_worker)
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert status == 130
    assert (summary["games"], summary["games_requested"]) == (1, 5)
    assert summary["stopped_early"] == "out of wall time (1e-09 min)"
    assert "out of wall time (1e-09 min) after 1 of 5 games" in captured.err


def test_cli_without_max_wall_plays_every_game(capsys):
    status = cmd_campaign.run(_args("-n", "3", "--workers", "0", "--faults", "wifly:loss",
                                    "--json", "--out", ":memory:", "--no-progress"),
                              worker=fake_worker)
    summary = json.loads(capsys.readouterr().out)
    assert status == 0 and summary["games"] == 3 and summary["stopped_early"] is None


def test_cli_summary_records_the_code_version_and_warns_when_it_changed(monkeypatch, capsys):
    """Games replay only with the code they were played with: a change mid-campaign is told."""
    versions = iter(["abc123", "def456"])
    monkeypatch.setattr(cmd_campaign, "code_version", lambda: next(versions))
    args = ("-n", "2", "--workers", "0", "--faults", "wifly:loss", "--out", ":memory:",
            "--no-progress")
    assert cmd_campaign.run(_args(*args), worker=fake_worker) == 0
    assert ("WARNING: the code changed during the campaign (abc123 -> def456)"
            in capsys.readouterr().out)
    monkeypatch.setattr(cmd_campaign, "code_version", lambda: "abc123")
    assert cmd_campaign.run(_args(*args, "--json"), worker=fake_worker) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["code"] == {"at_start": "abc123", "at_end": "abc123"}
    assert "WARNING" not in captured.out + captured.err


def test_code_version_names_this_checkout():
    """In a git checkout: the commit (12 hex digits), ``-dirty`` with uncommitted changes."""
    import shutil  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    root = Path(cmd_campaign.__file__).resolve().parents[1]
    if shutil.which("git") is None or not (root / ".git").exists():
        pytest.skip("not a git checkout")
    version = cmd_campaign.code_version()
    assert version is not None
    head = version.removesuffix("-dirty")
    assert len(head) == 12 and all(c in "0123456789abcdef" for c in head)


def test_the_campaign_package_exports_its_public_names():
    from supervisors.harness import campaign  # noqa: PLC0415

    assert all(hasattr(campaign, name) for name in campaign.__all__)


def test_a_pool_worker_imports_a_games_modules_at_its_start_and_freezes_them():
    """`start_worker` (the local pool's initializer) imports navigation, not the first game,
    and leaves those objects out of the cyclic collector's generations."""
    code = ("import gc, sys\n"
            "from supervisors.harness.campaign.local import start_worker\n"
            "assert gc.get_freeze_count() == 0\n"
            "start_worker()\n"
            "print(gc.get_freeze_count(), gc.isenabled(),"
            " 'actors.firmware.nav.factory' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert int(out[0]) > 10_000 and out[1:] == ["True", "True"]
