"""The console's keymap: one row per thing a person can do.

Every action is one `UiAction` row of `ACTIONS`: its key binding, footer label,
help text and command palette entry all come from that row. `ACTION_COMMANDS`
names the controller commands behind each action (a key is greyed when the
system refuses all of them), `MAP_KEYS` the keys of the map itself, `SPEEDS`
the speed steps (`nearest_speed`: the step a speed is on).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["UiAction", "ACTIONS", "ACTION_COMMANDS", "MAP_KEYS", "KEY_NAMES", "SPEEDS",
           "WIDER_SEARCH_CM", "nearest_speed"]

#: Speed steps for faster / slower; None is "as fast as possible".
SPEEDS: tuple[float | None, ...] = (1.0, 4.0, 16.0, None)
#: A wider search (``w``): the hider believed within this of the cursor [cm] (the
#: headless operator's `supervisors.harness.headless.Budget.wider_within_cm`).
WIDER_SEARCH_CM = 120.0


def nearest_speed(speeds: tuple[float | None, ...], speed: float | None) -> int:
    """The index of the step of ``speeds`` nearest ``speed`` (None, as fast as possible: the
    last step)."""
    if speed is None:
        return len(speeds) - 1
    steps = range(len(speeds) - (speeds[-1] is None))
    return min(steps, key=lambda i: abs(speeds[i] - speed))  # type: ignore[operator]


@dataclass(frozen=True, slots=True)
class UiAction:
    """One thing a person can do: key, action name, footer label, help text."""

    key: str
    """Textual key name(s), comma separated."""
    action: str
    """App action (``action_<name>``)."""
    label: str
    """Short footer label."""
    help: str
    """Help screen and command palette text."""
    footer: bool = True
    """Show in the footer (the help screen and palette list every action)."""


ACTIONS: tuple[UiAction, ...] = (
    UiAction("m", "start_mapping", "Map", "Start mapping"),
    UiAction("x", "stop_mapping", "Stop map", "Stop mapping early and use the map as it is",
             footer=False),
    UiAction("enter", "confirm", "Confirm",
             "Confirm the cursor: hide spot (map ready) or seek guess (hidden / not found)"),
    UiAction("w", "wider_search", "Wider",
             f"Seek at the cursor with a wider search ({WIDER_SEARCH_CM:.0f} cm round it)",
             footer=False),
    UiAction("space", "pause", "Pause", "Pause simulated time (not with an attached rover)"),
    UiAction("space", "resume", "Resume", "Resume simulated time"),
    UiAction("right_square_bracket", "faster", "Faster",
             "Speed up: x1, x4, x16, as fast as possible (the same game at every speed; "
             "not with an attached rover)"),
    UiAction("left_square_bracket", "slower", "Slower", "Slow down", footer=False),
    UiAction("f", "faults", "Faults", "Inject or clear a fault (target, kind, duration)"),
    UiAction("g", "toggle_truth", "Truth", "Toggle the ground-truth overlay (simulated rooms)"),
    UiAction("n", "new_game", "New", "Start a new game", footer=False),
    UiAction("e", "export_map", "Export",
             "Save the map (PGM + YAML, PNG) to the export directory", footer=False),
    UiAction("s", "screenshot", "Shot",
             "Save a screenshot (SVG, and PNG where cairosvg is installed) to the export "
             "directory", footer=False),
    UiAction("R", "record", "Record",
             "Start / stop recording the game as MCAP (hideseek replay opens it)", footer=False),
    UiAction("p", "toggle_log_pause", "Log pause", "Pause / resume the message log",
             footer=False),
    UiAction("slash", "filter_log", "Filter", "Filter the message log", footer=False),
    UiAction("1", "tab('queues')", "Queues", "Show queue traffic", footer=False),
    UiAction("2", "tab('log')", "Log", "Show the message log", footer=False),
    UiAction("3", "tab('tree')", "Tree", "Show the supervision tree", footer=False),
    UiAction("4", "tab('events')", "Events", "Show the timeline of events and faults",
             footer=False),
    UiAction("question_mark", "help", "Help", "Show every key"),
    UiAction("q", "quit", "Quit", "Quit (also ctrl+c)"),
)

#: Actions -> the controller commands they send (a key is greyed when all are refused).
ACTION_COMMANDS: dict[str, tuple[str, ...]] = {
    "pause": ("pause",), "resume": ("resume",), "toggle_pause": ("pause", "resume"),
    "faster": ("set_speed",), "slower": ("set_speed",),
    "start_mapping": ("start_mapping",), "stop_mapping": ("stop_mapping",),
    "confirm": ("hide_at", "seek_at"), "wider_search": ("seek_at",),
    "new_game": ("new_game",), "faults": ("inject_fault", "clear_fault"),
    "export_map": ("export_map",),
}

#: Keys of the map itself (focused by default), for the help screen.
MAP_KEYS: tuple[tuple[str, str], ...] = (
    ("arrows", "move the cursor (or click the map)"),
    ("shift+arrows", "pan the map"),
    ("+ / -", "zoom in / out"),
    ("0", "fit the known map, and follow it as it grows"),
    ("r", "rotate the hide heading by 45°"),
    ("escape", "back to the map from the log filter"),
    ("wheel / arrows, page keys", "scroll the log back (arrows once it is clicked); end: newest"),
    ("ctrl+p", "command palette: every action by name"),
)

#: Textual key names shown as the key itself.
KEY_NAMES = {"right_square_bracket": "]", "left_square_bracket": "[", "question_mark": "?",
             "slash": "/"}

