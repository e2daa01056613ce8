"""A block of text lines drawn line by line: a new set repaints only what changed.

Why not `Static`: ``Static.update`` turns the whole text into Textual content
and the next frame wraps, styles and renders every line of it again, even when
one number changed. The console's panels are redrawn many times a second
while the simulation runs at full speed, and every millisecond spent there is
simulation not run. `TextLines` keeps one `Strip` per line, compares each new
line with the one shown (text, style and styled spans) and asks
Textual to repaint only the rows that differ; a new layout only when the
number of lines changes. Lines never wrap: a line wider than the widget ends
in an ellipsis.
"""

from __future__ import annotations

from rich.style import Style
from rich.text import Text
from textual.geometry import Region, Size
from textual.strip import Strip
from textual.widget import Widget

__all__ = ["TextLines"]


class TextLines(Widget):
    """Fixed lines of rich text; feed it with `set_lines`.

    Its height is the number of lines (``height: auto``), its width the
    container's.
    """

    DEFAULT_CSS = """
    TextLines { height: auto; }
    """

    def __init__(self, *, name: str | None = None, id: str | None = None,
                 classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        self._texts: list[Text] = []
        self._strips: dict[int, Strip] = {}  # line -> strip drawn at `_width`
        self._width = -1
        self._style: Style | None = None  # the base style, until styles change
        self.repainted = 0
        """Lines marked for repaint so far (one per changed line; all on a new layout)."""

    @property
    def content(self) -> Text:
        """The lines shown, as one text."""
        return Text("\n").join(self._texts)

    @property
    def lines(self) -> list[Text]:
        """The lines shown (do not modify)."""
        return self._texts

    def get_content_width(self, container: Size, viewport: Size) -> int:
        return container.width

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        return len(self._texts)

    def render_line(self, y: int) -> Strip:
        width = self.size.width
        if width != self._width:
            self._strips.clear()
            self._width = width
        strip = self._strips.get(y)
        if strip is None:
            style = self._style
            if style is None:  # `rich_style` walks every ancestor's styles: once
                style = self._style = self.rich_style
            if not 0 <= y < len(self._texts):
                return Strip.blank(width, style)
            text = self._texts[y]
            if text.cell_len > width:
                text = text.copy()
                text.truncate(width, overflow="ellipsis")
            console = self.app.console
            strip = Strip(text.render(console, end=""), text.cell_len)
            if text.style:  # `Text.render` leaves the base style to its caller
                strip = strip.apply_style(console.get_style(text.style))
            strip = strip.apply_style(style).crop_extend(0, width, style)
            self._strips[y] = strip
        return strip

    def notify_style_update(self) -> None:
        super().notify_style_update()
        self._strips.clear()  # drawn with the old base style
        self._style = None

    def set_lines(self, lines: list[Text]) -> None:
        """Show these lines (one `Text` each, no newlines): repaint the changed ones."""
        old, self._texts = self._texts, lines
        if len(lines) != len(old):
            self._strips.clear()
            self.repainted += len(lines)
            self.refresh(layout=True)
            return
        width = self.size.width
        changed = [y for y, (a, b) in enumerate(zip(old, lines, strict=True))
                   if not _same(a, b)]
        for y in changed:
            self._strips.pop(y, None)
        if changed:
            self.repainted += len(changed)
            self.refresh(*(Region(0, y, width, 1) for y in changed))


def _same(a: Text, b: Text) -> bool:
    """Whether two lines look the same (``Text ==`` ignores the base style)."""
    return a.plain == b.plain and a.style == b.style and a.spans == b.spans
