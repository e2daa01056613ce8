"""The console over a recording: the same panels, with the replay's keys.

`ReplayApp` is `tui.app.ConsoleApp` given a `ReplaySystem` and its own
`REPLAY_ACTIONS`: pause, speed, step, seek (to a time or the next event of a
kind) and next event. The game's own commands (map, hide, seek, faults) are
not offered: nothing is simulated.
"""

from __future__ import annotations

from textual.binding import Binding

from tui.app import ConsoleApp
from tui.keymap import KEY_NAMES, UiAction
from tui.replay.seek_dialog import SeekDialog, parse_seek
from tui.replay.system import MAX_SPEED, ReplaySystem
from tui.snapshot import Snapshot

__all__ = ["ReplayApp", "REPLAY_ACTIONS", "REPLAY_SPEEDS", "STEP_S"]

STEP_S = 1.0
"""One step of ``.`` / ``,`` [s simulated]."""
REPLAY_SPEEDS: tuple[float, ...] = (1.0, 4.0, 16.0, MAX_SPEED)
"""Speed steps of ``]`` / ``[`` (``hideseek replay --speed`` takes the same)."""

REPLAY_ACTIONS: tuple[UiAction, ...] = (
    UiAction("space", "pause", "Pause", "Pause the replay"),
    UiAction("space", "resume", "Resume", "Resume the replay"),
    UiAction("right_square_bracket", "faster", "Faster",
             "Speed up: " + ", ".join(f"x{s:g}" for s in REPLAY_SPEEDS)),
    UiAction("left_square_bracket", "slower", "Slower", "Slow down", footer=False),
    UiAction("full_stop", f"step({STEP_S})", "Step", f"Pause and step {STEP_S:g} s forward"),
    UiAction("comma", f"step({-STEP_S})", "Back", f"Pause and step {STEP_S:g} s back",
             footer=False),
    UiAction("t", "seek", "Seek", "Go to a time, or to the next event of a kind"),
    UiAction("n", "next_event", "Next", "Go to the next event (of the kind last sought)"),
    UiAction("F", "fork", "Fork",
             "Fork here: the recorded game to this time, then the live console (fault dialog)"),
    UiAction("1", "tab('queues')", "Queues", "Show queue traffic", footer=False),
    UiAction("2", "tab('log')", "Log", "Show the message log", footer=False),
    UiAction("3", "tab('tree')", "Tree", "Show the supervision tree", footer=False),
    UiAction("4", "tab('events')", "Events", "Show the timeline of events and faults",
             footer=False),
    UiAction("p", "toggle_log_pause", "Log pause", "Pause / resume the message log",
             footer=False),
    UiAction("slash", "filter_log", "Filter", "Filter the message log", footer=False),
    UiAction("question_mark", "help", "Help", "Show every key"),
    UiAction("q", "quit", "Quit", "Quit (also ctrl+c)"),
)

_NAMES = {**KEY_NAMES, "full_stop": ".", "comma": ","}


class ReplayApp(ConsoleApp, inherit_bindings=False):
    """The console replaying a recording (see the module docstring).

    Args:
        system: the replay.
    """

    TITLE = "hideseek replay"
    BINDINGS = [Binding(a.key, a.action, a.label, show=a.footer,
                        key_display=_NAMES.get(a.key)) for a in REPLAY_ACTIONS]
    BINDINGS += [b for b in ConsoleApp.BINDINGS  # ctrl+c, escape: as in the console
                 if isinstance(b, Binding) and b.key in ("ctrl+c", "escape")]
    actions = REPLAY_ACTIONS
    speeds = REPLAY_SPEEDS

    def __init__(self, system: ReplaySystem, **kwargs: object) -> None:
        super().__init__(system, **kwargs)  # type: ignore[arg-type]
        self.replay = system
        self._kind: str | None = None  # the event kind ``n`` goes to (None: any)
        self._shown_t: float | None = None
        self.fork_at: float | None = None
        """Set by ``F``: fork the game at this time once the replay has closed."""

    def show(self, snap: Snapshot) -> None:
        """Redraw; a jump back in time starts the log and the timeline again."""
        if self._shown_t is not None and snap.time_s < self._shown_t - 1e-9 and \
                self.message_log.is_mounted:
            self.message_log.reset()
            self.timeline.reset()
        self._shown_t = snap.time_s
        super().show(snap)

    def action_step(self, dt: float) -> None:
        self.replay.step(dt)

    def action_seek(self) -> None:
        self.push_screen(SeekDialog(), self._seek_chosen)

    def _seek_chosen(self, text: str | None) -> None:
        if not text:
            return
        try:
            where = parse_seek(text)
        except ValueError as exc:
            self.notify(str(exc), severity="warning")
            return
        if isinstance(where, str):
            self._kind = where
            self.replay.next_event(where)
        else:
            self.replay.seek(where)

    def action_next_event(self) -> None:
        self.replay.next_event(self._kind)

    async def action_fork(self) -> None:
        """``F``: close the replay and fork at its time (``hideseek replay`` opens the live
        console next)."""
        if self.replay.rec.run.operator != "headless":
            self.notify("recorded from the console: a person's choices cannot be played "
                        "again", severity="warning")
            return
        self.fork_at = self.snapshot.time_s if self.snapshot else self.replay.time_s
        await self.action_quit()
