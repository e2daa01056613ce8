"""The Euclidean distance transform of a grid, capped: the distance field's one costly step.

Why
    The mapper rebuilds its distance field (`distance_field`) from the map every
    few batches, and the exact distance transform (``scipy.ndimage.
    distance_transform_edt``) of the whole window is most of that: its feature
    transform finds the nearest obstacle of every cell however far it is. The
    field caps the distance (``max_dist_cm``, ten cells), so only obstacles
    within the cap matter, and a cell's distance depends only on its squared
    distance in cells to the nearest obstacle, an integer.

Algorithm
    Separable, as the exact transform is (Felzenszwalb and Huttenlocher): along
    each row, the distance ``h`` in cells to the nearest obstacle of that row
    (from running maxima and minima of the obstacles' columns), capped at
    ``K + 1`` for a cap of ``K`` cells; then down each column, the squared
    distance ``q = min over |dy| <= K of h(row + dy)**2 + dy**2``. Every
    obstacle within the cap lies within ``K`` rows and ``K + 1`` columns, so
    ``q`` is exact wherever the distance is under the cap, and at least
    ``(K + 1)**2`` (beyond the cap) elsewhere. The distance is then read from
    a table over ``q`` holding what ``distance_transform_edt`` computes for an
    offset ``(dy, dx)``, ``sqrt((dy * res)**2 + (dx * res)**2)``, capped. When
    that value depends on the offset and not only on ``q`` (a cell side whose
    multiples round), or the cap spans too many cells for 16-bit squares,
    scipy's transform is used instead.

    Same floats as ``np.minimum(distance_transform_edt(~occupied, sampling=res),
    cap)`` (`tests/test_localisation_distance_field.py` compares them), in about
    half its time on a mapper's window.

Reference
    Felzenszwalb, Huttenlocher, "Distance Transforms of Sampled Functions",
    Theory of Computing 8 (2012): the separable squared transform.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from actors.firmware.ndimage import distance_transform_edt

__all__ = ["capped_distance"]

_MAX_CELLS = 126
"""Largest cap in cells for the separable path: its squares fit 16-bit integers [1]."""


def capped_distance(occupied: np.ndarray, resolution_cm: float, cap_cm: float) -> np.ndarray:
    """Distance [cm] from every cell centre to the nearest occupied cell's centre, capped.

    Args:
        occupied: bool (ny, nx), at least one True.
        resolution_cm: cell side [cm].
        cap_cm: the cap [cm], positive.

    Returns:
        float64 (ny, nx): ``min(distance, cap_cm)``, 0 on occupied cells.
    """
    k = int(math.ceil(cap_cm / resolution_cm))
    table = _table(resolution_cm, cap_cm, k) if k <= _MAX_CELLS else None
    if table is None:
        return np.minimum(distance_transform_edt(~occupied, sampling=resolution_cm), cap_cm)
    return table.take(_squared_cells(occupied, k))


@functools.lru_cache(maxsize=8)
def _table(res: float, cap: float, k: int) -> np.ndarray | None:
    """The capped distance [cm] by squared offset ``q = dy**2 + dx**2`` for every offset
    within ``k`` cells (and the cap for every other ``q`` up to ``(k + 1)**2 + k**2``),
    as `distance_transform_edt` computes it; None when two offsets of one ``q`` give
    different floats. Read-only, and made once per resolution and cap: a mapper's every
    field has the same two, and making the table took about a quarter of a field."""
    steps = np.arange(k + 1)
    dy, dx = np.meshgrid(steps, steps, indexing="ij")
    q = (dy * dy + dx * dx).ravel()
    ay, ax = (dy * res).ravel(), (dx * res).ravel()
    value = np.minimum(np.sqrt(ay * ay + ax * ax), cap)
    table = np.full((k + 1) ** 2 + k * k + 1, float(cap))
    table[q] = value
    table.flags.writeable = False
    return table if np.array_equal(table[q], value) else None


def _squared_cells(occupied: np.ndarray, k: int) -> np.ndarray:
    """Squared distance in cells to the nearest occupied cell, uint8 or int16 (ny, nx)
    (the narrower when ``(k + 1)**2 + k**2`` fits it): exact where
    the distance is at most ``k`` cells, over ``k**2`` elsewhere (see the module
    docstring)."""
    ny, nx = occupied.shape
    far = k + 1
    # column numbers in the narrowest integers that hold -nx - far .. 2 nx + far
    index = np.int16 if 2 * nx + far <= np.iinfo(np.int16).max else np.int32
    cols = np.arange(nx, dtype=index)
    # along the rows: the nearest occupied column at or before, and at or after, each cell
    before = np.where(occupied, cols, index(-nx - far))
    np.maximum.accumulate(before, axis=1, out=before)
    after = np.minimum.accumulate(np.where(occupied, cols, index(2 * nx + far))[:, ::-1],
                                  axis=1)[:, ::-1]
    np.subtract(cols, before, out=before)
    np.subtract(after, cols, out=after)
    h = np.minimum(before, after)
    np.minimum(h, far, out=h)
    # down the columns: h squared padded by k rows of "beyond the cap" above and below,
    # in the narrowest integers that hold every sum (half the memory traffic in bytes)
    small = far * far + k * k <= np.iinfo(np.uint8).max
    padded = np.full((ny + 2 * k, nx), far * far, np.uint8 if small else np.int16)
    np.multiply(h, h, out=padded[k:k + ny], casting="unsafe")
    q = padded[k:k + ny].copy()
    shifted = np.empty_like(q)
    for dy in range(1, k + 1):
        # the rows dy below and dy above share dy**2: min(a, b) + c is min(a + c, b + c)
        np.minimum(padded[k + dy:k + dy + ny], padded[k - dy:k - dy + ny], out=shifted)
        shifted += dy * dy
        np.minimum(q, shifted, out=q)
    return q
