"""Game and links: phase, simulated time and speed, rover poses, link statistics.

Drawn as fixed lines that never wrap (long lines end in an ellipsis), so the
panel's height depends only on the number of rovers and a new snapshot never
needs a new layout: a layout of the whole screen costs tens of milliseconds.
Only the lines that changed are repainted (`tui.widgets.text_lines`).
"""

from __future__ import annotations

from rich.text import Text

from tui.snapshot import Snapshot
from tui.widgets.text_lines import TextLines

__all__ = ["GamePanel", "speed_text", "render_game", "game_lines"]

_PHASE_STYLE = {"found": "bold green", "not_found": "bold red", "mapping": "bold cyan"}


def speed_text(speed: float | None, paused: bool, reached: float | None = None) -> str:
    """``x4``, ``max`` or ``paused x4``; with the speed ``reached`` when it is measured and
    falls short of the speed asked (``x16 (reached x5.2)``), or always at max (``max x120``)."""
    text = "max" if speed is None else f"x{speed:g}"
    if paused:
        return f"paused {text}"
    if reached is not None and (speed is None or reached < 0.9 * speed):
        shown = f"{reached:.0f}" if reached >= 10 else f"{reached:.1f}"
        text += f" x{shown}" if speed is None else f" (reached x{shown})"
    return text


def render_game(snap: Snapshot | None) -> Text:
    """The panel for a snapshot as one text (`game_lines` joined)."""
    out = Text("\n").join(game_lines(snap))
    out.no_wrap = True
    out.overflow = "ellipsis"
    return out


def game_lines(snap: Snapshot | None) -> list[Text]:
    """The panel's lines for a snapshot: phase and time; speed, guesses, faults;
    scenario and seed; one line per rover with pose [cm, deg] and link."""
    if snap is None:
        return [Text("waiting for the system…", style="dim")]
    lines = [
        Text.assemble(("phase ", "dim"),
                      (snap.phase.replace("_", " "), _PHASE_STYLE.get(snap.phase, "bold")),
                      ("  t ", "dim"), f"{snap.time_s:.1f} s"),
        Text.assemble(("speed ", "dim"),
                      (speed_text(snap.speed, snap.paused, snap.speed_reached),
                       "bold yellow" if snap.paused else ""),
                      ("  guesses ", "dim"), str(snap.guesses)),
        Text(f"{snap.scenario} · seed {snap.seed}", style="dim"),
    ]
    if snap.faults:
        lines[1].append(f"  faults {len(snap.faults)}", style="bold red")
    links = {ln.rover: ln for ln in snap.links}
    for rover in snap.rovers:
        p = rover.pose
        pose = "—" if p is None else f"{p.x_cm:5.0f},{p.y_cm:5.0f} {p.heading_deg % 360:3.0f}°"
        line = Text.assemble((f"{rover.id:<7}", "bold"), f"{pose:>17} ")
        ln = links.get(rover.id)
        if ln is None:
            line.append("no link", style="dim")
        elif not ln.up:
            line.append("DOWN", style="bold red")
        else:
            line.append("up ", style="green")
            line.append("?" if ln.rtt_ms is None else f"{ln.rtt_ms:.0f}ms")
            counts = [f"{name} {n}" for name, n in (("lost", ln.lost), ("re", ln.resent),
                                                      ("bad", ln.bad_frames)) if n]
            if counts:  # only what is not zero: the whole line fits at 120 columns
                line.append(" " + " ".join(counts), "yellow")
        lines.append(line)
    return lines


class GamePanel(TextLines):
    """Redrawn from each snapshot."""

    DEFAULT_CSS = """
    GamePanel { height: auto; border: round $primary; padding: 0 1; }
    """

    def on_mount(self) -> None:
        if not self.lines:
            self.set_lines(game_lines(None))

    def update_snapshot(self, snap: Snapshot) -> None:
        """Show a snapshot (a new layout only when the number of rovers changes)."""
        self.set_lines(game_lines(snap))
