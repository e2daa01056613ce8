"""TextLines: lines of text repainted line by line (the game panel and queue table)."""

from __future__ import annotations

import asyncio

from rich.text import Text
from textual.app import App, ComposeResult

from tui.widgets.text_lines import TextLines


class LinesApp(App):
    def compose(self) -> ComposeResult:
        yield TextLines(id="lines")


def run(test) -> None:
    async def main() -> None:
        app = LinesApp()
        async with app.run_test(size=(20, 10)) as pilot:
            await test(app.query_one(TextLines), pilot)

    asyncio.run(main())


def shown(widget: TextLines) -> list[str]:
    return [widget.render_line(y).text for y in range(widget.size.height)]


def test_only_changed_lines_are_repainted_and_drawn_again() -> None:
    """A new set of lines marks only the lines that differ (in text or style) for repaint."""
    async def test(widget: TextLines, pilot) -> None:
        widget.set_lines([Text("phase idle"), Text("t 1.0 s"), Text("mapper")])
        await pilot.pause()
        assert widget.size.height == 3 and widget.repainted == 3
        assert [s.rstrip() for s in shown(widget)] == ["phase idle", "t 1.0 s", "mapper"]
        widget.set_lines([Text("phase idle"), Text("t 2.0 s"), Text("mapper", style="bold")])
        assert widget.repainted == 5  # line 0 is the same
        await pilot.pause()
        assert shown(widget)[1].rstrip() == "t 2.0 s"
        assert widget.render_line(2).text.rstrip() == "mapper"
        assert any(seg.style and seg.style.bold for seg in widget.render_line(2))

    run(test)


def test_a_new_number_of_lines_changes_the_height() -> None:
    """More lines: a new layout, the widget grows to show them all."""
    async def test(widget: TextLines, pilot) -> None:
        widget.set_lines([Text("a")])
        await pilot.pause()
        assert widget.size.height == 1
        widget.set_lines([Text("a"), Text("b"), Text("c"), Text("d")])
        await pilot.pause()
        assert widget.size.height == 4 and shown(widget)[3].rstrip() == "d"

    run(test)


def test_a_long_line_ends_in_an_ellipsis_and_never_wraps() -> None:
    """A line wider than the widget is cut with an ellipsis, still one line."""
    async def test(widget: TextLines, pilot) -> None:
        widget.set_lines([Text("x" * 50), Text("short")])
        await pilot.pause()
        assert widget.size.height == 2
        first = shown(widget)[0]
        assert len(first) == 20 and first.endswith("…")

    run(test)
