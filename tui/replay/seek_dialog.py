"""The replay's seek dialog: a time, or the kind of the next event to go to."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label

from tui.replay.index import EVENT_KINDS

__all__ = ["SeekDialog", "parse_seek", "TITLE"]

TITLE = f"Go to a time [s] or to the next event:\n{', '.join(EVENT_KINDS)}"
"""The dialog's title: two lines, each shorter than the dialog is wide at 80 columns."""


def parse_seek(text: str) -> float | str:
    """``"120"`` -> 120.0 (a time [s]); ``"fault"`` -> ``"fault"`` (the next event of that kind).

    Raises:
        ValueError: neither a time nor an event kind.
    """
    text = text.strip().lower().removesuffix("s").strip()
    if text in EVENT_KINDS:
        return text
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"seek to a time [s] or the next event of a kind "
                         f"({', '.join(EVENT_KINDS)}), got {text!r}") from None


class SeekDialog(ModalScreen[str | None]):
    """Asks where to go; dismisses with the text typed (None: cancelled)."""

    BINDINGS = [Binding("escape", "cancel", "Cancel")]
    DEFAULT_CSS = """
    SeekDialog { align: center middle; }
    SeekDialog > Vertical {
        width: 60; max-width: 100%; height: auto;
        border: thick $primary; background: $surface; padding: 0 1;
    }
    """

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(TITLE, id="seek-title")
            yield Input(placeholder="120  or  fault", id="seek-input")

    def on_mount(self) -> None:
        self.query_one(Input).focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.dismiss(event.value)

    def action_cancel(self) -> None:
        self.dismiss(None)
