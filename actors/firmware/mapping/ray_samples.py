"""How a batch of LIDAR returns becomes ray samples on a grid [cells].

Why a module of its own
    The occupancy grid (`occupancy.OccupancyGrid`) owns the cells' log-odds and how
    they are updated; which cells a batch observes is geometry alone: each return's
    ray in cell units from its pose, where it hits, and the cells it crosses before
    its (possibly pulled back) end, sampled every ``ray_step`` [cells]. These
    functions hold no state and write nothing but their results: the grid passes its
    extent, its sensor model and its cached ramp of sample offsets.

Frame and units
    As the grid's: a point ``(x, y)`` [cm] of the rover frame is at ``((x - ox) / res,
    (y - oy) / res)`` [cells], ``origin_cm = (ox, oy)`` the lower-left corner of cell
    ``[0, 0]``; a cell ``[row, col]`` has the flat index ``row * nx + col``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from actors.firmware.mapping.sensor_model import LogOddsModel, grazing_shortening

__all__ = ["free_samples", "hit_points", "inside", "ray_geometry"]


def ray_geometry(x: float | np.ndarray, y: float | np.ndarray,
                 heading_deg: float | np.ndarray, angles: np.ndarray, ranges: np.ndarray,
                 model: LogOddsModel, resolution_cm: float, origin_cm: tuple[float, float]
                 ) -> tuple[np.ndarray, np.ndarray, tuple[float, float] | None, np.ndarray,
                            np.ndarray]:
    """The rays' geometry in cell units, from one pose (floats) or one per beam
    (arrays): whether each ray hit; ``rays``, the rows ``cos``, ``sin`` of each ray's
    direction and, from one pose per beam, ``px``, ``py`` of its origin (one array:
    the samples and the hits repeat or select all rows in one call); the origin
    (``px``, ``py``) from one pose, else None; each ray's length and its free length
    (strictly before its end, which is pulled back on rays that graze their surface,
    `sensor_model.grazing_shortening`)."""
    m = model
    res = resolution_cm
    ox, oy = origin_cm
    has_hit = (ranges > 0) & (ranges <= m.max_range_cm)
    length = np.where(has_hit, ranges, m.max_range_cm)  # [cm]
    theta = np.radians(angles + heading_deg)
    per_beam = isinstance(x, np.ndarray)
    out = np.empty((4 if per_beam else 2, angles.size))
    np.cos(theta, out=out[0])
    np.sin(theta, out=out[1])
    origin = None
    if per_beam:
        np.subtract(x, ox, out=out[2])
        out[2] /= res
        np.subtract(y, oy, out=out[3])
        out[3] /= res
    else:
        origin = ((x - ox) / res, (y - oy) / res)
    length_c = length / res
    free_c = length_c
    if m.grazing_margin_cells > 0 and angles.size > 1:
        free_c = length_c - grazing_shortening(angles, ranges, has_hit, res,
                                                m.grazing_margin_cells)
    return has_hit, out, origin, length_c, free_c


def hit_points(has_hit: np.ndarray, rays: np.ndarray, origin: tuple[float, float] | None,
               length_c: np.ndarray) -> np.ndarray:
    """The hits [cells] of the rays that hit, (2, h): the rows x, y (``x = px + cos
    length``; as its sum, ``cos length + px`` is the same float)."""
    hit = rays.compress(has_hit, axis=1)
    hxy = hit[:2]
    hxy *= length_c.compress(has_hit)
    hxy += hit[2:] if origin is None else np.array([[origin[0]], [origin[1]]])
    return hxy


def free_samples(rays: np.ndarray, origin: tuple[float, float] | None, free_c: np.ndarray,
                 step: float, ramp: Callable[[int], np.ndarray], shape: tuple[int, int],
                 first_ray: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Flat indices (in a grid of ``shape`` (ny, nx), with repeats) of the samples of
    every ray at t = 0, step, 2 step, ... strictly before its free length ``free_c``
    [cells], from the ray origin (``px``, ``py``) [cells; ``origin`` for all rays, or
    the rows of ``rays`` per ray] along (``cos``, ``sin``) (``rays``, as `ray_geometry`
    gives them); ``ramp(n)`` gives 0, step, 2 step, ... (n values).

    A sample in the cell of the sample before it is left out (half-cell steps put
    about two samples in each cell): the same cells, half the indices for the grid's
    distinct pass.

    Returns:
        (indices, None); with ``first_ray`` (the index of each batch's first ray, and
        the ray count last), (indices, where each batch's samples start in them, and
        their count last), a batch's first sample always kept, or None when some
        sample lies off the grid. Without it, samples off the grid are dropped.
    """
    n_samples = np.ceil(np.maximum(free_c, 0.0) / step).astype(np.int64)
    total = int(np.add.reduce(n_samples))
    start = n_samples.cumsum()
    start -= n_samples
    if total == 0:
        empty = np.empty(0, dtype=np.int64)
        return empty, (None if first_ray is None else np.zeros(len(first_ray), np.int64))
    # sample k of its ray at t = k step, as a ramp over the whole batch less each
    # ray's offset (all exact multiples of the step: the same floats as k * step);
    # both axes at once, each ray's (cos, sin) repeated per sample (cheaper than
    # gathering them by a ray index) together with its origin and its offset (one
    # repeat), the arithmetic in place: the same operations in the same order as
    # x = cos * t + px, so the same cells
    k = rays.shape[0]
    per_ray = np.empty((k + 1, rays.shape[1]))
    per_ray[:k] = rays
    np.multiply(start, -step, out=per_ray[k])
    rows = per_ray.repeat(n_samples, axis=1)
    t = rows[k]
    t += ramp(total)  # (-offset + ramp: the same float as ramp - offset)
    xy = rows[:2]
    xy *= t
    if origin is None:  # one origin per ray: repeated with the rest
        xy += rows[2:k]
        x0, y0 = np.minimum.reduce(rays[2:], axis=1).tolist()
        x1, y1 = np.maximum.reduce(rays[2:], axis=1).tolist()
    else:
        xy += np.array([[origin[0]], [origin[1]]])
        x0 = x1 = origin[0]
        y0 = y1 = origin[1]
    np.floor(xy, out=xy)
    fx, fy = xy
    ny, nx = shape
    # |cos t| <= t for every sample, and rounding is monotonic: all of them lie
    # within the farthest sample's t of its origin, so when that square round every
    # origin is on the grid, so is every sample, and the flat index is formed in
    # floats (whole numbers far below 2**53: exact)
    reach = (int(np.maximum.reduce(n_samples)) - 1) * step
    if not (x0 - reach >= 0 and y0 - reach >= 0 and x1 + reach < nx and y1 + reach < ny):
        if first_ray is not None:
            return None
        return inside(fy.astype(np.int64), fx.astype(np.int64), shape), None
    fy *= nx
    fy += fx
    # a sample in the cell of the sample before it adds nothing
    keep = np.concatenate(([True], fy[1:] != fy[:-1]))
    if first_ray is None:
        # (`compress`, not a boolean index: twice as fast on an irregular mask)
        return fy.compress(keep).astype(np.int64), None
    # each batch's first sample is kept (it is its own observation); where each
    # batch's kept samples start: the kept samples before its first sample
    first = np.append(start, total)[first_ray].tolist()
    kept = [0]
    for a, b in zip(first[:-1], first[1:], strict=True):
        if a < total:
            keep[a] = True
        # (a count per batch, not a cumulative sum over every sample: 2 against 43 us)
        kept.append(kept[-1] + int(np.count_nonzero(keep[a:b])))
    return fy.compress(keep).astype(np.int64), np.array(kept)


def inside(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Flat indices of the (row, col) cells that lie on a grid of ``shape`` (ny, nx)
    (the others dropped)."""
    ny, nx = shape
    # a negative index reads as a huge unsigned one: one comparison per axis
    on_grid = (rows.view(np.uint64) < ny) & (cols.view(np.uint64) < nx)
    flat = rows * nx + cols
    return flat if np.logical_and.reduce(on_grid) else flat[on_grid]
