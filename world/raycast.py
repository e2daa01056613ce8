"""Vectorised 2-D ray casting against line segments (numpy).

All rays of one tick share an origin (the LIDAR at the rover's centre). For ray
``o + t d`` (``|d| = 1``) and segment ``p + u s`` the hit is where
``t = (q x s) / (d x s)`` and ``u = (q x d) / (d x s)`` with ``q = p - o``, for
``t > 0`` and ``0 <= u <= 1``; the range is the smallest such ``t`` [cm].

Two casters: `cast_rays` tests every ray against every segment (any set of
directions; the reference), `FanCaster` casts a fan of evenly spaced rays and
intersects each segment only with the rays inside its angular extent (what the
LIDAR does every tick; `benchmarks.world` times both against pymunk).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

TWO_PI = 2.0 * math.pi
#: slack when deciding whether a ray lies inside a segment's extent [ray steps]
EXTENT_EPS = 1e-9
#: where parked boxes wait: out of any range [cm]
PARKED = (-1e9, -1e9, 0.0)


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


class FanCaster:
    """Casts fans of evenly spaced rays against fixed segments plus a few moving ones.

    A tick's LIDAR samples are consecutive angles from one origin: a *fan* of
    rays ``start + i * step`` for ``i < n``. Instead of testing every ray
    against every segment, each segment's angular extent seen from the origin
    becomes the range of ray indices it covers, only those (ray, segment) pairs
    are intersected, and each ray keeps its nearest hit (``np.minimum.at``). A
    segment not in line with the origin subtends less than pi, so every ray
    strictly inside its extent hits it, at ``t = h / sin(phi - theta)`` where
    ``h`` is the origin's signed distance from the segment's line and ``phi``
    the segment's direction. The per-segment terms of the fixed geometry are
    computed once; `set_boxes` replaces the moving segments (rover bodies).

    Fans wider than pi are cast in parts, so a segment's extent meets a part
    in at most one run of rays. A ray passing exactly through a segment's end
    counts as a hit (as in `cast_rays`); a segment seen edge-on is never hit,
    and one nearly edge-on never hides what lies behind it.

    Args:
        static: (N, 4) segments x0, y0, x1, y1 that never move [cm];
            zero-length ones are ignored.
        boxes: how many rectangles (4 segments each) `set_boxes` places.
    """

    def __init__(self, static: np.ndarray, boxes: int = 0) -> None:
        static = np.asarray(static, dtype=float).reshape(-1, 4)
        static = static[(static[:, 0] != static[:, 2]) | (static[:, 1] != static[:, 3])]
        self._n_static = len(static)
        self._n = len(static) + 4 * boxes
        # rows: x0, y0, x1, y1, then the unit direction ux, uy and its angle phi [rad];
        # one column per segment
        self._geo = np.zeros((7, self._n))
        self._geo[0:4, :self._n_static] = static.T
        # boxes start parked: unit squares far away, never hit
        self._parked = self._box_columns([PARKED], 1.0, 1.0)
        for i in range(boxes):
            self.set_box(i, None, 1.0, 1.0)
        g = self._geo[:, :self._n_static]
        length = np.hypot(g[2] - g[0], g[3] - g[1])
        g[4] = (g[2] - g[0]) / length
        g[5] = (g[3] - g[1]) / length
        g[6] = np.arctan2(g[5], g[4])
        self._origin = np.zeros((4, 1))
        """The ray origin, x, y, x, y [cm], written in place each cast."""

    @property
    def segments(self) -> np.ndarray:
        """Every segment, fixed ones then box edges, (N, 4) x0, y0, x1, y1 [cm]."""
        return self._geo[0:4].T.copy()

    def set_boxes(self, poses: Sequence[tuple[float, float, float]], length: float,
                  width: float) -> None:
        """Place the rectangles: one per ``(x, y [cm], heading [rad])``, ``length`` along it.

        Raises:
            ValueError: not exactly as many poses as boxes were reserved.
        """
        if 4 * len(poses) != self._n - self._n_static:
            raise ValueError(f"expected {(self._n - self._n_static) // 4} box poses, "
                             f"got {len(poses)}")
        if poses:
            self._geo[:, self._n_static:] = self._box_columns(poses, length, width)

    def set_box(self, index: int, pose: tuple[float, float, float] | None, length: float,
                width: float) -> None:
        """Place one rectangle at ``(x, y [cm], heading [rad])``, or park it (``None``).

        A parked box is far out of range: no ray hits it. Parking a box that no ray of
        the next fans can reach (see `fan_may_hit_disc`) saves placing it every tick.

        Raises:
            IndexError: no such box.
        """
        if not 0 <= index < (self._n - self._n_static) // 4:
            raise IndexError(f"box index {index} out of range")
        k = self._n_static + 4 * index
        self._geo[:, k:k + 4] = (self._parked if pose is None
                                 else self._box_columns([pose], length, width))

    @staticmethod
    def _box_columns(poses: Sequence[tuple[float, float, float]], length: float,
                     width: float) -> np.ndarray:
        """The geometry rows of the four edges of each box (plain Python: few boxes)."""
        hl, hw = length / 2.0, width / 2.0
        rows: list[list[float]] = [[], [], [], [], [], [], []]
        x0s, y0s, x1s, y1s, uxs, uys, phis = rows
        for x, y, a in poses:
            c, s = math.cos(a), math.sin(a)
            ax, ay, bx, by = c * hl, s * hl, -s * hw, c * hw
            # corners counter-clockwise from front-left; edges -x, -y, +x, +y of the body
            xs = (x + ax + bx, x - ax + bx, x - ax - bx, x + ax - bx)
            ys = (y + ay + by, y - ay + by, y - ay - by, y + ay - by)
            x0s += xs
            y0s += ys
            x1s += (xs[1], xs[2], xs[3], xs[0])
            y1s += (ys[1], ys[2], ys[3], ys[0])
            uxs += (-c, s, c, -s)
            uys += (-s, -c, s, c)
            phis += (a + math.pi, a - math.pi / 2, a, a + math.pi / 2)
        return np.array(rows)

    def cast_fan(self, origin: tuple[float, float], start_rad: float, step_rad: float, n: int,
                 max_range: float) -> np.ndarray:
        """Ranges along the rays ``start_rad + i * step_rad`` for ``i < n`` [cm].

        Args:
            origin: ray origin (x, y) [cm].
            start_rad: direction of the first ray in the room frame [rad].
            step_rad: angle between consecutive rays, in (0, pi] [rad].
            n: number of rays (any; fans wider than pi are cast in parts).
            max_range: rays that hit nothing nearer get ``inf`` [cm].

        Returns:
            (n,) distances [cm]; ``inf`` for no hit within ``max_range``.

        Raises:
            ValueError: ``step_rad`` is not within (0, pi], or ``n`` is negative.
        """
        if not 0.0 < step_rad <= math.pi:
            raise ValueError(f"step_rad must be within (0, pi], got {step_rad!r}")
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n!r}")
        part = max(1, int(math.pi / step_rad))  # rays per part: spans less than pi
        if n <= part:
            return self._cast_part(origin, start_rad, step_rad, n, max_range)
        return np.concatenate([
            self._cast_part(origin, start_rad + i * step_rad, step_rad, min(part, n - i),
                            max_range) for i in range(0, n, part)])

    def _cast_part(self, origin: tuple[float, float], start: float, step: float, n: int,
                   max_range: float) -> np.ndarray:
        # ndarray methods and ufuncs, not np.full/np.repeat/np.cumsum: their dispatch
        # costs more than the work on these small arrays
        out = np.empty(n)
        out.fill(np.inf)
        if n == 0 or self._n == 0:
            return out
        g = self._geo
        ox, oy = origin
        o = self._origin
        o[0, 0] = o[2, 0] = ox
        o[1, 0] = o[3, 0] = oy
        q = g[0:4] - o
        a0, a1 = np.arctan2(q[1::2], q[0::2])  # directions to both ends [rad]
        # the extent runs counter-clockwise over `w` (<= pi) and ends at `end` [rad]; it is
        # decided from the angles alone, so a segment nearly in line with the origin gets a
        # tiny extent, never a full turn
        d = a1 - a0
        d %= TWO_PI
        ccw = d < math.pi  # p0 -> p1 turns counter-clockwise
        w = np.where(ccw, d, TWO_PI - d)
        end = np.where(ccw, a1, a0)
        # the end relative to the first ray, in [0, 2 pi): with the part narrower than
        # pi the extent then meets the part in at most one run of rays
        end -= start
        end %= TWO_PI
        inv = 1.0 / step
        end *= inv
        w *= inv
        last = np.floor(end + EXTENT_EPS)
        end -= w
        end -= EXTENT_EPS
        first = np.ceil(end, out=end)
        np.maximum(first, 0.0, out=first)
        np.minimum(last, n - 1, out=last)
        last -= first
        count = last.astype(np.int64)
        count += 1
        np.maximum(count, 0, out=count)
        csum = np.add.accumulate(count)
        total = int(csum[-1])
        if total == 0:
            return out
        first_ray = first.astype(np.int64)
        first_ray -= csum
        first_ray += count
        ray = first_ray.repeat(count)
        ray += np.arange(total)
        h = q[0] * g[5]
        h -= q[1] * g[4]  # the origin's signed distance from each segment's line [cm]
        ang = (g[6] - start).repeat(count)
        ang -= ray * step
        sin = np.sin(ang)
        sin[sin == 0.0] = np.nan  # parallel: no hit (and no division by zero)
        t = h.repeat(count)
        t /= sin
        # a segment in line with the origin gives a zero, rounding-sized or nan range: no hit
        t[~(t > 1e-9)] = np.inf
        np.minimum.at(out, ray, t)
        out[out > max_range] = np.inf
        return out


def fan_may_hit_disc(origin: tuple[float, float], start_rad: float, span_rad: float,
                     centre: tuple[float, float], radius: float) -> bool:
    """Whether any ray from ``start_rad`` counter-clockwise over ``span_rad`` can meet a disc.

    Conservative (a True may still miss; a False never hides a hit): the disc of
    ``radius`` [cm] around ``centre`` seen from ``origin`` covers the directions
    within ``asin(radius / distance)`` of its centre's, plus a little slack.
    """
    dx, dy = centre[0] - origin[0], centre[1] - origin[1]
    d = math.hypot(dx, dy)
    if d <= radius * 1.001 or span_rad >= TWO_PI:
        return True
    half = math.asin(radius / d) + 1e-6
    rel = (math.atan2(dy, dx) - start_rad) % TWO_PI
    return rel <= span_rad + half or rel >= TWO_PI - half
