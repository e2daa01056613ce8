"""The live message log: filterable, pausable, scrollable.

Lines arrive as a bounded tail in each snapshot; this widget appends the ones
whose ``seq`` it has not seen (see `tui.snapshot`), keeps the newest
`HISTORY` lines so a new filter can be applied to the past, and while paused
keeps collecting without scrolling, so nothing is missed on resume.

The lines are drawn by `LogView`, a line-API widget over the bounded
list of matching lines that formats only the rows on screen: at full speed
hundreds of lines arrive per frame, and rendering each one as it came (as
`RichLog.write` does) cost more than the simulation itself.
"""

from __future__ import annotations

from collections import deque

from rich.cells import cell_len
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.events import MouseScrollDown, MouseScrollUp
from textual.geometry import Region
from textual.reactive import reactive
from textual.strip import Strip
from textual.widget import Widget
from textual.widgets import Input

from tui.snapshot import LogLine

__all__ = ["MessageLog", "LogView", "HISTORY", "format_line", "line_segments"]

#: Lines kept for re-filtering and for the view.
HISTORY = 2000


_DIM = Style(dim=True)
_MARKER = Style(dim=True, italic=True)
_ACTOR = Style(color="cyan")
_ALARM = Style(color="red", bold=True)


def line_segments(line: LogLine) -> list[Segment]:
    """`format_line` as segments, made directly (a `Text` costs ten times more to render)."""
    if not line.actor:
        return [Segment(line.text, _MARKER)]
    alarm = line.text.startswith(("DROP", "CRASH"))
    return [Segment(f"{line.time_s:7.1f} ", _DIM), Segment(f"{line.actor:<13} ", _ACTOR),
            Segment(line.text, _ALARM if alarm else None)]


def format_line(line: LogLine) -> Text:
    """One log line: time [s], actor, decoded text."""
    if not line.actor:  # a marker from the console itself, e.g. skipped lines
        return Text(line.text, style="dim italic")
    style = "bold red" if line.text.startswith(("DROP", "CRASH")) else ""
    return Text.assemble((f"{line.time_s:7.1f} ", "dim"), (f"{line.actor:<13} ", "cyan"),
                         (line.text, style))


class LogView(Widget, can_focus=True):
    """The lines of the log, newest last; formats only the rows it draws.

    It draws the last rows itself rather than scrolling a tall virtual
    canvas: a scroll view moved its offset on every frame while following,
    and Textual then recomposed the whole screen (about 20 widgets a frame).
    ``back`` is how many rows the view is scrolled back from the newest
    (mouse wheel, arrows, page keys, home / end while focused); at 0 it
    follows the newest. A line wider than the view ends in an ellipsis.

    | Key | Action |
    |---|---|
    | up / down | one row back / forward |
    | pageup / pagedown | one page back / forward |
    | home / end | the oldest / the newest row |
    """

    BINDINGS = [
        Binding("up", "scroll_back(1)", "Back", show=False),
        Binding("down", "scroll_back(-1)", "Forward", show=False),
        Binding("pageup", "page(1)", "Page back", show=False),
        Binding("pagedown", "page(-1)", "Page forward", show=False),
        Binding("home", "scroll_back(1000000)", "Oldest", show=False),
        Binding("end", "scroll_back(-1000000)", "Newest", show=False),
    ]

    DEFAULT_CSS = """
    LogView { height: 1fr; }
    """

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self.rows: deque[LogLine] = deque(maxlen=HISTORY)
        """The lines shown (bounded), oldest first."""
        self.follow = True
        """Keep the newest rows in view as lines are added (False while paused)."""
        self.back = 0
        """Rows the view is scrolled back from the newest (0: the newest at the bottom)."""
        self._strips: dict[int, Strip] = {}  # seq -> strip of the rows drawn lately
        self._style: Style | None = None  # the base style, until styles change
        self._frame: tuple | None = None  # size while a frame is drawn

    def add(self, lines: list[LogLine]) -> None:
        """Append lines (oldest first); a view scrolled back keeps its rows in place."""
        if not lines:
            return
        self.rows.extend(lines)
        if self.back or not self.follow:
            self.back = min(self.back + len(lines), self._max_back())
        self.refresh()

    def clear(self) -> None:
        """Remove every line."""
        self.rows.clear()
        self._strips.clear()
        self.back = 0
        self.refresh()

    def _max_back(self) -> int:
        return max(0, len(self.rows) - self.size.height)

    def action_scroll_back(self, rows: int) -> None:
        """Scroll ``rows`` back (negative: forward, towards the newest)."""
        back = max(0, min(self.back + rows, self._max_back()))
        if back != self.back:
            self.back = back
            self.refresh()

    def action_page(self, pages: int) -> None:
        self.action_scroll_back(pages * max(1, self.size.height - 1))

    def on_mouse_scroll_up(self, event: MouseScrollUp) -> None:
        event.stop()
        self.action_scroll_back(3)

    def on_mouse_scroll_down(self, event: MouseScrollDown) -> None:
        event.stop()
        self.action_scroll_back(-3)

    def render_lines(self, crop: Region) -> list[Strip]:
        # the size costs a widget lookup: read it once per frame
        self._frame = tuple(self.size)
        try:
            return super().render_lines(crop)
        finally:
            self._frame = None

    def render_line(self, y: int) -> Strip:
        width, height = self._frame or self.size
        style = self._style
        if style is None:  # `rich_style` walks every ancestor's styles: once, not per row
            style = self._style = self.rich_style
        top = max(0, len(self.rows) - height - self.back)  # index of the first row shown
        index = top + y
        if not 0 <= index < len(self.rows):
            return Strip.blank(width, style)
        line = self.rows[index]
        strip = self._strips.get(line.seq)
        if strip is None:
            if len(self._strips) > 4 * max(1, height):  # rows drawn lately only
                self._strips.clear()
            # one Strip, styled as made: each Strip made costs a handful of caches
            segs = [Segment(seg.text, style + seg.style if seg.style else style)
                    for seg in line_segments(line)]
            strip = Strip(segs, sum(cell_len(seg.text) for seg in segs))
            self._strips[line.seq] = strip
        if strip.cell_length > width > 1:  # cut: say so
            return Strip.join([strip.crop(0, width - 1), Strip([Segment("…", style)], 1)])
        return strip.crop_extend(0, width, style)

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._strips.clear()
        self._style = None


class MessageLog(Vertical):
    """A filter box above a scrolling log of decoded messages."""

    DEFAULT_CSS = """
    MessageLog { height: 1fr; }
    MessageLog > Input { height: 3; }
    MessageLog > LogView { height: 1fr; }
    """

    paused: reactive[bool] = reactive(False)
    """While paused the view does not change; lines are still collected."""
    live: reactive[bool] = reactive(True)
    """Whether the log is on screen; when not, lines are collected but not drawn."""
    filter_text: reactive[str] = reactive("")
    """Show only lines whose actor or text contains this (case-insensitive)."""

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self.history: deque[LogLine] = deque(maxlen=HISTORY)
        self.last_seq = 0
        self.skipped = 0
        self._shown_seq = 0

    def compose(self) -> ComposeResult:
        yield Input(placeholder="filter (actor or message)…", id="log-filter")
        yield LogView(id="log-lines")

    def watch_paused(self, paused: bool) -> None:
        if self.is_mounted:
            self.query_one(LogView).follow = not paused
            self.border_title = "paused" if paused else ""
            if not paused:
                self._show_new()

    def watch_live(self, live: bool) -> None:
        if live and self.is_mounted and not self.paused:
            self._show_new()

    def watch_filter_text(self) -> None:
        if self.is_mounted:
            self._rebuild()

    def on_input_changed(self, event: Input.Changed) -> None:
        event.stop()
        self.filter_text = event.value

    def matches(self, line: LogLine) -> bool:
        """Whether a line passes the filter (the console's own markers always do)."""
        return _matches(line, self.filter_text.lower())

    def add_lines(self, lines: tuple[LogLine, ...]) -> None:
        """Take the lines of a snapshot; only unseen ones (by seq) are added."""
        new = [ln for ln in lines if ln.seq > self.last_seq]
        if not new:
            return
        gap = new[0].seq - self.last_seq - 1
        if gap > 0 and self.last_seq:
            # more lines flowed than a snapshot carries: say so rather than stay silent
            self.skipped += gap
            self.history.append(LogLine(new[0].seq - 1, new[0].time_s, "", "",
                                        f"… {gap} lines skipped (more than a snapshot holds)"))
        self.history.extend(new)
        self.last_seq = new[-1].seq
        if self.live and not self.paused:
            self._show_new()

    def _show_new(self) -> None:
        shown = self._shown_seq
        f = self.filter_text.lower()
        new = []
        for line in reversed(self.history):  # the new lines are at the end
            if line.seq <= shown:
                break
            if _matches(line, f):
                new.append(line)
        new.reverse()
        self.query_one(LogView).add(new)
        self._shown_seq = self.last_seq

    def _rebuild(self) -> None:
        self.query_one(LogView).clear()
        self._shown_seq = 0
        self._show_new()

    def reset(self) -> None:
        """Forget every line (a replay that jumped back starts its log again)."""
        self.history.clear()
        self.last_seq = 0
        self._rebuild()

    def shown_text(self) -> list[str]:
        """The plain text of the lines the log holds now (for tests)."""
        return [format_line(line).plain for line in self.query_one(LogView).rows]


def _matches(line: LogLine, f: str) -> bool:
    """``f`` (lower case) in the line's actor or text; markers and an empty filter match."""
    return not f or not line.actor or f in line.actor.lower() or f in line.text.lower()
