"""Mailbox traffic: depth against capacity, rate and overflow drops, per rover."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import DataTable

from tui.snapshot import QueueStats

__all__ = ["QueueTable", "depth_bar"]


def depth_bar(depth: int, capacity: int, width: int = 8) -> Text:
    """A bar of ``width`` cells for depth/capacity: green, yellow over half, red when full."""
    capacity = max(1, capacity)
    filled = round(width * min(depth, capacity) / capacity)
    colour = "red" if depth >= capacity else ("yellow" if depth * 2 > capacity else "green")
    return Text("█" * filled, style=colour) + Text("·" * (width - filled), style="dim")


class QueueTable(DataTable):
    """One row per mailbox, updated in place from each snapshot."""

    DEFAULT_CSS = """
    QueueTable { height: 1fr; }
    """

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes, cursor_type="row", zebra_stripes=True)
        self._keys: set[str] = set()

    def on_mount(self) -> None:
        self.add_column("mailbox", key="name")
        self.add_column("depth", key="depth")
        self.add_column("fill", key="bar")
        self.add_column("msg/s", key="rate")
        self.add_column("drops", key="drops")

    def update_queues(self, queues: tuple[QueueStats, ...]) -> None:
        """Show these mailboxes (rows are added, updated or removed by name)."""
        seen = set()
        for q in queues:
            seen.add(q.name)
            depth = Text(f"{q.depth}/{q.capacity}", justify="right")
            rate = Text(f"{q.rate_hz:.0f}", justify="right")
            drops = Text(str(q.drops), style="bold red" if q.drops else "", justify="right")
            bar = depth_bar(q.depth, q.capacity)
            if q.name in self._keys:
                for col, value in (("depth", depth), ("bar", bar), ("rate", rate),
                                   ("drops", drops)):
                    self.update_cell(q.name, col, value)
            else:
                self.add_row(q.name, depth, bar, rate, drops, key=q.name)
                self._keys.add(q.name)
        for gone in self._keys - seen:
            self.remove_row(gone)
        self._keys = seen
