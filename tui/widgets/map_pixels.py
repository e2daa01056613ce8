"""What each pixel of the map view shows: pixel classes and their colours, sampling a
grid at pixel centres, the known extent and the zoom that fits it.

Pure functions on `tui.snapshot.GridView` (numpy, no widget): a pixel's class is
unknown, free or occupied from the map, and with ground truth also an obstacle
not yet seen, an obstacle mapped free (missed) or free ground mapped occupied
(false). When a pixel covers several cells the class with the highest rank
wins (occupied over free over unknown), so thin walls survive zooming out.
"""

from __future__ import annotations

import numpy as np
from rich.text import Text

from tui.snapshot import FREE, OCCUPIED, GridView

__all__ = ["ZOOMS_CM", "COLOURS", "RANK", "CODE", "ROVER_COLOURS", "TRUTH_LEGEND",
           "TRUTH_LEGEND_SHORT", "TRUTH_LEGEND_CELLS",
           "UNKNOWN_PX", "FREE_PX", "OCCUPIED_PX", "MISSED_PX", "FALSE_PX", "PATH_PX",
           "LIDAR_PX", "TRUTH_PX", "heading_glyph", "classify", "classify_values",
           "same_raster", "indexer", "gather", "known_extent", "fit_view"]

#: Pixel sizes the zoom steps through [cm per pixel].
ZOOMS_CM: tuple[float, ...] = (1.25, 2.5, 4.0, 5.0, 6.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0,
                                40.0, 60.0)

# Pixel classes, drawn in this colour (index = class).
UNKNOWN_PX, FREE_PX, OCCUPIED_PX, MISSED_PX, FALSE_PX, PATH_PX, LIDAR_PX, TRUTH_PX = range(8)
COLOURS = ("#161616", "#4a4a4a", "#e0e0e0", "#d040ff", "#e07020", "#c8a000", "#ff4040",
           "#283c64")
#: Which sample wins when a pixel covers several cells (index = class).
RANK = np.array([0, 2, 5, 4, 3, 0, 0, 1], np.int8)
#: A class with its rank above it (rank * 8 + class): the largest code wins.
CODE = (RANK.astype(np.uint8) << 3) | np.arange(8, dtype=np.uint8)
ROVER_COLOURS = {"mapper": "#40d0ff", "hider": "#40ff60", "seeker": "#ff60ff"}
#: The truth overlay's legend, in the map's title while the overlay is on.
TRUTH_LEGEND = (f" · truth: [{COLOURS[TRUTH_PX]}]■[/] unseen [{COLOURS[MISSED_PX]}]■[/] "
                f"missed [{COLOURS[FALSE_PX]}]■[/] false ○ true pose")
#: The same for a narrow map (80 columns): the title is then ``20cm`` (per pixel) and this.
TRUTH_LEGEND_SHORT = (f" [{COLOURS[TRUTH_PX]}]■[/]unseen [{COLOURS[MISSED_PX]}]■[/]missed "
                      f"[{COLOURS[FALSE_PX]}]■[/]false ○true")
#: Terminal cells the full legend takes (its text without the colour markup).
TRUTH_LEGEND_CELLS = Text.from_markup(TRUTH_LEGEND).cell_len
_ARROWS = "→↗↑↖←↙↓↘"


def heading_glyph(heading_deg: float) -> str:
    """An arrow for a heading [deg] (counter-clockwise from +x, screen up is +y)."""
    return _ARROWS[int(round((heading_deg % 360.0) / 45.0)) % 8]


def classify(grid: GridView | None, truth: GridView | None, xs: np.ndarray,
             ys: np.ndarray) -> np.ndarray:
    """Pixel classes for sample points (any shape) [cm]: unknown/free/occupied, and
    with ``truth``: obstacles not yet seen (dim blue), mapping errors (an obstacle
    mapped as free: purple; free ground mapped as occupied: orange)."""
    return classify_values(None if grid is None else _sample(grid, xs, ys),
                           None if truth is None else _sample(truth, xs, ys), xs.shape)


def classify_values(map_val: np.ndarray | None, true_val: np.ndarray | None,
                    shape: tuple[int, ...]) -> np.ndarray:
    """`classify` from cell values already sampled (-1 outside a grid)."""
    out = np.full(shape, UNKNOWN_PX, np.int8)
    if map_val is None:
        return out
    out[map_val == FREE] = FREE_PX
    out[map_val == OCCUPIED] = OCCUPIED_PX
    if true_val is not None:
        out[(true_val == OCCUPIED) & (map_val == -1)] = TRUTH_PX
        out[(true_val == OCCUPIED) & (map_val == FREE)] = MISSED_PX
        out[(true_val == FREE) & (map_val == OCCUPIED)] = FALSE_PX
    return out


def same_raster(a: GridView, b: GridView) -> bool:
    """Whether two grids share cells one for one (shape, origin and resolution)."""
    return (a.cells.shape == b.cells.shape and a.origin_cm == b.origin_cm
            and a.resolution_cm == b.resolution_cm)


def _sample(grid: GridView, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    return gather(grid, indexer(grid, xs, ys))


def indexer(grid: GridView, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Flat cell index of each sample point, -1 outside the grid."""
    ny, nx = grid.cells.shape
    cols = np.floor((xs - grid.origin_cm[0]) / grid.resolution_cm).astype(np.int64)
    rows = np.floor((ys - grid.origin_cm[1]) / grid.resolution_cm).astype(np.int64)
    inside = (cols >= 0) & (cols < nx) & (rows >= 0) & (rows < ny)
    return np.where(inside, rows * nx + cols, -1)


def gather(grid: GridView, index: np.ndarray) -> np.ndarray:
    """Cell values at flat indexes (from `indexer`), -1 where the index is -1."""
    flat = grid.cells.reshape(-1)
    out = flat[np.maximum(index, 0)].astype(np.int16)
    out[index < 0] = -1
    return out


def known_extent(grid: GridView) -> tuple[float, float, float, float] | None:
    """(x_min, y_min, x_max, y_max) [cm] of the cells the map knows, one cell of
    margin; None when it knows none (a fresh grid is mostly unknown space)."""
    known = grid.cells != -1
    rows = np.flatnonzero(known.any(axis=1))
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(known.any(axis=0))
    r, (ox, oy) = grid.resolution_cm, grid.origin_cm
    return (ox + (cols[0] - 1) * r, oy + (rows[0] - 1) * r,
            ox + (cols[-1] + 2) * r, oy + (rows[-1] + 2) * r)


def fit_view(extent: tuple[float, float, float, float], width: int,
             height: int) -> tuple[int, tuple[float, float]]:
    """The finest zoom index showing ``extent`` [cm] in ``width`` x ``height``
    characters (two pixels per character vertically), and the centre [cm]."""
    x0, y0, x1, y1 = extent
    zoom = len(ZOOMS_CM) - 1
    for i, s in enumerate(ZOOMS_CM):
        if (x1 - x0) / s <= width and (y1 - y0) / s <= 2 * height:
            zoom = i
            break
    return zoom, ((x0 + x1) / 2, (y0 + y1) / 2)
