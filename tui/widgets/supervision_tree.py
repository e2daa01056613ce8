"""The supervision tree: every supervisor and actor with state, restarts, last exit.

A node that is restarting, or exited within `FLASH_S` simulated seconds, is
drawn reversed in red so a crash or hang visibly flashes and then recovers.
"""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from tui.snapshot import TreeNode

__all__ = ["SupervisionTree", "FLASH_S", "render_tree"]

#: How long after an exit a node stays highlighted [s, simulated].
FLASH_S = 2.0
_STATE_STYLE = {"running": "green", "restarting": "bold yellow", "stopped": "red"}


def render_tree(root: TreeNode | None, now_s: float) -> Text:
    """The tree as indented lines: name, state, restarts and last exit reason."""
    if root is None:
        return Text("(no supervision tree yet)", style="dim")
    out = Text()
    for depth, node in root.walk():
        recent = node.last_exit_s is not None and now_s - node.last_exit_s < FLASH_S
        flash = node.state == "restarting" or recent
        icon = "▸" if node.kind == "supervisor" else "•"
        name = Text(f"{'  ' * depth}{icon} {node.name.split('/')[-1] if depth > 1 else node.name}",
                    style="bold reverse red" if flash else ("bold" if node.kind == "supervisor"
                                                            else ""))
        out.append_text(name)
        out.append(f" {node.state}", style=_STATE_STYLE.get(node.state, ""))
        if node.restarts:
            out.append(f" ↻{node.restarts}", style="yellow")
        if node.last_exit:
            out.append(f" ({node.last_exit})", style="dim")
        out.append("\n")
    out.rstrip()
    return out


class SupervisionTree(Static):
    """The live supervision tree (put it in a scrolling container)."""

    def update_tree(self, root: TreeNode | None, now_s: float) -> None:
        """Redraw from a snapshot's tree at simulated time ``now_s`` [s]."""
        text = render_tree(root, now_s)
        lines = text.plain.count("\n")
        self.update(text, layout=lines != getattr(self, "_lines", None))
        self._lines = lines
