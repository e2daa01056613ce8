"""The message log on its own: seq-based appends, gaps, filter, pause."""

from __future__ import annotations

import asyncio

from textual.app import App, ComposeResult

from tui.snapshot import LogLine
from tui.widgets import MessageLog


class LogApp(App[None]):
    def compose(self) -> ComposeResult:
        yield MessageLog()


def lines(*seqs: int, actor: str = "mapper/motor") -> tuple[LogLine, ...]:
    return tuple(LogLine(s, s / 10, actor, actor, f"MOTOR_MOVE {s}") for s in seqs)


def run(test) -> None:
    async def main():
        app = LogApp()
        async with app.run_test() as pilot:
            await test(app.query_one(MessageLog), pilot)

    asyncio.run(main())


def test_lines_already_seen_are_not_repeated():
    """Overlapping snapshot tails add each line once, in order."""

    async def test(log, pilot):
        log.add_lines(lines(1, 2, 3))
        log.add_lines(lines(2, 3, 4))
        await pilot.pause()
        assert [t.split()[-1] for t in log.shown_text()] == ["1", "2", "3", "4"]

    run(test)


def test_a_gap_is_shown_as_skipped_lines():
    """When lines were lost between snapshots, a marker says how many."""

    async def test(log, pilot):
        log.add_lines(lines(1, 2))
        log.add_lines(lines(10, 11))
        await pilot.pause()
        shown = log.shown_text()
        assert log.skipped == 7
        assert shown[2] == "… 7 lines skipped (more than a snapshot holds)"
        assert shown[3].endswith("MOTOR_MOVE 10")

    run(test)


def test_filter_keeps_matching_lines_and_markers():
    """A filter applies to past lines too; skip markers always show."""

    async def test(log, pilot):
        log.add_lines(lines(1) + lines(2, actor="mapper/lidar"))
        log.add_lines(lines(5, actor="mapper/lidar"))
        log.filter_text = "lidar"
        await pilot.pause()
        shown = log.shown_text()
        assert len(shown) == 3 and "mapper/lidar" in shown[0] and "skipped" in shown[1]

    run(test)


def test_paused_log_collects_but_does_not_show_until_resumed():
    """While paused nothing new is drawn; on resume the collected lines appear."""

    async def test(log, pilot):
        log.add_lines(lines(1))
        log.paused = True
        log.add_lines(lines(2, 3))
        await pilot.pause()
        assert len(log.shown_text()) == 1 and log.last_seq == 3
        log.paused = False
        await pilot.pause()
        assert len(log.shown_text()) == 3

    run(test)


def test_only_the_rows_on_screen_are_formatted_and_the_newest_stay_in_view():
    """Thousands of lines: the view keeps at most HISTORY, follows the newest, and
    formats only the rows it draws."""
    from tui.widgets.message_log import HISTORY, LogView

    async def test(log, pilot):
        for start in range(1, 3001, 300):
            log.add_lines(lines(*range(start, start + 300)))
        await pilot.pause()
        view = log.query_one(LogView)
        assert len(view.rows) == HISTORY and view.rows[-1].seq == 3000
        bottom = view.render_line(view.size.height - 1).text
        assert bottom.split()[:3] == ["300.0", "mapper/motor", "MOTOR_MOVE"]
        assert 0 < len(view._strips) <= 4 * view.size.height

    run(test)


def test_line_segments_read_as_the_formatted_line_with_its_styles():
    """The segments drawn say what format_line says, alarms in bold red, markers dim."""
    from tui.widgets.message_log import format_line, line_segments

    for line in (LogLine(3, 12.5, "mapper/lidar", "mapper/lidar", "LIDAR_SAMPLE 1.0"),
                 LogLine(4, 13.0, "mapper/map", "mapper/map", "DROP overflow NOOP 0"),
                 LogLine(5, 13.0, "", "", "… 7 lines skipped")):
        segs = line_segments(line)
        assert "".join(seg.text for seg in segs) == format_line(line).plain
    assert segs[0].style.dim and segs[0].style.italic
    drop = line_segments(LogLine(4, 13.0, "mapper/map", "mapper/map", "DROP overflow"))
    assert drop[-1].style.bold and drop[-1].style.color.name == "red"


def test_lines_added_while_hidden_show_the_newest_when_shown_again():
    """The log on a tab not shown yet keeps following: shown, its newest line is in
    view; a line too long for the view ends in an ellipsis."""
    from textual.widgets import Static, TabbedContent, TabPane

    from tui.widgets.message_log import LogView

    class TabsApp(App[None]):
        def compose(self) -> ComposeResult:
            with TabbedContent(id="tabs"):
                with TabPane("Other", id="other"):
                    yield Static("other")
                with TabPane("Log", id="log"):
                    yield MessageLog()

    async def main():
        app = TabsApp()
        async with app.run_test(size=(60, 20)) as pilot:
            log = app.query_one(MessageLog)
            for start in range(1, 200, 20):
                log.add_lines(lines(*range(start, start + 20)))
                await pilot.pause()
            log.add_lines((LogLine(201, 20.1, "mapper/lidar", "mapper/lidar", "X" * 120),))
            await pilot.pause()
            app.query_one(TabbedContent).active = "log"
            await pilot.pause()
            await pilot.pause()
            view = log.query_one(LogView)
            visible = view.scrollable_content_region  # less the scrollbars
            bottom = view.render_line(visible.height - 1).text[:visible.width]
            assert bottom.split()[:2] == ["20.1", "mapper/lidar"] and bottom.endswith("…")
            assert len(bottom) == visible.width

    asyncio.run(main())


def test_scrolled_back_the_rows_stay_put_and_end_follows_again():
    """Scrolled back, new lines do not move the rows in view; ``end`` shows the newest."""
    from tui.widgets.message_log import LogView

    async def test(log, pilot):
        log.add_lines(lines(*range(1, 101)))
        await pilot.pause()
        view = log.query_one(LogView)
        bottom = view.size.height - 1
        view.action_scroll_back(10)
        await pilot.pause()
        assert view.render_line(bottom).text.split()[-1] == "90"
        log.add_lines(lines(*range(101, 106)))
        await pilot.pause()
        assert view.render_line(bottom).text.split()[-1] == "90" and view.back == 15
        view.action_scroll_back(-1000000)
        await pilot.pause()
        assert view.back == 0 and view.render_line(bottom).text.split()[-1] == "105"

    run(test)
