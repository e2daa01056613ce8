"""The fault dialog: inject a catalogue fault on a target with a duration, or clear one.

It offers exactly what the snapshot's catalogue lists, so a person cannot pick
a kind the target does not accept. Dismisses with a `FaultRequest` or None.
"""

from __future__ import annotations

from dataclasses import dataclass

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, Select

from tui.snapshot import ActiveFault, FaultTarget

__all__ = ["FaultDialog", "FaultRequest", "parse_duration"]


@dataclass(frozen=True, slots=True)
class FaultRequest:
    """What the person asked for."""

    action: str
    """``inject`` or ``clear``."""
    target: str = ""
    """Catalogue target (inject), or fault id / target (clear)."""
    kind: str = ""
    """Fault kind (inject)."""
    duration_s: float | None = None
    """Simulated duration [s] (inject); None until cleared."""


def parse_duration(text: str) -> float | None:
    """``""`` -> None (until cleared); ``"5"`` -> 5.0 [s].

    Raises:
        ValueError: when the text is not a positive number of seconds.
    """
    text = text.strip().removesuffix("s").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"duration must be a number of seconds, got {text!r}") from None
    if not value > 0:
        raise ValueError(f"duration must be > 0 s, got {text!r}")
    return value


class FaultDialog(ModalScreen[FaultRequest | None]):
    """Choose target, kind and duration; or choose an active fault to clear."""

    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    DEFAULT_CSS = """
    FaultDialog { align: center middle; }
    FaultDialog > Vertical {
        width: 60; max-width: 100%; height: auto; max-height: 100%;
        border: thick $error; background: $surface; padding: 0 1;
        overflow-y: auto;
    }
    FaultDialog Select, FaultDialog Input { width: 1fr; }
    FaultDialog Horizontal { height: auto; }
    FaultDialog Label { margin-top: 1; }
    FaultDialog #error { color: $error; margin: 0; }
    """

    def __init__(self, catalogue: tuple[FaultTarget, ...],
                 active: tuple[ActiveFault, ...] = ()) -> None:
        super().__init__()
        self.catalogue = catalogue
        self.active = active
        self._kinds = {t.target: t.kinds for t in catalogue}

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("[b]Inject a fault[/b]")
            yield Select([(t, t) for t in self._kinds], prompt="target", id="target")
            yield Select([], prompt="kind", id="kind")
            yield Input(placeholder="duration [s], empty = until cleared", id="duration")
            yield Label("", id="error")
            with Horizontal():
                yield Button("Inject", variant="error", id="inject")
                yield Button("Cancel", id="cancel")
            if self.active:
                yield Label("[b]Clear an active fault[/b]")
                yield Select([("all faults", "*")] + [
                    (f"{f.id}: {f.kind} on {f.target}", f.id) for f in self.active],
                    prompt="fault", id="active")
                yield Button("Clear", variant="success", id="clear")

    def on_select_changed(self, event: Select.Changed) -> None:
        if event.select.id == "target":
            kinds = self._kinds.get(str(event.value), ())
            self.query_one("#kind", Select).set_options([(k, k) for k in kinds])

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "cancel":
            self.dismiss(None)
        elif event.button.id == "inject":
            self._inject()
        elif event.button.id == "clear":
            value = self.query_one("#active", Select).value
            if value is Select.BLANK:
                self._error("choose a fault to clear")
            else:
                self.dismiss(FaultRequest("clear", str(value)))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self._inject()

    def _inject(self) -> None:
        target = self.query_one("#target", Select).value
        kind = self.query_one("#kind", Select).value
        if target is Select.BLANK or kind is Select.BLANK:
            self._error("choose a target and a kind")
            return
        try:
            duration = parse_duration(self.query_one("#duration", Input).value)
        except ValueError as exc:
            self._error(str(exc))
            return
        self.dismiss(FaultRequest("inject", str(target), str(kind), duration))

    def _error(self, text: str) -> None:
        self.query_one("#error", Label).update(text)

    def action_cancel(self) -> None:
        self.dismiss(None)
