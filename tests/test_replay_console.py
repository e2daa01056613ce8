"""The replay console tells the truth: the footer while paused, the speed label, the seek
prompt at 80 columns, and ``--at`` past the end refused (tui/replay, tui/cmd_replay.py)."""

from __future__ import annotations

import asyncio
from typing import Any

from tests.test_replay import recording  # noqa: F401 - the recorded game, module-scoped
from tests.test_tui_app import press, until
from tui.cli import main
from tui.replay import ReplaySystem
from tui.replay.app import REPLAY_SPEEDS, ReplayApp
from tui.replay.seek_dialog import TITLE, SeekDialog
from tui.widgets.game_panel import speed_text


def _footer_labels(app: ReplayApp) -> list[str]:
    return [str(key.description) for key in app.query("FooterKey")]


def test_the_footer_offers_resume_while_paused_and_pause_while_playing(
        recording: Any) -> None:  # noqa: F811
    rec, _ = recording
    app = ReplayApp(ReplaySystem(rec, paused=True))

    async def go() -> None:
        async with app.run_test(size=(80, 24)) as pilot:
            await until(lambda: app.snapshot is not None, "the first snapshot")
            await pilot.pause()
            labels = _footer_labels(app)
            assert "Resume" in labels and "Pause" not in labels, labels
            press(app, "space")
            await until(lambda: app.snapshot is not None and not app.snapshot.paused,
                        "playing")
            await until(lambda: "Pause" in _footer_labels(app), "the footer's Pause")
            assert "Resume" not in _footer_labels(app)

    asyncio.run(go())


def test_the_fastest_replay_speed_is_labelled_x64_as_speed_64_is(recording: Any) -> None:  # noqa: F811
    """Three ``]`` from x1 reach x64, the label ``--speed 64`` and the docs give."""
    rec, _ = recording
    app = ReplayApp(ReplaySystem(rec, paused=True))
    assert REPLAY_SPEEDS[-1] == 64.0

    async def go() -> None:
        async with app.run_test(size=(100, 30)) as pilot:
            await until(lambda: app.snapshot is not None, "the first snapshot")
            for expected in REPLAY_SPEEDS[1:]:
                press(app, "right_square_bracket")
                await until(lambda e=expected: app.snapshot.speed == e, f"x{expected:g}")
                await pilot.pause()
            press(app, "right_square_bracket")  # already the fastest: stays
            await pilot.pause()
            assert app.snapshot.speed == 64.0

    asyncio.run(go())
    assert speed_text(64.0, False) == "x64" and speed_text(64.0, True) == "paused x64"


def test_the_seek_prompt_title_fits_at_80_columns(recording: Any) -> None:  # noqa: F811
    rec, _ = recording
    app = ReplayApp(ReplaySystem(rec, paused=True))

    async def go() -> None:
        async with app.run_test(size=(80, 24)) as pilot:
            await until(lambda: app.snapshot is not None, "the first snapshot")
            press(app, "t")
            await until(lambda: isinstance(app.screen, SeekDialog), "the seek dialog")
            await pilot.pause()
            title = app.screen.query_one("#seek-title")
            lines = TITLE.splitlines()
            assert title.region.width >= max(len(line) for line in lines)
            assert title.region.height == len(lines)
            assert title.region.right <= 80

    asyncio.run(go())


def test_at_past_the_end_is_one_line_and_status_2(recording: Any, capsys) -> None:  # noqa: F811
    rec, _ = recording
    assert main(["replay", str(rec.path), "--at", "9999"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line == (f"hideseek replay: --at must be within the recording, {rec.start_s:.1f} "
                    f"to {rec.end_s:.1f} s, got 9999")
