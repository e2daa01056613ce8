"""What a scan says about the mapper's pose: the Fisher information of its hits on faces.

Why
    The mapper's belief (`gaussian_pose`) is updated by a matched pose with an
    information matrix. A hit on a mapped face pins the pose along that face's
    normal, to the spread of a hit round a face (``ScanOptions.sigma_hit_cm``),
    and pins the heading by the lever of its range: a wall seen at 2 m turns a
    1 deg heading error into 3.5 cm. The likelihood's own curvature (second
    differences of `scan_likelihood.scan_log_likelihood`) cannot read this at a
    match: the hit term is flat within half a cell of a face, so a second
    difference over one cell reads only the tails, and
    with its cross terms it comes out indefinite. On a drawn map it is rank-deficient
    in most matched scans, along a mostly heading direction, which the positive
    semi-definite projection zeroes; a belief updated with it learns the heading from
    odometry, its batches are placed at the prediction's heading, and the map turns
    round the start with the heading odometry carries (a wall 4 m away a few cm per
    degree). The Fisher information keeps what each hit says, in every direction.

Algorithm
    Gauss-Newton information of the likelihood field (Thrun et al. 6.4; the
    covariance of ICP-style scan matching, Censi 2007's first-order term): each hit,
    put in the map frame at the pose, has the unit normal ``n`` of its nearest face
    (the distance field's gradient, central differences over a cell, read a cell in
    front of the hit on the ray's free side: at the hit itself a wall band's inside
    is flat or V-shaped) and the Jacobian ``J = [n_x, n_y, n . dR/dtheta p]`` of its
    distance to the face; the
    information is ``sum r J^T J / sigma_hit**2``, each hit weighed by its
    responsibility ``r = z_hit term / (z_hit term + z_rand)`` (a hit the map does not
    explain says nothing; a hit on new ground is not judged), over at most
    ``MAX_BEAMS`` hits, scaled to ``independent_hits`` measurements like the
    likelihood (`scan_likelihood.scan_log_likelihood`). Where the distance field is
    flat in front of a hit (no face within its reach) the hit has no normal and adds
    nothing. A scan along a corridor's walls gives no
    information along them: the matrix is rank-deficient there, as it should be.

Frame and units
    Hits in the rover frame [cm]; the pose in the map frame; the matrix is of
    (x [cm], y [cm], heading [rad]).
"""

from __future__ import annotations

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import to_map
from actors.firmware.localisation.scan_likelihood import (
    MAX_BEAMS,
    ScanOptions,
    _beams,
    _hit_terms,
)
from actors.firmware.scan_hits import MIN_POINTS
from server.protocol.pose import Pose

__all__ = ["face_information", "MIN_NORMAL"]

MIN_NORMAL = 0.5
"""Least length of the distance field's gradient for a hit to have a face normal [1]: the
field is 1 cm per cm along a face's normal, and flat where no face is within its reach."""


def face_information(field: DistanceField, pose: Pose, points: np.ndarray,
                     options: ScanOptions | None = None) -> np.ndarray:
    """The information matrix (3 x 3, of x [cm], y [cm], heading [rad]) a scan at
    ``pose`` gives about the pose: its hits' Fisher information (module docstring).

    Args:
        field: the distance field of the map built so far.
        pose: the matched pose (map frame).
        points: (K, 2) hits in the rover frame [cm] (`scan_likelihood.hits_to_points`).
        options: the scan likelihood's noise levels (``sigma_hit_cm``, ``z_rand``,
            ``new_ground_cm``, ``independent_hits``).

    Returns:
        Zeros for a scan of fewer than `scan_hits.MIN_POINTS` hits.
    """
    o = options or ScanOptions()
    pts = _beams(np.asarray(points, dtype=float).reshape(-1, 2), MAX_BEAMS)
    if pts.shape[0] < MIN_POINTS:
        return np.zeros((3, 3))
    th = pose.heading_rad
    x, y = to_map(np.array([[pose.x, pose.y, th]]), pts)
    x, y = x[0], y[0]
    # the face's normal: the field's gradient a cell in front of the hit, on the ray's
    # free side (at the hit itself it reads the wall band's flat or V-shaped inside)
    res = field.resolution_cm
    rng = np.maximum(np.hypot(pts[:, 0], pts[:, 1]), 1e-9)
    qx, qy = x - res * (x - pose.x) / rng, y - res * (y - pose.y) / rng
    e = 0.5 * res
    # the four reads of the central differences in one pass (the same floats point by
    # point: a hundred hits cost a numpy call's fixed cost more than its arithmetic)
    ahead = field.at(np.concatenate((qx + e, qx - e, qx, qx)),
                     np.concatenate((qy, qy, qy + e, qy - e)))
    k = qx.shape[0]
    gx = (ahead[:k] - ahead[k:2 * k]) / (2.0 * e)
    gy = (ahead[2 * k:3 * k] - ahead[3 * k:]) / (2.0 * e)
    norm = np.hypot(gx, gy)
    has_normal = norm >= MIN_NORMAL
    nx = np.where(has_normal, gx / np.maximum(norm, 1e-9), 0.0)
    ny = np.where(has_normal, gy / np.maximum(norm, 1e-9), 0.0)
    term, judged = _hit_terms(field, x, y, o)
    # a hit on new ground is no evidence about the pose
    resp = np.where(judged, o.z_hit * term / (o.z_hit * term + o.z_rand), 0.0)
    c, s = np.cos(th), np.sin(th)
    # d(map point)/d(heading) for a rover-frame point (fx, fy)
    dxt = -s * pts[:, 0] - c * pts[:, 1]
    dyt = c * pts[:, 0] - s * pts[:, 1]
    jac = np.column_stack([nx, ny, nx * dxt + ny * dyt])
    scale = min(1.0, o.independent_hits / pts.shape[0])
    info = scale * (jac * resp[:, None]).T @ jac / o.sigma_hit_cm ** 2
    return 0.5 * (info + info.T)
