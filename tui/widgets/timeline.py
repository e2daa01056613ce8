"""The timeline of game events and faults, newest last."""

from __future__ import annotations

from collections import deque

from rich.text import Text
from textual.widgets import RichLog

from tui.snapshot import TimelineEvent

__all__ = ["Timeline", "format_event"]

#: Events kept (and shown) at most.
PENDING = 1000
_KIND_STYLE = {"fault": "bold red", "crash": "red", "clear": "green", "restart": "yellow",
               "phase": "bold cyan", "link": "magenta", "export": "blue"}


def format_event(event: TimelineEvent) -> Text:
    """One timeline line: time [s], kind, text."""
    return Text.assemble((f"{event.time_s:9.2f} ", "dim"),
                         (f"{event.kind:<7} ", _KIND_STYLE.get(event.kind, "")), event.text)


class Timeline(RichLog):
    """Appends the events of each snapshot it has not seen yet (by seq).

    While not `live` (its tab hidden) events are kept (the newest `PENDING`)
    and written when it is shown: writing resizes the log, which costs a
    layout of the whole screen.
    """

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(max_lines=PENDING, wrap=True, min_width=20, name=name, id=id,
                         classes=classes)
        self.last_seq = 0
        self.live = True
        self._pending: deque[TimelineEvent] = deque(maxlen=PENDING)

    def add_events(self, events: tuple[TimelineEvent, ...]) -> None:
        """Take the events of a snapshot; only unseen ones (by seq) are added."""
        for event in events:
            if event.seq > self.last_seq:
                self._pending.append(event)
                self.last_seq = event.seq
        if self.live:
            self.flush()

    def flush(self) -> None:
        """Write the events kept while hidden."""
        while self._pending:
            self.write(format_event(self._pending.popleft()))

    def reset(self) -> None:
        """Forget every event (a replay that jumped back starts its timeline again)."""
        self.clear()
        self._pending.clear()
        self.last_seq = 0
