"""benchmarks.viewpoint: the scoring it times finds viewpoints; bad options are one line."""

from __future__ import annotations

import json

from benchmarks.viewpoint import main


def test_the_benchmark_scores_the_furnished_room_and_prints_json(capsys) -> None:
    assert main(["--reps", "1", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["reps"] == 1 and figures["viewpoints"] > 0
    assert figures["best_ms"] == figures["median_ms"] >= 0


def test_bad_reps_is_one_line_and_status_2(capsys) -> None:
    assert main(["--reps", "0"]) == 2
    assert capsys.readouterr().err == "viewpoint: --reps must be at least 1, got 0\n"
