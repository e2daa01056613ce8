"""Progress on standard error only on a terminal (tui/progress.py), and the run counts a
shrink prints, writes into its file and reports agree."""

from __future__ import annotations

import io
import re

from supervisors.harness.shrink import Failure, Played, shrink_game
from supervisors.harness.shrink import game as shrink_game_module
from tests.test_shrink import _FAULTS, _ROOM
from tui.progress import progress_bar
from world.scenario import parse_scenario


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_bar_is_drawn_on_a_terminal_and_nothing_elsewhere() -> None:
    for stream, drawn in ((_Terminal(), True), (io.StringIO(), False)):
        with progress_bar("games", 3, stream=stream) as bar:
            for _ in range(3):
                bar.advance(note="0 failed")
        assert bar.done == 3 and bar.shown == drawn
        text = stream.getvalue()
        assert ("games" in text and "3/3" in text and "0 failed" in text) if drawn else not text


def test_a_bar_turned_off_draws_nothing_on_a_terminal() -> None:
    stream = _Terminal()
    with progress_bar("games", 2, stream=stream, enabled=False) as bar:
        bar.advance(2)
    assert stream.getvalue() == "" and bar.done == 2


def test_the_shrunk_files_header_and_the_report_count_the_same_runs(monkeypatch) -> None:
    """Every game played is counted once, the check of the written file included: in the
    report, in the file's header and by the progress callback."""
    def play(scenario, run_seed, budget, wall_timeout_s) -> Played:  # LIDAR death fails
        dead = any(f.target == "mapper/lidar" and f.kind == "dead" for f in scenario.faults)
        return Played(Failure.of("failed" if dead else "found", []), 100.0, "h")

    monkeypatch.setattr(shrink_game_module, "play_scenario", play)
    told: list[int] = []
    report = shrink_game(parse_scenario(_ROOM + _FAULTS, "three"), 7, on_run=told.append)
    header = re.search(r"faults -> \d+, (\d+) runs", report["toml"])
    assert header is not None and int(header.group(1)) == report["runs"]
    assert told == list(range(1, report["runs"] + 1))
    assert report["shrunk"] and report["reproduces"]
