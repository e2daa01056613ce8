"""Scan likelihood for the mapper: how well a LIDAR scan fits the map at a pose.

Why
    The mapper places every LIDAR batch by scan matching (`mapping.scan_match`).
    The fit itself is a measurement: the likelihood of the scan at a pose,
    against the map built so far. For one matched pose it gives the verdict
    (`judge_fit`): accepted, or refused with the reason as data (too few hits,
    new ground, a bad fit, or a match outside what the mapper's pose belief
    allows); over particles it weighs a particle belief
    (`scan_log_likelihood`). What a matched scan says about the pose is the
    hits' Fisher information (`face_information`).

Algorithm
    Likelihood field (Thrun et al.; Nav2 AMCL ``likelihood_field``): each hit,
    put in the map frame at the pose, reads the distance ``d`` to the nearest
    mapped obstacle (`distance_field`); its gap to the wall's face is ``g =
    max(0, d - res / 2)`` and its likelihood ``z_hit * exp(-g**2 / (2
    sigma_hit**2)) + z_rand``. A hit on new ground (an unknown cell farther
    than ``new_ground_cm`` from every mapped obstacle: what the map has not
    seen) reads at least ``UNKNOWN_HIT``: it neither confirms nor contradicts
    the pose. The scan's log-likelihood is the sum over at most
    ``MAX_BEAMS`` hits taken evenly along the scan (neighbouring beams are
    not independent; AMCL's ``max_beams``). Everything is vectorised over
    particles times hits.

    The verdict on one pose (`judge_fit`): refused when fewer than
    ``MIN_POINTS`` hits, when under ``MIN_JUDGED`` of them are off new ground
    (nothing to judge by), when the mean hit term ``exp(-g**2 /
    (2 sigma_hit**2))`` over the judged hits is under ``MIN_FIT``
    (a bad fit), or, given the belief's mean and covariance, when the pose's
    squared Mahalanobis distance from it exceeds ``GATE_CHI2`` (the match
    jumped further than the belief allows).

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, section 6.4, table 6.3
    (``likelihood_field_range_finder_model``); Nav2 ``nav2_amcl``
    ``LikelihoodFieldModel`` (``z_hit``, ``z_rand``, ``sigma_hit``,
    ``max_beams``).

Frame and units
    Hits in the rover frame [cm] (forward, left); poses in the map frame;
    particles (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import to_map
from actors.firmware.localisation.gaussian_pose import GaussianPose
from actors.firmware.scan_hits import MAX_RANGE_CM, MIN_JUDGED, MIN_POINTS, MIN_RANGE_CM
from server.protocol.pose import Pose

__all__ = ["ScanOptions", "FitVerdict", "ScanFit", "hits_to_points", "scan_log_likelihood",
           "judge_fit", "gate_fit", "acceptable_log_fit", "odometry_floor",
           "MAX_BEAMS", "UNKNOWN_HIT", "MIN_JUDGED", "MIN_FIT", "GATE_CHI2", "FLOOR_CM",
           "FLOOR_DEG"]


# Structural constants of the likelihood and of the verdict: how many beams a particle's
# likelihood reads (AMCL's ``max_beams``), the neutral term of a hit on new ground, and
# the verdict's least evidence and gate. The hits used are scan matching's
# (`scan_hits`): one LIDAR, one notion of a usable hit.
MAX_BEAMS = 60
"""Hits taken per scan for the likelihood of particles [1]."""
UNKNOWN_HIT = 0.5
"""Least hit term of a hit on new ground [1]: it neither confirms nor refutes."""
MIN_FIT = math.exp(-0.5)
"""Least mean hit term over the judged hits for an accepted fit [1]: the term of a hit
one ``sigma_hit_cm`` from its face (0.61), so a scan whose hits lie on average within
the hit model's spread fits. In a 3 x 2 m test room a pose 5 cm or 3 deg off fits
0.74-0.84, 12 cm across the walls or 10 deg off under 0.5; a shift along most walls'
direction keeps their hits on them (15 cm along the long walls: 0.67), which only the
belief's gate can refuse."""
GATE_CHI2 = 11.34
"""Largest squared Mahalanobis distance of a matched pose from the belief [1]: the
chi-square 99 % point for 3 degrees of freedom (x, y, heading)."""
FLOOR_CM = 1.0
"""Standard deviation added to the belief's x and y when a pose is judged against it [cm]:
a stamp's own error (a batch is stamped with the pose of its tick, not of each ray), so a
collapsed belief still accepts its own mean."""
FLOOR_DEG = 1.0
"""Standard deviation added to the belief's heading when a pose is judged against it [deg]:
the encoders' quantisation (one Int E of one tread turns the dead-reckoned heading by
0.5 cm / 13 cm, 2.2 deg; the rounding of two treads leaves 0.9 deg), which does not add
up from stamp to stamp as the motion noise does."""


_FLOOR = np.diag([FLOOR_CM ** 2, FLOOR_CM ** 2, math.radians(FLOOR_DEG) ** 2])
_FLOOR.flags.writeable = False


def odometry_floor() -> np.ndarray:
    """The 3 x 3 covariance of one odometry stamp's own error (``FLOOR_CM``, ``FLOOR_DEG``)
    of (x [cm], y [cm], heading [rad]): one read-only array (it is added to every batch's
    covariances, so it is not built again for each)."""
    return _FLOOR


@dataclass(frozen=True, slots=True)
class ScanOptions:
    """Noise levels of the scan likelihood (each with its unit)."""

    sigma_hit_cm: float = 3.0
    """Spread of a hit round the mapped face [cm] (range noise, the map's cell size and
    the scan's own blur while turning)."""
    z_rand: float = 0.1
    """Weight of "a hit the map does not explain" (noise, a rover, an unmapped object) in
    the mixture [1]; "the hit lies on a mapped face" weighs the rest (`z_hit`)."""
    new_ground_cm: float = 15.0
    """A hit on an unknown cell farther than this from every mapped obstacle is on new
    ground [cm]. Nearer, it is judged like any other: a pose that puts hits just behind
    a mapped wall (unknown cells: no ray ever crossed it) fits badly."""
    independent_hits: float = 10.0
    """How many independent measurements one scan counts as [1]: the hits of one scan err
    together (the pose they were stamped with, the map's cells, a scan blurred by a
    turn), so the sum of their log-likelihoods is scaled by ``independent_hits / K``.
    Counting every hit as independent makes the belief far surer than it is (its 95 %
    radius shrank under its true error)."""

    def __post_init__(self) -> None:
        if not (self.sigma_hit_cm > 0 and 0 <= self.z_rand < 1):
            raise ValueError("ScanOptions needs sigma_hit_cm > 0 and z_rand in [0, 1), got "
                             f"{self.sigma_hit_cm!r}, {self.z_rand!r}")
        if not self.independent_hits > 0:
            raise ValueError(f"independent_hits must be > 0, got {self.independent_hits!r}")
        if not self.new_ground_cm >= 0:
            raise ValueError(f"new_ground_cm must be >= 0, got {self.new_ground_cm!r}")

    @property
    def z_hit(self) -> float:
        """Weight of "the hit lies on a mapped face" in the mixture: ``1 - z_rand`` [1]."""
        return 1.0 - self.z_rand


class FitVerdict(Enum):
    """The verdict on one scan's fit at one pose."""

    ACCEPTED = "accepted"
    TOO_FEW_HITS = "too few hits"
    NEW_GROUND = "new ground"
    """Too many hits on new ground: the scan cannot be judged against the map."""
    BAD_FIT = "bad fit"
    OUTSIDE_BELIEF = "outside the belief"
    """The pose fits, but lies further from the belief than its spread allows."""


@dataclass(frozen=True, slots=True)
class ScanFit:
    """The fit of one scan at one pose, and the verdict on it."""

    verdict: FitVerdict
    """Accepted, or why not."""
    fit: float
    """Mean hit term over the judged hits, 0..1 (1: every hit on a mapped face) [1]."""
    judged: float
    """Share of the hits not on new ground [1]."""
    hits: int
    """Hits judged [1]."""
    mahalanobis2: float | None
    """Squared Mahalanobis distance from the belief, when one was given [1]."""
    log_fit: float = 0.0
    """Mean log hit likelihood ``log(z_hit * term + z_rand)`` over the judged hits [1]:
    the scan's log-likelihood per measurement, what `odometry_fault` weighs."""

    @property
    def accepted(self) -> bool:
        """Whether the pose may be taken."""
        return self.verdict is FitVerdict.ACCEPTED


def hits_to_points(angles_deg: np.ndarray, ranges_cm: np.ndarray,
                   min_range_cm: float = MIN_RANGE_CM) -> np.ndarray:
    """The usable hits of a scan in the rover frame: (K, 2) forward, left [cm].

    Args:
        angles_deg: ray angles, counter-clockwise from the heading [deg], (n,).
        ranges_cm: ranges [cm], (n,); 0 is "no return".
        min_range_cm: nearer hits are not used, nor hits farther than
            `scan_hits.MAX_RANGE_CM` [cm].

    Raises:
        ValueError: when the arrays are not 1-D of one length.
    """
    a = np.asarray(angles_deg, dtype=float)
    r = np.asarray(ranges_cm, dtype=float)
    if a.ndim != 1 or a.shape != r.shape:
        raise ValueError(f"angles_deg and ranges_cm must be 1-D of one length, got "
                         f"{a.shape} and {r.shape}")
    keep = np.isfinite(a) & np.isfinite(r) & (r >= min_range_cm) & (r <= MAX_RANGE_CM)
    t = np.radians(a[keep])
    return np.column_stack([r[keep] * np.cos(t), r[keep] * np.sin(t)])


def _hit_terms(field: DistanceField, x: np.ndarray, y: np.ndarray, o: ScanOptions
               ) -> tuple[np.ndarray, np.ndarray]:
    """The hit term exp(-g^2 / 2 sigma^2) of each hit and whether it is judged (not on
    new ground)."""
    d, judged = field.at_known(x, y, near_cm=o.new_ground_cm)
    assert judged is not None
    gap = np.maximum(d - 0.5 * field.resolution_cm, 0.0)
    return np.exp(-0.5 * (gap / o.sigma_hit_cm) ** 2), judged


def _beams(points: np.ndarray, max_beams: int) -> np.ndarray:
    """At most ``max_beams`` of the points, taken evenly along the scan: the indices
    ``np.linspace(0, k - 1, max_beams)`` rounds to, formed as linspace forms them (the
    step ``(k - 1) / (max_beams - 1)`` times 0, 1, ..., the last set to ``k - 1``)
    without its wrapper, which costs more than the rest of a scan's information
    matrix's bookkeeping."""
    k = points.shape[0]
    if k <= max_beams:
        return points
    at = np.arange(max_beams, dtype=float)
    at *= (k - 1) / (max_beams - 1)
    at[-1] = k - 1
    return points.take(at.round().astype(np.int64), axis=0)


def scan_log_likelihood(field: DistanceField, particles: np.ndarray, points: np.ndarray,
                        options: ScanOptions | None = None) -> np.ndarray:
    """Log-likelihood (N,) of a scan at every particle.

    Args:
        field: the distance field of the map built so far.
        particles: (N, 3) ``x``, ``y`` [cm], ``theta`` [rad].
        points: (K, 2) hits in the rover frame [cm] (`hits_to_points`).
        options: the model's parameters.

    Returns:
        Zeros when the scan has no usable hit (it tells nothing).
    """
    o = options or ScanOptions()
    p = np.asarray(particles, dtype=float)
    pts = _beams(np.asarray(points, dtype=float).reshape(-1, 2), MAX_BEAMS)
    if pts.shape[0] == 0:
        return np.zeros(p.shape[0])
    x, y = to_map(p, pts)
    term, judged = _hit_terms(field, x, y, o)
    np.maximum(term, UNKNOWN_HIT, out=term, where=~judged)
    term *= o.z_hit
    term += o.z_rand
    scale = min(1.0, o.independent_hits / pts.shape[0])
    return scale * np.add.reduce(np.log(term, out=term), axis=1)


def judge_fit(field: DistanceField, pose: Pose, points: np.ndarray,
              options: ScanOptions | None = None, *, belief_pose: Pose | None = None,
              belief_covariance: np.ndarray | None = None) -> ScanFit:
    """The verdict on a scan placed at ``pose`` (e.g. scan matching's result).

    Args:
        field: the distance field of the map built so far.
        pose: the pose the scan is placed at (map frame).
        points: (K, 2) hits in the rover frame [cm].
        options: the model's parameters.
        belief_pose, belief_covariance: the belief's mean and 3 x 3 covariance of
            (x [cm], y [cm], heading [rad]) (`belief.Spread`); with them, a pose beyond
            ``GATE_CHI2`` is refused (`gate_fit`).
    """
    o = options or ScanOptions()
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    n = int(pts.shape[0])
    if n < MIN_POINTS:
        fit = ScanFit(FitVerdict.TOO_FEW_HITS, 0.0, 0.0, n, None)
    else:
        # the hits put at the pose as `to_map` puts them at one particle (same floats)
        th = pose.heading_rad
        c, s = np.cos(th), np.sin(th)
        px, py = pts[:, 0], pts[:, 1]
        term, judged = _hit_terms(field, pose.x + c * px - s * py, pose.y + s * px + c * py, o)
        k = int(np.count_nonzero(judged))
        fit_mean = log_fit = 0.0
        if k:
            # a mean is the sum over the count (what `ndarray.mean` computes)
            t = term.compress(judged)
            fit_mean = float(np.add.reduce(t)) / k
            t *= o.z_hit
            t += o.z_rand
            log_fit = float(np.add.reduce(np.log(t, out=t))) / k
        share = k / n
        if share < MIN_JUDGED:
            verdict = FitVerdict.NEW_GROUND
        elif fit_mean < MIN_FIT:
            verdict = FitVerdict.BAD_FIT
        else:
            verdict = FitVerdict.ACCEPTED
        fit = ScanFit(verdict, fit_mean, share, n, None, log_fit)
    if belief_pose is None or belief_covariance is None:
        return fit
    return gate_fit(fit, pose, belief_pose, belief_covariance)


def gate_fit(fit: ScanFit, pose: Pose, belief_pose: Pose, belief_covariance: np.ndarray
             ) -> ScanFit:
    """``fit`` (`judge_fit` at ``pose`` without a belief) judged against the belief too:
    its squared Mahalanobis distance from the belief's mean ``belief_pose`` under
    ``belief_covariance`` (3 x 3, of x [cm], y [cm], heading [rad]) is recorded, and an
    accepted fit beyond ``GATE_CHI2`` is refused as outside the belief.

    Why apart: the gate needs only the pose, so a caller that judged the pose already
    (the evidence for "odometry broke unseen") gates that fit instead of reading every
    hit again. The stamp's own error (`odometry_floor`) is added to the covariance (a
    collapsed belief must still accept its own mean).
    """
    cov = np.asarray(belief_covariance, dtype=float) + odometry_floor()
    d2 = GaussianPose(belief_pose, cov).distance2(pose)
    verdict = fit.verdict
    if verdict is FitVerdict.ACCEPTED and d2 > GATE_CHI2:
        verdict = FitVerdict.OUTSIDE_BELIEF
    return ScanFit(verdict, fit.fit, fit.judged, fit.hits, d2, fit.log_fit)


def acceptable_log_fit(options: ScanOptions | None = None) -> float:
    """The mean log hit likelihood [1] of a scan whose every judged hit has the hit term
    ``MIN_FIT``: what a just acceptable fit scores (`ScanFit.log_fit`)."""
    o = options or ScanOptions()
    return math.log(o.z_hit * MIN_FIT + o.z_rand)
