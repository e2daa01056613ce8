"""Map-constrained motion: a body driven obliquely into a mapped wall slides along it.

Why
    The encoders count the body's motion (its travel along the heading, and
    its turn), not the treads' turning on the spot: a rover pushed square
    into a wall counts nothing and is reported blocked, but one driven into
    it at a slant slides along the face, and its encoders count the slide's
    share along the heading. The tread motion model alone moves such a
    particle straight on into the wall, where the free-space model drops it;
    the particles that were right (the rover did touch the wall) die with the
    ones that were wrong, and the belief is left on poses that drove on
    through free space (a gap's middle, when the rover slid down the wall
    beside it). With the slide the belief keeps the poses that explain the
    counts as a slide, and a later contact tells them from the others.

Algorithm
    After the motion model moved every particle (``before`` -> ``after``), a
    particle whose body now overlaps an occupied cell
    (`free_space_model.inside_obstacle`) is taken to have met a wall on the
    way:

    1. ``u``: the direction it moved in (the mid heading, signed by the
       counted travel ``s`` along it); the wall's outward normal ``n`` is the
       distance field's gradient at the body's leading edge before the
       motion (central differences one cell apart).
    2. The body went freely until its leading edge met the face (the gap
       ``g``, the contact model's, at most ``|s|``), then along the face's
       tangent ``t`` (``t . u > 0``): the encoders counted the slide's share
       along the heading, so it is ``(|s| - g) / (t . u)`` long.
    3. The heading is the motion model's (the treads' difference counted the
       turn).

    A particle is left where the motion model put it (the free-space model
    weighs it down) when no slide explains its counts: the face is too
    square to the motion (``t . u`` under ``MIN_SLIDE_COS``: such a push
    barely counts), no wall is within the field's reach, or the slid body
    overlaps an obstacle too (a corner).

Reference
    Fox, Burgard, Thrun, "Markov localization for mobile robots in dynamic
    environments" (1999), and Thrun, Burgard, Fox, *Probabilistic Robotics*,
    section 5.7 (motion and maps: ``p(x' | u, x, m)``, a motion model that
    knows the map).

Frame and units
    Particles (N, 3): ``x``, ``y`` [cm], ``theta`` [rad] in the map frame.
"""

from __future__ import annotations

import math

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import inside_obstacle

__all__ = ["slide_along_walls", "MIN_SLIDE_COS"]

MIN_SLIDE_COS = 0.25
"""A slide explains a motion's counts only when the face's tangent is within
``acos(MIN_SLIDE_COS)`` (75.5 deg) of the motion [1]: a push squarer than that counts
too little for its slide to be known (a quarter of the slide, at this bound)."""


def _wrap(theta: np.ndarray) -> np.ndarray:
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


def slide_along_walls(field: DistanceField, before: np.ndarray, after: np.ndarray,
                      body_cm: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The poses ``after`` (N, 3), each body that the motion from ``before`` put into a
    mapped wall slid along it instead (a new array only when some particle slid), and
    which of them still overlap an occupied cell (`free_space_model.inside_obstacle`
    of the poses returned, for the free-space model to use as it is).

    Args:
        field: the map's distance field.
        before: (N, 3) the particles before the motion.
        after: (N, 3) the same particles moved by the motion model.
        body_cm: the rover's body (length along the heading, width) [cm].
    """
    inside = inside_obstacle(field, after, body_cm)
    if not inside.any():
        return after, inside
    idx = np.flatnonzero(inside)
    p0, p1 = before[idx], after[idx]
    mid = p0[:, 2] + 0.5 * _wrap(p1[:, 2] - p0[:, 2])
    hx, hy = np.cos(mid), np.sin(mid)
    s = (p1[:, 0] - p0[:, 0]) * hx + (p1[:, 1] - p0[:, 1]) * hy
    sign = np.where(s >= 0.0, 1.0, -1.0)
    ux, uy = hx * sign, hy * sign
    half = 0.5 * float(body_cm[0])
    lx, ly = p0[:, 0] + half * ux, p0[:, 1] + half * uy  # the leading edge's middle
    res = field.resolution_cm
    d = field.at(np.stack([lx + res, lx - res, lx, lx]), np.stack([ly, ly, ly + res, ly - res]))
    gx, gy = (d[0] - d[1]) / (2.0 * res), (d[2] - d[3]) / (2.0 * res)
    norm = np.hypot(gx, gy)
    ok = norm > 1e-9
    norm = np.where(ok, norm, 1.0)
    tx, ty = -gy / norm, gx / norm  # along the face
    along = tx * ux + ty * uy
    flip = np.where(along < 0.0, -1.0, 1.0)
    tx, ty, along = tx * flip, ty * flip, along * flip
    ok &= along >= MIN_SLIDE_COS
    ok &= field.at(lx, ly) < field.max_dist_cm  # a wall within the field's reach
    travel = np.abs(s)
    gap = np.clip(field.at(lx, ly) - 0.5 * res, 0.0, travel)
    slide = (travel - gap) / np.where(ok, along, 1.0)
    slid = np.column_stack([p0[:, 0] + gap * ux + slide * tx,
                            p0[:, 1] + gap * uy + slide * ty, p1[:, 2]])
    ok &= ~inside_obstacle(field, slid, body_cm)
    if not ok.any():
        return after, inside
    out = after.copy()
    out[idx[ok]] = slid[ok]
    inside[idx[ok]] = False
    return out, inside
