"""Slide model: a body driven into a face at a slant slides along it.

Why
    A tread rover that meets a wall at a slant is not stopped: the wall takes
    the part of its motion into the face, and the rest carries it along the
    face. The encoders count the body's motion along its heading only, so dead
    reckoning puts the rover short of where it went and off to one side; the
    free-space model then squeezes the belief against the face, away from the
    truth, and a heading that explains the squeeze wins over the true one. So
    a particle that the tread motion model put into a mapped obstacle, clear
    of it before the motion, is moved along the face instead: the motion model
    with the map's faces in it.

Algorithm
    For each such particle, the face's normal ``n`` is the distance field's
    gradient at the point of the leading edge nearest an obstacle before the
    motion (where the edge was clear: inside a wall one cell thick the field
    rises again towards the wall's far side), and the tangent ``t`` is the
    perpendicular of ``n`` on the side of the heading ``h``. The counts give
    the motion's part along the heading, ``c = d . h`` (``d`` the particle's
    displacement). The body goes free along ``h`` until its leading edge meets
    the face (``f``: the edge's gap before the motion, the distance field's
    distance less half a cell as in `contact_model`, over the rate ``-h . n``
    it closes at), then ``s`` along ``t`` with ``f + s (t . h) = c``: it ends
    touching the face. A slide at a slant ``a`` (``cos a = t . h``) counts
    ``cos(a)**2`` of the travel the treads drove; Motor Control reports both
    treads short under ``min_count_share`` of it, so without that report the
    slant is at most ``acos(sqrt(min_count_share))``. A particle that would
    have met its face more steeply would have stopped (a contact,
    `contact_model`) and is left where it is, for the free-space model.

Frame and units
    Particles (N, 3): ``x``, ``y`` [cm], ``theta`` [rad] in the map frame.
"""

from __future__ import annotations

import math

import numpy as np

from actors.firmware.localisation.contact_model import nearest_edge_point
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import inside_obstacle

__all__ = ["slide_along_faces"]


def slide_along_faces(field: DistanceField, before: np.ndarray, after: np.ndarray,
                      body_cm: tuple[float, float], min_count_share: float) -> np.ndarray:
    """``after`` with every particle that the motion put into a mapped obstacle slid along
    its face.

    Args:
        field: the map's distance field.
        before: (N, 3) the particles before the motion.
        after: (N, 3) the same particles moved by the tread motion model.
        body_cm: the rover's body (length along the heading, width) [cm].
        min_count_share: the share of the driven travel under which Motor Control
            reports both treads short in a move [1].

    Returns:
        A new (N, 3) array (``after`` itself when no particle entered an obstacle).
    """
    entered = inside_obstacle(field, after, body_cm) & ~inside_obstacle(field, before, body_cm)
    idx = np.flatnonzero(entered)
    if idx.size == 0:
        return after
    a, b = after[idx], before[idx]
    h = np.column_stack([np.cos(a[:, 2]), np.sin(a[:, 2])])
    c = np.einsum("ij,ij->i", a[:, :2] - b[:, :2], h)
    min_cos = math.sqrt(min_count_share)
    e = 0.5 * field.resolution_cm
    out = after.copy()
    for direction in (1, -1):
        sel = np.flatnonzero(np.sign(c) == direction)
        if sel.size == 0:
            continue
        # the face: nearest the leading edge before the motion, where the edge was clear
        px, py, gap = nearest_edge_point(field, b[sel], body_cm, direction)
        gx = field.at(px + e, py) - field.at(px - e, py)
        gy = field.at(px, py + e) - field.at(px, py - e)
        norm = np.hypot(gx, gy)
        safe = np.where(norm > 0, norm, 1.0)
        nx, ny = gx / safe, gy / safe  # away from the face
        tx, ty = -ny, nx  # along it
        cos_a = tx * h[sel, 0] + ty * h[sel, 1]
        side = np.where(cos_a * direction < 0, -1.0, 1.0)  # the tangent the motion took
        tx, ty, cos_a = tx * side, ty * side, cos_a * side
        slid = (norm > 0) & (np.abs(cos_a) >= min_cos)
        # free along the heading until the leading edge meets the face, then along it
        approach = -direction * (h[sel, 0] * nx + h[sel, 1] * ny)
        free = np.minimum(gap / np.where(approach > 0, approach, np.inf), np.abs(c[sel]))
        free = direction * free[slid]
        s = (c[sel][slid] - free) / cos_a[slid]
        rows = sel[slid]
        out[idx[rows], 0] = b[rows, 0] + h[rows, 0] * free + tx[slid] * s
        out[idx[rows], 1] = b[rows, 1] + h[rows, 1] * free + ty[slid] * s
    return out
