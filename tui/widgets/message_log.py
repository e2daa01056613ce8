"""The live message log: filterable, pausable, scrollable.

Lines arrive as a bounded tail in each snapshot; this widget appends the ones
whose ``seq`` it has not seen (see `tui.snapshot`), keeps the newest
`HISTORY` lines so a new filter can be applied to the past, and while paused
keeps collecting without scrolling, so nothing is missed on resume.
"""

from __future__ import annotations

from collections import deque

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.reactive import reactive
from textual.widgets import Input, RichLog

from tui.snapshot import LogLine

__all__ = ["MessageLog", "HISTORY", "format_line"]

#: Lines kept for re-filtering and for the view.
HISTORY = 2000


def format_line(line: LogLine) -> Text:
    """One log line: time [s], actor, decoded text."""
    if not line.actor:  # a marker from the console itself, e.g. skipped lines
        return Text(line.text, style="dim italic")
    style = "bold red" if line.text.startswith(("DROP", "CRASH")) else ""
    return Text.assemble((f"{line.time_s:7.1f} ", "dim"), (f"{line.actor:<13} ", "cyan"),
                         (line.text, style))


class MessageLog(Vertical):
    """A filter box above a scrolling log of decoded messages."""

    DEFAULT_CSS = """
    MessageLog { height: 1fr; }
    MessageLog > Input { height: 3; }
    MessageLog > RichLog { height: 1fr; }
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
        yield RichLog(max_lines=HISTORY, wrap=True, min_width=20, id="log-lines")

    def watch_paused(self, paused: bool) -> None:
        if self.is_mounted:
            self.query_one(RichLog).auto_scroll = not paused
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
        f = self.filter_text.lower()
        return not f or not line.actor or f in line.actor.lower() or f in line.text.lower()

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
        log = self.query_one(RichLog)
        for line in self.history:
            if line.seq > self._shown_seq and self.matches(line):
                log.write(format_line(line))
        self._shown_seq = self.last_seq

    def _rebuild(self) -> None:
        self.query_one(RichLog).clear()
        self._shown_seq = 0
        self._show_new()

    def shown_text(self) -> list[str]:
        """The plain text of the lines the log holds now (for tests)."""
        return [strip.text for strip in self.query_one(RichLog).lines]
