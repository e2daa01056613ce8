"""Game and links: phase, simulated time and speed, rover poses, link statistics."""

from __future__ import annotations

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from tui.snapshot import Snapshot

__all__ = ["GamePanel", "speed_text", "render_game"]

_PHASE_STYLE = {"found": "bold green", "not_found": "bold red", "mapping": "bold cyan"}


def speed_text(speed: float | None, paused: bool) -> str:
    """``x4``, ``max`` or ``paused (x4)``."""
    text = "max" if speed is None else f"x{speed:g}"
    return f"paused ({text})" if paused else text


def render_game(snap: Snapshot | None) -> Table | Text:
    """The panel's content for a snapshot."""
    if snap is None:
        return Text("waiting for the system…", style="dim")
    head = Text.assemble(
        ("phase ", "dim"), (snap.phase.replace("_", " "), _PHASE_STYLE.get(snap.phase, "bold")),
        ("  t ", "dim"), f"{snap.time_s:.1f} s",
        ("  speed ", "dim"), (speed_text(snap.speed, snap.paused),
                              "bold yellow" if snap.paused else ""),
        ("  guesses ", "dim"), str(snap.guesses),
    )
    if snap.faults:
        head.append(f"  faults {len(snap.faults)}", style="bold red")
    table = Table.grid(padding=(0, 1), expand=True)
    table.add_column("rover")
    table.add_column("pose", justify="right")
    table.add_column("link")
    links = {ln.rover: ln for ln in snap.links}
    for rover in snap.rovers:
        p = rover.pose
        pose = "—" if p is None else f"{p.x_cm:5.0f},{p.y_cm:5.0f} {p.heading_deg % 360:3.0f}°"
        ln = links.get(rover.id)
        if ln is None:
            link = Text("no link", style="dim")
        elif not ln.up:
            link = Text("DOWN", style="bold red")
        else:
            rtt = "?" if ln.rtt_ms is None else f"{ln.rtt_ms:.0f}ms"
            link = Text.assemble(("up ", "green"), rtt)
            if ln.lost or ln.resent or ln.bad_frames:
                link.append(f" lost {ln.lost} re {ln.resent} bad {ln.bad_frames}", "yellow")
        table.add_row(Text(rover.id, style="bold"), pose, link)
    outer = Table.grid(expand=True)
    outer.add_row(head)
    outer.add_row(Text(f"{snap.scenario} · seed {snap.seed}", style="dim"))
    outer.add_row(table)
    return outer


class GamePanel(Static):
    """Redrawn from each snapshot."""

    DEFAULT_CSS = """
    GamePanel { height: auto; border: round $primary; padding: 0 1; }
    """

    def update_snapshot(self, snap: Snapshot) -> None:
        """Show a snapshot."""
        # A new layout costs a lot at 15 Hz: only when the height may have changed.
        shape = (len(snap.rovers), snap.phase, snap.paused, snap.speed, bool(snap.faults),
                 self.size.width)
        self.update(render_game(snap), layout=shape != getattr(self, "_shape", None))
        self._shape = shape
