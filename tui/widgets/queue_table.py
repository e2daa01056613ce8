"""Mailbox traffic: depth against capacity, rate and overflow drops, per rover.

Drawn as one block of text rather than a `DataTable`: a DataTable re-renders
every cell through Textual's style machinery and, refreshed 15 times a second,
cost more than the whole simulation at full speed (see ``benchmarks/console``).
"""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from tui.snapshot import QueueStats

__all__ = ["QueueTable", "depth_bar", "short_name", "render_queues"]


def depth_bar(depth: int, capacity: int, width: int = 8) -> Text:
    """A bar of ``width`` cells for depth/capacity: green, yellow over half, red when full."""
    capacity = max(1, capacity)
    filled = round(width * min(depth, capacity) / capacity)
    colour = "red" if depth >= capacity else ("yellow" if depth * 2 > capacity else "green")
    return Text("█" * filled, style=colour) + Text("·" * (width - filled), style="dim")


def short_name(name: str) -> str:
    """A mailbox's name within its rover (``mapper/navigation`` -> ``nav``), for narrow screens."""
    base = name.rsplit("/", 1)[-1]
    return {"navigation": "nav"}.get(base, base)


def render_queues(queues: tuple[QueueStats, ...]) -> Text:
    """A header line, then per rover its name and one line per mailbox:
    name, fill bar, depth/capacity, rate [msg/s], drops."""
    out = Text.assemble(("mailbox  depth       msg/s   drop", "bold underline"))
    rover = None
    for q in queues:
        if q.rover != rover:
            rover = q.rover
            out.append(f"\n{rover}", style="bold")
        out.append(f"\n {short_name(q.name)[:7]:<7} ")
        out.append_text(depth_bar(q.depth, q.capacity, width=4))
        out.append(f" {q.depth:>3}/{q.capacity:<4} {q.rate_hz:>5.0f} ")
        out.append(f"{q.drops:>6}", style="bold red" if q.drops else "")
    return out


class QueueTable(Static):
    """Redrawn from each snapshot (put it in a scrolling container)."""

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self._lines = 0

    def update_queues(self, queues: tuple[QueueStats, ...]) -> None:
        """Show these mailboxes (a new layout only when the number of lines changes)."""
        text = render_queues(queues)
        lines = len(queues) + len({q.rover for q in queues}) + 1
        self.update(text, layout=lines != self._lines)
        self._lines = lines
