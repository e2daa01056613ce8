"""benchmarks.speedup: its seed ranges, its rate, and its refusal of bad arguments."""

from __future__ import annotations

import pytest

from benchmarks.speedup import Game, main, parse_seeds, rate


def test_seed_ranges_and_single_seeds_expand_in_order():
    assert parse_seeds("1-3,7") == [1, 2, 3, 7]
    assert parse_seeds("2") == [2]


def test_rate_is_total_simulated_over_total_cpu_seconds():
    games = [Game(100.0, 2.0, "found", "a"), Game(300.0, 8.0, "found", "b")]
    assert rate(games) == pytest.approx(40.0)  # 400 s over 10 CPU s, not the mean of 50 and 37.5


def test_unknown_room_or_revision_is_one_error_line_and_status_2(capsys):
    assert main(["--rooms", "nowhere"]) == 2
    assert main(["--base", "no-such-revision-xyz", "--rooms", "empty"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("speedup: ") for line in err)


def test_base_tree_that_holds_no_tree_is_one_error_line_and_status_2(capsys, tmp_path):
    assert main(["--base-tree", str(tmp_path), "--rooms", "empty"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("speedup: ") and "no tui/cli.py" in err[0]
