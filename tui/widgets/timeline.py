"""The timeline of game events and faults, newest last."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import RichLog

from tui.snapshot import TimelineEvent

__all__ = ["Timeline", "format_event"]

_KIND_STYLE = {"fault": "bold red", "crash": "red", "clear": "green", "restart": "yellow",
               "phase": "bold cyan", "link": "magenta", "export": "blue"}


def format_event(event: TimelineEvent) -> Text:
    """One timeline line: time [s], kind, text."""
    return Text.assemble((f"{event.time_s:9.2f} ", "dim"),
                         (f"{event.kind:<7} ", _KIND_STYLE.get(event.kind, "")), event.text)


class Timeline(RichLog):
    """Appends the events of each snapshot it has not seen yet (by seq)."""

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(max_lines=1000, wrap=True, name=name, id=id, classes=classes)
        self.last_seq = 0

    def add_events(self, events: tuple[TimelineEvent, ...]) -> None:
        """Append the unseen events."""
        for event in events:
            if event.seq > self.last_seq:
                self.write(format_event(event))
                self.last_seq = event.seq
