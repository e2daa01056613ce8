"""Free-space measurement model: the rover's body is not inside a mapped obstacle.

Why
    A rover that drove somewhere stands on free ground. A particle whose body
    outline overlaps an occupied cell describes a pose the rover cannot have:
    its weight drops. This is the measurement every rover has at every step
    for free, and it is what keeps a particle cloud that spread along a
    corridor inside the corridor. It is not zero: a map can show an obstacle
    that is not there (a phantom from a badly placed scan), and a model that
    kills every particle there would kill the truth with them.

Algorithm
    The body (a ``length`` x ``width`` rectangle centred on the pose, the
    rover's `HardwareSpec` body), shrunk by one cell on each side, is sampled
    on a regular lattice of points at most half a cell apart; each particle's points are put
    in the map frame at once and looked up in the grid. A particle with any
    point in an occupied cell gets the likelihood ``inside_likelihood``, every
    other one 1. Unknown cells and points off the map are not obstacles (no
    evidence).

Why a cell of shrink
    A mapped face lies up to a cell in front of the wall's face: a LIDAR hit
    on a face lands in the cell on the free side of it when the range noise or
    the mapper's pose error puts it short, and the face lies anywhere in the
    cell that holds it. A rover touching a wall, or passing close by, then
    overlaps the map's occupied cells by up to a cell. Measured on the
    server's maps (the true poses of hider and seeker at rest, at every pose
    frame of three games in generated rooms and three in built-in ones, 2368
    poses): with half a cell of shrink 4 % of them overlapped an occupied cell
    (6 % in the generated rooms, by up to 1.5 cm more), each weighing the
    belief a thousandfold against the truth, away from the wall it touched;
    with a cell none did, save a rover standing on the outline the mapper
    scanned of it while it was parked there (every particle alike: no bias).

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, section 6.6 (map
    consistency: ``p(x | m)``, poses inside obstacles are impossible).

Frame and units
    Particles (N, 3): ``x``, ``y`` [cm], ``theta`` [rad] in the map frame.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField

__all__ = ["FreeSpaceOptions", "body_points", "to_map", "inside_obstacle",
           "free_space_log_likelihood"]


@dataclass(frozen=True, slots=True)
class FreeSpaceOptions:
    """Parameters of the free-space model (the body's size is the rover's, an argument)."""

    inside_likelihood: float = 1e-3
    """Likelihood of a pose whose body overlaps an occupied cell, relative to one that
    does not [1] (the chance that the map's obstacle there is a phantom)."""

    def __post_init__(self) -> None:
        if not 0 < self.inside_likelihood <= 1:
            raise ValueError(f"inside_likelihood must be in (0, 1], got "
                             f"{self.inside_likelihood!r}")


def body_points(length_cm: float, width_cm: float, shrink_cm: float, spacing_cm: float
                ) -> np.ndarray:
    """A lattice over the body rectangle shrunk by ``shrink_cm``, in the body frame.

    Returns:
        (K, 2) forward, left [cm]; at least the centre.
    """
    half_l = max(0.5 * length_cm - shrink_cm, 0.0)
    half_w = max(0.5 * width_cm - shrink_cm, 0.0)
    nl = max(1, math.ceil(2 * half_l / spacing_cm) + 1)
    nw = max(1, math.ceil(2 * half_w / spacing_cm) + 1)
    fx, fy = np.meshgrid(np.linspace(-half_l, half_l, nl), np.linspace(-half_w, half_w, nw),
                         indexing="ij")
    return np.column_stack([fx.ravel(), fy.ravel()])


def to_map(particles: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame ``points`` (K, 2) put at every particle (N, 3): map x, y, each (N, K)."""
    c = np.cos(particles[:, 2])[:, None]
    s = np.sin(particles[:, 2])[:, None]
    fx, fy = points[None, :, 0], points[None, :, 1]
    return (particles[:, 0][:, None] + c * fx - s * fy,
            particles[:, 1][:, None] + s * fx + c * fy)


def _check_body(body_cm: tuple[float, float]) -> tuple[float, float]:
    """``body_cm`` as (length, width) [cm], both positive.

    Raises:
        ValueError: for a size that is not two positive numbers.
    """
    length, width = (float(v) for v in body_cm)
    if not (length > 0 and width > 0):
        raise ValueError(f"body_cm must be (length, width) > 0, got {body_cm!r}")
    return length, width


def inside_obstacle(field: DistanceField, particles: np.ndarray,
                    body_cm: tuple[float, float]) -> np.ndarray:
    """Whether each particle's body, shrunk by a cell on each side (a mapped face lies up
    to a cell in front of the wall's face), overlaps an occupied cell: bool (N,).

    Args:
        field: the map's distance field.
        particles: (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
        body_cm: the rover's body (length along the heading, width) [cm].
    """
    length, width = _check_body(body_cm)
    res = field.resolution_cm
    p = np.asarray(particles, dtype=float)
    pts, reach = _body_lattice(length, width, res)
    # a body point's cell centre lies within reach + res * sqrt(2) of the centre's cell
    # centre (each point within res / sqrt(2) of its own), so a particle whose cell is
    # farther than that from every occupied cell has no point in one: only the others
    # are put on the map and looked up (the same answer, a few particles' work)
    near = np.flatnonzero(~field.cell_farther_than(p[:, 0], p[:, 1], reach + 2.0 * res))
    out = np.zeros(p.shape[0], dtype=bool)
    x, y = to_map(p[near], pts)
    out[near] = np.logical_or.reduce(field.occupied_at(x, y), axis=1)
    return out


@functools.lru_cache(maxsize=8)
def _body_lattice(length_cm: float, width_cm: float, res_cm: float
                  ) -> tuple[np.ndarray, float]:
    """`body_points` of the body shrunk by a cell, half a cell apart (read-only), and the
    farthest point's distance from the centre [cm]: the same for every call of one rover
    on one map, so made once."""
    pts = body_points(length_cm, width_cm, res_cm, 0.5 * res_cm)
    pts.flags.writeable = False
    return pts, float(np.max(np.hypot(pts[:, 0], pts[:, 1])))


def free_space_log_likelihood(field: DistanceField, particles: np.ndarray,
                              body_cm: tuple[float, float],
                              options: FreeSpaceOptions | None = None) -> np.ndarray:
    """Log-likelihood (N,) of "the body (``body_cm``: length, width [cm]) is on free
    ground" for every particle."""
    options = options or FreeSpaceOptions()
    inside = inside_obstacle(field, particles, body_cm)
    return np.where(inside, math.log(options.inside_likelihood), 0.0)
