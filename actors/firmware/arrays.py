"""Small array helpers shared by mapping and planning.

Why a module: `np.pad` is a general Python function (modes, per-axis widths) that
costs tens of microseconds before any copying; the firmware pads grids with a
constant border many times per simulated second (matching fields, frontiers,
grid searches), and a constant border is one allocation and one copy.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pad_border"]


def pad_border(values: np.ndarray, width: int = 1, fill: bool | float = 0) -> np.ndarray:
    """``np.pad(values, width, constant_values=fill)`` for a 2-D array: a new array of
    ``values``' dtype with a border of ``width`` cells of ``fill`` on every side.

    Raises:
        ValueError: ``values`` is not 2-D or ``width`` is negative.
    """
    a = np.asarray(values)
    if a.ndim != 2:
        raise ValueError(f"pad_border needs a 2-D array, got {a.ndim}-D")
    if width < 0:
        raise ValueError(f"width must be >= 0, got {width!r}")
    ny, nx = a.shape
    out = np.full((ny + 2 * width, nx + 2 * width), fill, dtype=a.dtype)
    out[width:width + ny, width:width + nx] = a
    return out
