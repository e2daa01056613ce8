"""Progress on standard error for work that takes more than a few seconds.

`progress_bar` shows a `rich.progress` bar (description, bar, done of total, a note,
elapsed time) on a stream, only when that stream is a terminal: a log file, a pipe
or a test's captured stderr gets nothing, so what a command prints stays the same
wherever it goes. Used by ``campaign`` (its games, the shrink phase, the recorded
failures) and ``shrink`` (its runs).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

__all__ = ["Bar", "progress_bar"]


class Bar:
    """One task's bar; `advance` moves it, `note` changes the text beside it. Does
    nothing when the stream is not a terminal (or progress is off)."""

    def __init__(self, progress: object | None = None, task: int | None = None) -> None:
        self._progress, self._task = progress, task
        self.done = 0
        """Steps done so far (counted whether or not the bar is shown)."""

    @property
    def shown(self) -> bool:
        """Whether the bar is drawn."""
        return self._progress is not None

    def advance(self, steps: int = 1, *, note: str | None = None) -> None:
        """``steps`` more done (and the note beside the bar, when given)."""
        self.done += steps
        if self._progress is not None:
            fields = {} if note is None else {"note": note}
            self._progress.update(self._task, advance=steps, **fields)  # type: ignore[attr-defined]

    def finish(self) -> None:
        """The work ended: the bar is full at the steps done (work that ends before its
        total, a search that found its answer early)."""
        if self._progress is not None:
            self._progress.update(self._task, total=self.done, completed=self.done)  # type: ignore[attr-defined]

    def note(self, text: str) -> None:
        """The text beside the bar."""
        if self._progress is not None:
            self._progress.update(self._task, note=text)  # type: ignore[attr-defined]


@contextmanager
def progress_bar(description: str, total: int | None, *, stream: TextIO | None = None,
                 enabled: bool = True) -> Iterator[Bar]:
    """A bar for ``total`` steps (None: unknown) on ``stream`` (standard error by
    default), drawn only when ``enabled`` and the stream is a terminal; it stays on
    screen, complete, when the block ends."""
    out = sys.stderr if stream is None else stream
    if not enabled or not out.isatty():
        yield Bar()
        return
    from rich.console import Console  # noqa: PLC0415 - only when a bar is drawn
    from rich.progress import (  # noqa: PLC0415
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[note]}"), TimeElapsedColumn())
    with Progress(*columns, console=Console(file=out, force_terminal=True),
                  redirect_stdout=False, redirect_stderr=False) as progress:
        yield Bar(progress, progress.add_task(description, total=total, note=""))
