"""The one map type every layer uses: `GridMap`, its cell convention and its geometry.

Map Management publishes and uploads a `GridMap`; the wire codec (`mapcodec`)
sends and assembles one; the server stores, exports and serves one; navigation,
the planner, frontier search and the clearance check read one.

Cell values (`GridMap.cells`, ``numpy.int8``, read-only)
    ``-1`` unknown, ``0`` free, ``100`` occupied, and nothing else; row 0 is
    the lowest ``y``. Cell ``[row, col]`` covers ``x`` in ``[ox + col * res,
    ox + (col + 1) * res)`` and ``y`` in ``[oy + row * res, oy + (row + 1) *
    res)``, where ``origin_cm = (ox, oy)`` is the lower-left corner of cell
    ``[0, 0]``.

Occupancy percentages (values 0..100 between free and occupied) are classified
once, when a map is made, by one of two named rules:

* `GridMap.split` (what the constructor applies): ``0..49`` free, ``50..100``
  occupied. Every observed cell is decided; the rovers' own maps and the maps
  they receive use it.
* `GridMap.trinary` (`GridMap.from_percentages`): ``<= FREE_MAX`` free,
  ``>= OCCUPIED_MIN`` occupied, anything between unknown. map_server's
  thresholds, and the protocol's rule (docs/protocol.md) for a sender whose map
  holds percentages.

A map whose cells are already -1 / 0 / 100 is the same under both rules, so a
map that crossed the wire is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["UNKNOWN", "FREE", "OCCUPIED", "OCCUPIED_SPLIT", "FREE_MAX", "OCCUPIED_MIN",
           "MAX_CELLS", "MapError", "GridMap", "world_to_cell", "cell_to_world",
           "check_resolution", "check_origin"]

UNKNOWN = -1
"""Cell value: never observed, or evidence too mixed to tell."""
FREE = 0
"""Cell value: observed free."""
OCCUPIED = 100
"""Cell value: observed occupied."""
OCCUPIED_SPLIT = 50
"""`GridMap.split`: cells at or above this occupancy [%] are occupied, below it free."""
FREE_MAX = 19
"""`GridMap.trinary`: cells at or below this occupancy [%] are free (map_server's 0.196)."""
OCCUPIED_MIN = 65
"""`GridMap.trinary`: cells at or above this occupancy [%] are occupied (map_server's 0.65)."""
MAX_CELLS = 4096 * 4096
"""Cells a map may hold at most."""


class MapError(ValueError):
    """A malformed map or map chunk; the message names what is wrong."""


def world_to_cell(origin_cm: tuple[float, float], resolution_cm: float,
                  x: float, y: float) -> tuple[int, int]:
    """(row, col) of the cell holding point (x, y) [cm] of a grid placed at ``origin_cm``."""
    ox, oy = origin_cm
    return math.floor((y - oy) / resolution_cm), math.floor((x - ox) / resolution_cm)


def cell_to_world(origin_cm: tuple[float, float], resolution_cm: float,
                  row: float, col: float) -> tuple[float, float]:
    """Centre (x, y) [cm] of cell (row, col) of a grid placed at ``origin_cm``."""
    ox, oy = origin_cm
    return ox + (col + 0.5) * resolution_cm, oy + (row + 0.5) * resolution_cm


def check_resolution(resolution_cm: float) -> float:
    """``resolution_cm`` as a float. Raises MapError unless it is a positive finite number."""
    if not (isinstance(resolution_cm, int | float) and math.isfinite(resolution_cm)
            and resolution_cm > 0):
        raise MapError(f"resolution_cm must be a positive number, got {resolution_cm!r}")
    return float(resolution_cm)


def check_origin(origin_cm: tuple[float, float]) -> tuple[float, float]:
    """``origin_cm`` as a pair of floats. Raises MapError unless it is two finite numbers."""
    try:
        ox, oy = (float(v) for v in origin_cm)
    except (TypeError, ValueError):
        raise MapError(f"origin_cm must be a pair of numbers, got {origin_cm!r}") from None
    if not (math.isfinite(ox) and math.isfinite(oy)):
        raise MapError(f"origin_cm must be finite, got {origin_cm!r}")
    return ox, oy


def _percentages(cells: np.ndarray) -> np.ndarray:
    """``cells`` checked: a non-empty 2-D integer array of at most `MAX_CELLS` in -1..100."""
    arr = np.asarray(cells)
    if arr.ndim != 2 or arr.size == 0:
        raise MapError(f"cells must be a non-empty 2-D array, got shape {arr.shape}")
    if arr.size > MAX_CELLS:
        raise MapError(f"cells must hold 1..{MAX_CELLS} cells, got {arr.size}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise MapError(f"cells must hold integers, got dtype {arr.dtype}")
    bad = (arr < -1) | (arr > 100)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise MapError(f"cells must hold -1..100, got {int(arr[r, c])} at [{r}, {c}]")
    return arr


_UNKNOWN_WORD = np.uint64(0xFFFF_FFFF_FFFF_FFFF)
"""Eight unknown int8 cells (-1 each) read as one 64-bit word."""


def _known_row_span(cells: np.ndarray) -> tuple[int, int] | None:
    """The first row of ``cells`` holding a known cell and one past the last, or None.

    From the flat positions of the known cells (their first and last give the rows),
    not from a reduction per row (slow on rows this short). An int8 grid whose rows
    are whole 64-bit words is read eight cells at a time: an all-unknown word is all
    ones."""
    ny, nx = cells.shape
    if cells.dtype == np.int8 and nx % 8 == 0 and cells.flags.c_contiguous:
        per_row = nx // 8
        known = np.flatnonzero(cells.view(np.uint64) != _UNKNOWN_WORD)
    else:
        per_row = nx
        known = np.flatnonzero(cells != UNKNOWN)
    if known.size == 0:
        return None
    return int(known[0]) // per_row, int(known[-1]) // per_row + 1


@dataclass(frozen=True, slots=True, eq=False)
class GridMap:
    """An immutable occupancy map: cells, resolution and where cell [0, 0] is.

    ``cells`` may hold occupancy percentages; they are classified by `split` (see
    the module docstring). ``cells`` is read-only afterwards.

    Raises:
        MapError: (a ValueError) cells that are not a non-empty 2-D integer array of
            -1..100 with at most `MAX_CELLS` cells, a resolution that is not a positive
            number, or an origin that is not two finite numbers.
    """

    cells: np.ndarray
    """int8 (ny, nx): -1 unknown, 0 free, 100 occupied; row 0 is the lowest y."""
    resolution_cm: float = 5.0
    """Cell side [cm]."""
    origin_cm: tuple[float, float] = (0.0, 0.0)
    """Lower-left corner of cell [0, 0] in the holder's frame (rover or map frame) [cm]."""

    def __post_init__(self) -> None:
        cells = self.cells
        if not (isinstance(cells, np.ndarray) and cells.dtype == np.int8 and cells.ndim == 2
                and not cells.flags.writeable):
            cells = GridMap.split(cells)
            cells.flags.writeable = False
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "resolution_cm", check_resolution(self.resolution_cm))
        object.__setattr__(self, "origin_cm", check_origin(self.origin_cm))

    # -- the two classifications ------------------------------------------------------

    @staticmethod
    def split(cells: np.ndarray) -> np.ndarray:
        """Cells of -1..100 as -1 / 0 / 100 by the occupancy split: 0..49 free, 50..100
        occupied (a new int8 array). Raises MapError for cells out of range."""
        arr = _percentages(cells)
        out = np.full(arr.shape, UNKNOWN, dtype=np.int8)
        out[(arr >= 0) & (arr < OCCUPIED_SPLIT)] = FREE
        out[arr >= OCCUPIED_SPLIT] = OCCUPIED
        return out

    @staticmethod
    def trinary(cells: np.ndarray) -> np.ndarray:
        """Cells of -1..100 as -1 / 0 / 100 by map_server's thresholds: ``<= FREE_MAX``
        free, ``>= OCCUPIED_MIN`` occupied, between unknown (a new int8 array). Raises
        MapError for cells out of range."""
        arr = _percentages(cells)
        out = np.full(arr.shape, UNKNOWN, dtype=np.int8)
        out[(arr >= 0) & (arr <= FREE_MAX)] = FREE
        out[arr >= OCCUPIED_MIN] = OCCUPIED
        return out

    @classmethod
    def from_percentages(cls, cells: np.ndarray, resolution_cm: float = 5.0,
                         origin_cm: tuple[float, float] = (0.0, 0.0)) -> GridMap:
        """A map of occupancy percentages classified by `trinary` (map_server's rule)."""
        classes = cls.trinary(cells)
        classes.flags.writeable = False
        return cls(classes, resolution_cm, origin_cm)

    # -- geometry ---------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) [cells]."""
        return self.cells.shape  # type: ignore[return-value]

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell holding point (x, y) [cm]; may lie outside the grid."""
        return world_to_cell(self.origin_cm, self.resolution_cm, x, y)

    def cell_to_world(self, row: float, col: float) -> tuple[float, float]:
        """Centre (x, y) [cm] of cell (row, col)."""
        return cell_to_world(self.origin_cm, self.resolution_cm, row, col)

    def contains(self, row: int, col: int) -> bool:
        """Whether (row, col) is a cell of this grid."""
        ny, nx = self.cells.shape
        return 0 <= row < ny and 0 <= col < nx

    def known_bounds(self) -> tuple[int, int, int, int] | None:
        """Half-open box ``(row0, row1, col0, col1)`` of the known cells, or None.

        The rows come from the known cells' first and last flat position
        (`_known_row_span`), the columns from the rows between them only: a mapper's
        grid is mostly unknown, and the box is asked for at every map change.
        """
        span = _known_row_span(self.cells)
        if span is None:
            return None
        row0, row1 = span
        band = self.cells[row0:row1]
        cols = np.flatnonzero(np.logical_or.reduce(band != UNKNOWN, axis=0))
        return row0, row1, int(cols[0]), int(cols[-1]) + 1

    def crop(self, row0: int, row1: int, col0: int, col1: int) -> GridMap:
        """The sub-map of rows [row0, row1) and columns [col0, col1), clipped to the grid."""
        ny, nx = self.cells.shape
        row0, row1 = max(0, row0), min(ny, row1)
        col0, col1 = max(0, col0), min(nx, col1)
        if row0 >= row1 or col0 >= col1:
            raise ValueError(f"crop box is empty: rows [{row0}, {row1}) cols [{col0}, {col1})")
        ox, oy = self.origin_cm
        sub = self.cells[row0:row1, col0:col1]
        return GridMap(sub, self.resolution_cm,
                       (ox + col0 * self.resolution_cm, oy + row0 * self.resolution_cm))

    def crop_known(self, margin_cells: int = 1) -> GridMap:
        """The smallest sub-map holding every known cell plus a margin of unknown ones.

        An all-unknown map crops to itself.
        """
        box = self.known_bounds()
        if box is None:
            return self
        r0, r1, c0, c1 = box
        m = max(0, int(margin_cells))
        return self.crop(r0 - m, r1 + m, c0 - m, c1 + m)

    # -- the wire -----------------------------------------------------------------------

    def codes(self) -> np.ndarray:
        """The wire codes (0 unknown, 1 free, 2 occupied) as ``uint8``, same shape."""
        out = np.zeros(self.cells.shape, dtype=np.uint8)
        out[self.cells == FREE] = 1
        out[self.cells == OCCUPIED] = 2
        return out

    def same_as(self, other: GridMap) -> bool:
        """True when both maps carry the same cells and placement."""
        return (self.cells.shape == other.cells.shape
                and bool(np.array_equal(self.cells, other.cells))
                and self.resolution_cm == other.resolution_cm
                and tuple(self.origin_cm) == tuple(other.origin_cm))
