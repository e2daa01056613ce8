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


def short_name(name: str) -> str:
    """A mailbox's name within its rover (``mapper/navigation`` -> ``nav``), for narrow screens."""
    base = name.rsplit("/", 1)[-1]
    return {"navigation": "nav"}.get(base, base)


class QueueTable(DataTable):
    """A header row per rover, then one row per mailbox, updated in place."""

    DEFAULT_CSS = """
    QueueTable { height: 1fr; }
    """

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes, cursor_type="row", zebra_stripes=True)
        self._keys: set[str] = set()

    def on_mount(self) -> None:
        self.add_column("mailbox", key="name")
        self.add_column("depth", key="bar")
        self.add_column("msg/s", key="rate")
        self.add_column("drop", key="drops")

    def update_queues(self, queues: tuple[QueueStats, ...]) -> None:
        """Show these mailboxes (rows are added, updated or removed by name)."""
        seen = set()
        for q in queues:
            if q.rover not in seen:
                seen.add(q.rover)
                if q.rover not in self._keys:
                    self.add_row(Text(q.rover, style="bold"), "", "", "", key=q.rover)
            seen.add(q.name)
            bar = depth_bar(q.depth, q.capacity, width=4) + Text(f"{q.depth:>3}/{q.capacity}")
            rate = Text(f"{q.rate_hz:.0f}", justify="right")
            drops = Text(str(q.drops), style="bold red" if q.drops else "", justify="right")
            if q.name in self._keys:
                for col, value in (("bar", bar), ("rate", rate), ("drops", drops)):
                    self.update_cell(q.name, col, value)
            else:
                self.add_row(Text(" " + short_name(q.name)), bar, rate, drops, key=q.name)
        for gone in self._keys - seen:
            self.remove_row(gone)
        self._keys = seen
