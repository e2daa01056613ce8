"""Contact measurement model: the rover stopped because its body met something.

Why
    Hider and seeker have no range sensor; a blocked motion is their best
    measurement of where they are. The body stopped, so some part of its
    leading edge touches a wall or an obstacle, and no part of it is inside
    one. Scored against the map for every particle, that measurement keeps
    the poses that explain the stop and drops the others, and it keeps *all*
    of them: at a gap's mouth the left front corner on one wall's end and the
    right front corner on the other wall's end both explain a stop, and both
    hypotheses stay in the belief (two clusters) until a later measurement
    tells them apart. Nothing is thrown away for being ambiguous, and nothing
    picks the cheapest explanation.

Algorithm
    The leading edge (the front edge for a forward motion, the rear edge for a
    backward one) is sampled every half cell across the body's width; when the
    side that stalled is known (``side``: +1 left, -1 right, from the yaw while
    stalled) only that half of the edge is taken. For each particle the gap
    between the edge and the nearest obstacle is ``g = max(0, d - res / 2)``,
    ``d`` the distance field's distance (cell centres) at the nearest edge
    point and ``res / 2`` because a wall's face lies half a cell from its
    cell's centre on average. The likelihood is a Gaussian in the gap mixed
    with a uniform term for what the map does not show (another rover, an
    unmapped obstacle): ``p = exp(-g**2 / (2 sigma**2)) + unmapped_weight``,
    times the free-space model's term (`free_space_model`) for a body that
    overlaps an occupied cell.

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, section 6.4 (likelihood
    field with ``z_hit`` / ``z_rand`` mixture), applied to a bump sensor's
    outline instead of laser end points.

Frame and units
    Particles (N, 3): ``x``, ``y`` [cm], ``theta`` [rad] in the map frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import (
    FreeSpaceOptions,
    free_space_log_likelihood,
    to_map,
)

__all__ = ["ContactOptions", "edge_points", "nearest_edge_point", "contact_gap_cm",
           "contact_log_likelihood"]


@dataclass(frozen=True, slots=True)
class ContactOptions:
    """Parameters of the contact model (the body's size is the rover's, an argument;
    a body overlapping an obstacle is scored by `free_space_model.FreeSpaceOptions`)."""

    sigma_cm: float = 1.5
    """Spread of the gap between the leading edge and the wall's face at a contact [cm]:
    the face lies anywhere in the cell that holds it, uniform over a 5 cm cell has a
    standard deviation of 5 / sqrt(12) = 1.4 cm. Wider blurs the two explanations of a
    contact at a 30 cm gap's mouth (7.5 cm of play each side) into one."""
    unmapped_weight: float = 0.02
    """Likelihood, relative to a touching pose's, that something the map does not show
    stopped the rover [1] (``z_rand``): no particle drops to zero on one contact."""

    def __post_init__(self) -> None:
        if not self.sigma_cm > 0:
            raise ValueError(f"sigma_cm must be positive, got {self.sigma_cm!r}")
        if not self.unmapped_weight >= 0:
            raise ValueError(f"unmapped_weight must be >= 0, got {self.unmapped_weight!r}")


def edge_points(length_cm: float, width_cm: float, direction: int, side: int,
                spacing_cm: float) -> np.ndarray:
    """Points on the leading edge of the body, in the body frame (forward, left) [cm].

    Args:
        direction: +1 the blocked motion was forward (front edge), -1 backward (rear).
        side: +1 only the left half, -1 only the right half, 0 the whole edge.
        spacing_cm: largest distance between neighbouring points [cm].

    Raises:
        ValueError: for a direction not +1 / -1 or a side not in -1, 0, +1.
    """
    if direction not in (1, -1):
        raise ValueError(f"direction must be 1 or -1, got {direction!r}")
    if side not in (-1, 0, 1):
        raise ValueError(f"side must be -1, 0 or 1, got {side!r}")
    half_w = 0.5 * width_cm
    lo, hi = (-half_w, half_w) if side == 0 else ((0.0, half_w) if side > 0 else (-half_w, 0.0))
    n = max(2, math.ceil((hi - lo) / spacing_cm) + 1)
    lat = np.linspace(lo, hi, n)
    return np.column_stack([np.full(n, 0.5 * length_cm * direction), lat])


def nearest_edge_point(field: DistanceField, particles: np.ndarray,
                       body_cm: tuple[float, float], direction: int = 1, side: int = 0
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each particle, the point of its leading edge (of a body ``body_cm``: length,
    width [cm]) nearest a mapped obstacle, map x and y [cm], and the gap [cm] between the
    edge there and the nearest mapped face: three (N,) arrays."""
    length, width = body_cm
    res = field.resolution_cm
    pts = edge_points(length, width, direction, side, 0.5 * res)
    x, y = to_map(np.asarray(particles, dtype=float), pts)
    d = field.at(x, y)
    k = np.argmin(d, axis=1)
    rows = np.arange(d.shape[0])
    return x[rows, k], y[rows, k], np.maximum(d[rows, k] - 0.5 * res, 0.0)


def contact_gap_cm(field: DistanceField, particles: np.ndarray, body_cm: tuple[float, float],
                   direction: int = 1, side: int = 0) -> np.ndarray:
    """Gap [cm] between each particle's leading edge (of a body ``body_cm``: length,
    width [cm]) and the nearest mapped face: (N,) (`nearest_edge_point`)."""
    return nearest_edge_point(field, particles, body_cm, direction, side)[2]


def contact_log_likelihood(field: DistanceField, particles: np.ndarray,
                           body_cm: tuple[float, float], direction: int = 1, side: int = 0,
                           options: ContactOptions | None = None,
                           free: FreeSpaceOptions | None = None) -> np.ndarray:
    """Log-likelihood (N,) of "the body stopped against something" for every particle.

    Args:
        field: the map's distance field.
        particles: (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
        body_cm: the rover's body (length along the heading, width) [cm].
        direction: +1 the blocked motion was forward, -1 backward.
        side: the side that stalled, +1 left, -1 right, 0 unknown.
        options: the model's parameters.
        free: the free-space model's parameters (a body inside an obstacle).
    """
    o = options or ContactOptions()
    gap = contact_gap_cm(field, particles, body_cm, direction, side)
    touch = np.exp(-0.5 * (gap / o.sigma_cm) ** 2) + o.unmapped_weight
    return np.log(touch) + free_space_log_likelihood(field, particles, body_cm, free)
