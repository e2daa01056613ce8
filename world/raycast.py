"""Vectorised 2-D ray casting against line segments (numpy).

All rays of one tick share an origin (the LIDAR at the rover's centre). For ray
``o + t d`` (``|d| = 1``) and segment ``p + u s`` the hit is where
``t = (q x s) / (d x s)`` and ``u = (q x d) / (d x s)`` with ``q = p - o``, for
``t > 0`` and ``0 <= u <= 1``; the range is the smallest such ``t`` [cm].
A prototype measured this about 4x faster than pymunk segment queries and 60x
faster than shapely per ray.
"""

from __future__ import annotations

import numpy as np


def cast_rays(origin: tuple[float, float], angles_rad: np.ndarray, segments: np.ndarray,
              max_range: float) -> np.ndarray:
    """Distance from ``origin`` to the nearest segment along each ray.

    Args:
        origin: ray origin (x, y) [cm].
        angles_rad: ray directions in the room frame [rad], shape (M,).
        segments: (N, 4) array of x0, y0, x1, y1 [cm].
        max_range: rays that hit nothing nearer get ``inf`` [cm].

    Returns:
        (M,) distances [cm]; ``inf`` for no hit within ``max_range``.
    """
    angles_rad = np.asarray(angles_rad, dtype=float)
    if len(segments) == 0 or len(angles_rad) == 0:
        return np.full(angles_rad.shape, np.inf)
    dx = np.cos(angles_rad)[:, None]
    dy = np.sin(angles_rad)[:, None]
    qx = segments[:, 0] - origin[0]
    qy = segments[:, 1] - origin[1]
    sx = segments[:, 2] - segments[:, 0]
    sy = segments[:, 3] - segments[:, 1]
    denom = dx * sy - dy * sx
    # (near-)parallel: nan compares false below and warns of nothing
    denom[np.abs(denom) < 1e-12] = np.nan
    inv = 1.0 / denom
    t = (qx * sy - qy * sx) * inv
    u = (qx * dy - qy * dx) * inv
    t[~((t > 1e-9) & (u >= 0.0) & (u <= 1.0))] = np.inf
    t = t.min(axis=1)
    t[t > max_range] = np.inf
    return t


def cull_to_wedge(origin: tuple[float, float], start_rad: float, span_rad: float,
                  segments: np.ndarray) -> np.ndarray:
    """The segments that rays within a wedge could hit (a conservative subset).

    The wedge runs counter-clockwise from ``start_rad`` over ``span_rad`` (< pi). A
    segment is dropped only when both its ends lie strictly outside one of the
    wedge's two bounding half-planes, which no ray in the wedge can then reach.
    A tick's LIDAR samples span about 40 deg, so most segments go.
    """
    if span_rad >= np.pi - 1e-6 or len(segments) == 0:
        return segments
    c0, s0 = np.cos(start_rad), np.sin(start_rad)
    c1, s1 = np.cos(start_rad + span_rad), np.sin(start_rad + span_rad)
    px = segments[:, 0::2] - origin[0]  # (N, 2): both ends
    py = segments[:, 1::2] - origin[1]
    eps = 1e-9
    left_of_start = c0 * py - s0 * px  # >= 0 inside the start half-plane
    right_of_end = c1 * py - s1 * px  # <= 0 inside the end half-plane
    out = ((left_of_start < -eps).all(axis=1)) | ((right_of_end > eps).all(axis=1))
    return segments[~out]
