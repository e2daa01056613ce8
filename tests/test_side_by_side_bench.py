"""benchmarks.game --base (benchmarks.side_by_side): its rates and its refusal of bad arguments."""

from __future__ import annotations

import pytest

from benchmarks.game import main
from benchmarks.side_by_side import Played, rate


def test_rates_are_total_simulated_over_total_cpu_seconds_of_the_run_or_the_process():
    games = [Played(100.0, 2.0, 2.5, "found", "a"), Played(300.0, 8.0, 9.5, "found", "b")]
    assert rate(games) == pytest.approx(40.0)  # 400 s over 10 CPU s of the games' runs
    assert rate(games, process=True) == pytest.approx(400.0 / 12.0)  # starts included


def test_base_that_holds_no_tree_is_one_error_line_and_status_2(capsys, tmp_path):
    assert main(["--base", str(tmp_path), "--scenarios", "empty"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("benchmarks.game: ") and "no tui/cli.py" in err[0]


def test_base_with_no_rounds_is_one_error_line_and_status_2(capsys):
    assert main(["--base", ".", "--scenarios", "empty", "--rounds", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--rounds" in err[0]


def test_campaign_base_that_holds_no_tree_is_refused(tmp_path):
    from benchmarks.side_by_side import compare_campaign

    with pytest.raises(ValueError, match="holds no tree"):
        compare_campaign(str(tmp_path), 4)
    with pytest.raises(ValueError, match="must be >= 1"):
        compare_campaign(".", 0)


def test_games_per_cpu_minute_counts_the_workers_cpu():
    from benchmarks.side_by_side import Campaign

    assert Campaign(10, 120.0, 70.0, {}).games_per_cpu_min == pytest.approx(5.0)
