"""Delta debugging (Zeller and Hildebrandt, "Simplifying and Isolating
Failure-Inducing Input", IEEE TSE 2002): the ``ddmin`` algorithm.

Given a list that makes a test fail, ``ddmin`` removes chunks of it while
the failure persists: it splits the list into ``n`` chunks, keeps a chunk
that fails alone, else drops a chunk whose complement still fails, else
splits finer, until each chunk is one element. The result is *1-minimal*:
removing any single element of it makes the test pass. It spends
O(n²) tests at worst and O(log n) when one element is the cause.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

T = TypeVar("T")


def _chunks(items: Sequence[T], n: int) -> list[list[T]]:
    """``items`` cut into ``n`` nearly equal consecutive chunks (none empty)."""
    size, extra = divmod(len(items), n)
    out, start = [], 0
    for i in range(n):
        end = start + size + (1 if i < extra else 0)
        out.append(list(items[start:end]))
        start = end
    return out


def ddmin(items: Sequence[T], fails: Callable[[list[T]], bool]) -> list[T]:
    """A 1-minimal sublist of ``items`` (order kept) for which ``fails`` is still true.

    ``fails(items)`` is assumed true and is not asked again. ``fails`` is
    called only on sublists; the caller caches and bounds it (it may raise
    to stop early: the exception propagates).
    """
    current = list(items)
    n = 2
    while len(current) >= 2:
        chunks = _chunks(current, min(n, len(current)))
        reduced = False
        for chunk in chunks:                       # one chunk alone fails
            if fails(chunk):
                current, n, reduced = chunk, 2, True
                break
        if not reduced and len(chunks) > 2:        # (with two chunks, complements = chunks)
            for i in range(len(chunks)):           # a chunk can go
                rest = [x for j, c in enumerate(chunks) if j != i for x in c]
                if fails(rest):
                    current, n, reduced = rest, max(len(chunks) - 1, 2), True
                    break
        if not reduced:
            if len(chunks) >= len(current):        # every chunk is one element: 1-minimal
                break
            n = min(2 * len(chunks), len(current))
    return current
