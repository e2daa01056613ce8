"""Small charts as inline SVG text: horizontal bars of rates, and a histogram.

Written by hand on purpose: a page of a campaign's results needs two kinds of chart,
and SVG text in the page keeps it one self-contained file with nothing to install
(a plotting library would bring a large dependency for two shapes). Every size is
in SVG user units [px]; text is escaped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from html import escape

__all__ = ["BAR_COLOUR", "CHART_WIDTH", "rate_bars", "histogram"]

CHART_WIDTH = 640
"""Width of every chart [px]."""
BAR_COLOUR = "#3d8bd4"
"""Bars; the part that failed is drawn in `_FAIL_COLOUR`."""
_FAIL_COLOUR = "#d9534f"
_ROW_PX = 22
_LABEL_PX = 180  # left column: the row's label
_TITLE_PX = 28


def _svg(width: int, height: int, body: list[str], title: str) -> str:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
            f'viewBox="0 0 {width} {height}" role="img" aria-label="{escape(title)}">'
            f'<text x="0" y="18" font-size="15" font-weight="bold">{escape(title)}</text>'
            + "".join(body) + "</svg>")


def rate_bars(title: str, rows: Sequence[tuple[str, int, int]], *,
              width: int = CHART_WIDTH) -> str:
    """One bar per row, ``(label, good, total)``: the bar's blue part is ``good / total``.

    Each row is labelled with its rate and counts (``75 % (3 of 4)``).
    """
    bar_px = width - _LABEL_PX - 110
    height = _TITLE_PX + _ROW_PX * max(1, len(rows)) + 6
    body = []
    for i, (label, good, total) in enumerate(rows):
        y = _TITLE_PX + i * _ROW_PX
        rate = good / total if total else 0.0
        filled = round(bar_px * rate)
        body.append(f'<text x="0" y="{y + 15}" font-size="12">{escape(label)}</text>')
        body.append(f'<rect x="{_LABEL_PX}" y="{y + 3}" width="{bar_px}" height="16" '
                    f'fill="{_FAIL_COLOUR}" opacity="0.35"/>')
        body.append(f'<rect x="{_LABEL_PX}" y="{y + 3}" width="{filled}" height="16" '
                    f'fill="{BAR_COLOUR}"/>')
        body.append(f'<text x="{_LABEL_PX + bar_px + 6}" y="{y + 15}" font-size="12">'
                    f'{100 * rate:.0f} % ({good} of {total})</text>')
    if not rows:
        body.append(f'<text x="0" y="{_TITLE_PX + 15}" font-size="12">no games</text>')
    return _svg(width, height, body, title)


def histogram(title: str, values: Sequence[float], *, unit: str, bins: int = 12,
              width: int = CHART_WIDTH, height: int = 220) -> str:
    """Counts of ``values`` in ``bins`` equal bins from 0 to the largest value, with the
    bins' bounds below (in ``unit``)."""
    plot_h = height - _TITLE_PX - 34
    body = []
    if not values:
        body.append(f'<text x="0" y="{_TITLE_PX + 15}" font-size="12">no values</text>')
        return _svg(width, height, body, title)
    top = max(values)
    step = max(1.0, math.ceil(top / bins)) if top > 0 else 1.0
    counts = [0] * bins
    for v in values:
        counts[min(bins - 1, int(v // step))] += 1
    most = max(counts)
    bar_w = (width - 40) / bins
    base = _TITLE_PX + plot_h
    for i, n in enumerate(counts):
        h = round(plot_h * n / most) if most else 0
        x = 20 + i * bar_w
        body.append(f'<rect x="{x:.1f}" y="{base - h}" width="{bar_w - 2:.1f}" height="{h}" '
                    f'fill="{BAR_COLOUR}"><title>{i * step:g} to {(i + 1) * step:g} {unit}: '
                    f'{n}</title></rect>')
        if n:
            body.append(f'<text x="{x + bar_w / 2 - 4:.1f}" y="{base - h - 3}" '
                        f'font-size="11">{n}</text>')
        if i % 2 == 0:
            body.append(f'<text x="{x:.1f}" y="{base + 14}" font-size="11">'
                        f'{i * step:g}</text>')
    body.append(f'<text x="20" y="{base + 30}" font-size="11">'
                f'{escape(unit)}, bins of {step:g}</text>')
    return _svg(width, height, body, title)
