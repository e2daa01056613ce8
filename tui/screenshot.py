"""Screenshots of the console: an SVG of the screen, and a PNG beside it where
cairosvg is installed (an optional dependency)."""

from __future__ import annotations

import pathlib

from textual.app import App

__all__ = ["save_screenshot"]


def save_screenshot(app: App, filename: str | None, folder: pathlib.Path) -> list[str]:
    """Save ``app``'s screen into ``folder`` as ``filename`` (Textual's name with the time
    when None): the files written, the SVG first.

    Raises:
        OSError: ``folder`` is not a directory, or a file cannot be written there.
    """
    if not folder.is_dir():
        raise OSError(f"no directory {folder}")
    svg = pathlib.Path(app.save_screenshot(filename, str(folder)))
    saved = [str(svg)]
    try:
        import cairosvg  # noqa: PLC0415 - optional: PNG only where it is installed
    except ImportError:
        return saved
    png = svg.with_suffix(".png")
    cairosvg.svg2png(url=str(svg), write_to=str(png))
    saved.append(str(png))
    return saved
