"""Mailbox traffic: depth against capacity, rate and overflow drops, per rover.

Drawn as lines of text rather than a `DataTable`: a DataTable re-renders
every cell through Textual's style machinery and, refreshed 15 times a second,
cost more than the whole simulation at full speed (see ``benchmarks/console``);
only the lines that changed are repainted (`tui.widgets.text_lines`).
"""

from __future__ import annotations

from rich.text import Text

from tui.snapshot import QueueStats
from tui.widgets.text_lines import TextLines

__all__ = ["QueueTable", "depth_bar", "short_name", "render_queues", "queue_lines"]


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
    """The table as one text (`queue_lines` joined)."""
    return Text("\n").join(queue_lines(queues))


def queue_lines(queues: tuple[QueueStats, ...]) -> list[Text]:
    """A header line, then per rover its name and one line per mailbox:
    name, fill bar, depth/capacity, rate [msg/s], drops."""
    out = [Text.assemble(("mailbox  depth       msg/s   drop", "bold underline"))]
    rover = None
    for q in queues:
        if q.rover != rover:
            rover = q.rover
            out.append(Text(rover, style="bold"))
        line = Text(f" {short_name(q.name)[:7]:<7} ")
        line.append_text(depth_bar(q.depth, q.capacity, width=4))
        line.append(f" {q.depth:>3}/{q.capacity:<4} {q.rate_hz:>5.0f} ")
        line.append(f"{q.drops:>6}", style="bold red" if q.drops else "")
        out.append(line)
    return out


class QueueTable(TextLines):
    """Redrawn from each snapshot (put it in a scrolling container)."""

    def update_queues(self, queues: tuple[QueueStats, ...]) -> None:
        """Show these mailboxes (a new layout only when the number of lines changes)."""
        self.set_lines(queue_lines(queues))
