"""The inverse sensor model of the occupancy grid: what one batch of LIDAR returns
says about the cells along its rays.

`LogOddsModel` holds the log-odds increments a ray adds (``l_free`` to the cells it
crosses, ``l_occ`` to the cell of its hit), the clamps, the thresholds that classify a
cell, the longest range trusted and the sampling step; `grazing_shortening` pulls back
the free end of a ray that meets its surface at a shallow angle; `check_batch` is the
contract a batch must meet. The grid that applies them is `occupancy.OccupancyGrid`.

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, chapter 9 (the inverse range
    sensor model, ``inverse_range_sensor_model``).

Units
    Log-odds for increments and thresholds; ranges [cm]; steps and margins [cells];
    angles [deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["LogOddsModel", "grazing_shortening", "check_batch"]


@dataclass(frozen=True, slots=True)
class LogOddsModel:
    """Inverse sensor model and classification thresholds (all in log-odds)."""

    l_free: float = -0.35
    """Added to a cell a ray passes through: two passes make a cell free, so one stray
    ray (a scan placed a little wrong) cannot open a hole through a wall."""
    l_occ: float = 0.9
    """Added to the cell holding a hit."""
    l_min: float = -2.0
    """Lower clamp: how sure "free" may become."""
    l_max: float = 3.5
    """Upper clamp: how sure "occupied" may become."""
    free_threshold: float = -0.4
    """Below this a cell reads free."""
    occ_threshold: float = 0.4
    """Above this a cell reads occupied."""
    max_range_cm: float = 600.0
    """Longest range trusted [cm]: longer returns and "no return" (0) clear
    free space up to here and mark no hit."""
    ray_step: float = 0.5
    """Sampling step along a ray [cells]."""
    grazing_margin_cells: float = 0.5
    """Free space along a ray with a hit ends this far [cells], measured across the
    surface, before the hit: ``margin / sin(incidence)`` along the ray, so a ray that
    grazes a wall (incidence from the neighbouring returns) stops clearing well before
    the wall line, where a fraction of a degree of pose error would carry it through
    the wall (to the outside, where no later ray can repair the map). 0 turns it off."""

    def __post_init__(self) -> None:
        if not (self.l_min < self.free_threshold < 0 < self.occ_threshold < self.l_max):
            raise ValueError(
                "LogOddsModel needs l_min < free_threshold < 0 < occ_threshold < l_max, got "
                f"{self.l_min}, {self.free_threshold}, {self.occ_threshold}, {self.l_max}"
            )
        if not (self.l_free < 0 < self.l_occ):
            raise ValueError(f"LogOddsModel needs l_free < 0 < l_occ, got {self.l_free}, "
                             f"{self.l_occ}")
        if not (self.max_range_cm > 0 and 0 < self.ray_step <= 1):
            raise ValueError(f"max_range_cm must be > 0 and ray_step in (0, 1], got "
                             f"{self.max_range_cm}, {self.ray_step}")


def grazing_shortening(angles_deg: np.ndarray, ranges_cm: np.ndarray, has_hit: np.ndarray,
                        resolution_cm: float, margin_cells: float) -> np.ndarray:
    """How much to pull back each ray's free end [cells] (0 for rays without a hit).

    The incidence of a return on its surface comes from the neighbouring return (the
    nearer in angle, within 3 [deg], on the more grazing side): for a flat surface
    ``sin(incidence) = r dtheta / hypot(dr, r dtheta)``. A depth jump to the neighbour
    reads as grazing too, which only makes that ray more careful.
    """
    # a batch usually comes in angle order (argsort's identity, no gathers needed)
    in_order = np.logical_and.reduce(angles_deg[1:] >= angles_deg[:-1])
    order = None if in_order else np.argsort(angles_deg, kind="stable")
    a = np.radians(angles_deg if in_order else angles_deg[order])
    r = ranges_cm if in_order else ranges_cm[order]
    hit = has_hit if in_order else has_hit[order]
    # the differences as `np.diff` takes them, without its Python wrapper
    da = a[1:] - a[:-1]
    dr = np.abs(r[1:] - r[:-1])
    ok = (da > 0) & (da <= np.radians(3.0)) & hit[:-1] & hit[1:]
    arc = np.maximum(r[:-1], r[1:]) * da
    sin_pair = np.where(ok, arc / np.maximum(np.hypot(dr, arc), 1e-9), 1.0)
    sin_inc = np.ones(r.size)
    sin_inc[:-1] = sin_pair
    sin_inc[1:] = np.minimum(sin_inc[1:], sin_pair)
    pull = np.where(hit, margin_cells / np.maximum(sin_inc, 0.05), 0.0)
    pull = np.minimum(pull, r / resolution_cm)
    if in_order:
        return pull
    out = np.empty_like(pull)
    out[order] = pull
    return out


def check_batch(angles_deg: np.ndarray, ranges_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A batch's angles and ranges as float64 arrays.

    Raises:
        ValueError: the arrays differ in shape, are not 1-D, or hold a non-finite
            angle or a negative or non-finite range.
    """
    angles = np.asarray(angles_deg, dtype=np.float64)
    ranges = np.asarray(ranges_cm, dtype=np.float64)
    if angles.ndim != 1 or angles.shape != ranges.shape:
        raise ValueError(f"angles_deg and ranges_cm must be 1-D of one length, got "
                         f"{angles.shape} and {ranges.shape}")
    if angles.size == 0:
        return angles, ranges
    # the ufuncs' own reductions, without the array methods' Python wrappers, one per
    # check where one tells: a sum is finite only when every term is (a NaN or an
    # infinity carries through it; an overflowing sum of finite terms gets the full
    # check), and the extremes propagate a NaN
    if not (math.isfinite(np.add.reduce(angles))
            or np.logical_and.reduce(np.isfinite(angles))):
        raise ValueError("angles_deg must be finite")
    if not (np.minimum.reduce(ranges) >= 0 and np.maximum.reduce(ranges) < math.inf):
        raise ValueError("ranges_cm must be finite and >= 0")
    return angles, ranges
