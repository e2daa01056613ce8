"""The help screen: every key and what it does, from the bindings themselves."""

from __future__ import annotations

from rich.table import Table
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Static

__all__ = ["HelpScreen"]


class HelpScreen(ModalScreen[None]):
    """A table of (key, action) pairs; any of escape, q or ? closes it."""

    BINDINGS = [Binding("escape,q,question_mark", "close", "Close")]

    DEFAULT_CSS = """
    HelpScreen { align: center middle; }
    HelpScreen > VerticalScroll {
        width: 72; max-width: 100%; height: auto; max-height: 100%;
        border: thick $primary; background: $surface; padding: 0 1;
    }
    """

    def __init__(self, keys: list[tuple[str, str]], intro: str = "") -> None:
        super().__init__()
        self.keys = keys
        self.intro = intro

    def compose(self) -> ComposeResult:
        table = Table(box=None, expand=True, show_header=False)
        table.add_column("key", style="bold cyan", no_wrap=True)
        table.add_column("action")
        for key, text in self.keys:
            table.add_row(key, text)
        with VerticalScroll():
            if self.intro:
                yield Static(self.intro)
            yield Static(table)

    def action_close(self) -> None:
        self.dismiss(None)
