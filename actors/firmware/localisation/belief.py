"""The rover's pose belief: a particle filter over its pose in the map frame.

Why a particle filter, not an EKF
    The measurements that matter most to hider and seeker are contacts, and a
    contact near a corner or a gap's mouth has two explanations (the left
    front corner on one wall's end, the right one on the other's): the
    posterior has two separate modes. An EKF holds one Gaussian; it would
    have to pick a side (what the hand-tuned contact rules did, and why they
    threw ambiguous contacts away) or average the two into a pose that
    explains neither. A particle filter keeps both until a later measurement
    tells them apart, and the map's walls (the free-space model) are a hard,
    non-Gaussian constraint that particles take as they are. The rovers' state
    is three numbers and the measurements are few per second, so a few hundred
    particles cost little (every step is vectorised over them).

Algorithm
    Monte Carlo localisation: ``predict`` moves every particle by the tread
    motion model (`motion_model.sample_motion`), ``update`` multiplies the
    weights by a measurement model's likelihood (given as log-likelihoods:
    `contact_model`, `free_space_model`, `scan_likelihood`), and the particles
    are resampled (low-variance, one random number for the whole set) when
    the effective sample size ``1 / sum(w**2)`` falls under
    ``RESAMPLE_ESS * N`` (selective resampling: resampling after every update
    would throw away diversity for nothing).

    What the belief publishes (`Spread`): the weighted mean pose (circular
    mean for the heading), the covariance, the radius round the mean holding
    95 % of the weight [cm] and the heading deviation holding 95 % [deg]
    (weighted quantiles: honest for a two-mode belief, where a covariance
    ellipse is not), and the clusters (`clusters`: modes of the weight
    density, joined where the density between them does not dip), each with
    its weight, mean pose and 95 % spread. One cluster is one hypothesis;
    after a contact at a corner there are two.

Reference
    Thrun, Burgard, Fox, *Probabilistic Robotics*, chapter 8.3 (MCL) and
    table 4.4 (``low_variance_sampler``); PythonRobotics
    ``Localization/particle_filter/particle_filter.py`` (``pf_localization``,
    ``re_sampling``); Nav2 AMCL (clusters, ``resample_interval``).

Frame and units
    Particles are an (N, 3) float array: ``x``, ``y`` [cm] and ``theta``
    [rad], in the map frame. `Pose` values are given in [cm] and [deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.arrays import wrap_angle
from actors.firmware.localisation.clusters import cluster_labels
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion, sample_motion
from server.protocol.pose import Pose, compose, inverse

__all__ = ["BeliefOptions", "Cluster", "Spread", "UpdateReport", "PoseBelief",
           "low_variance_resample", "RESAMPLE_ESS", "MIN_CLUSTER_WEIGHT", "MAX_CLUSTERS"]

_TWO_PI = 2.0 * math.pi


def _wrap(theta: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped to [-pi, pi) (`arrays.wrap_angle`)."""
    return wrap_angle(theta, _TWO_PI)


RESAMPLE_ESS = 0.5
"""Resample when the effective sample size falls under this share of the particles [1]
(the usual N/2 of particle filters; a structural constant of the filter)."""
MIN_CLUSTER_WEIGHT = 0.02
"""Clusters lighter than this share of the weight are not reported [1]."""
MAX_CLUSTERS = 8
"""At most this many clusters are reported, heaviest first (a bound on the report)."""


@dataclass(frozen=True, slots=True)
class BeliefOptions:
    """Parameters of the filter (not of its models). How the hypotheses are found is
    `clusters`'; when to resample and which clusters are reported are the constants
    above."""

    particles: int = 500
    """Number of particles [1]."""

    def __post_init__(self) -> None:
        if not (isinstance(self.particles, int) and 1 <= self.particles <= 1_000_000):
            raise ValueError(f"particles must be an integer in 1..1000000, got "
                             f"{self.particles!r}")


class Cluster:
    """One hypothesis of the belief: a connected group of particles (read-only).

    Its weight and mean pose are computed with it, its 95 % spread when first read, from
    the group's particles as they were (the belief replaces its arrays, it never writes
    into them). Why: navigation reads the heaviest hypothesis's pose after every update
    that may split the belief, and the spreads (a sort of the group each) rarely.

    Args:
        particles: (n, 3) the group's particles.
        weights: (n,) their weights, not normalised (a positive sum).
        weight: the group's share of the belief's weight [1].
    """

    __slots__ = ("_weight", "_pose", "_p", "_wn", "_mean", "_radius95", "_heading95")

    def __init__(self, particles: np.ndarray, weights: np.ndarray, weight: float) -> None:
        wn = weights / weights.sum()
        x, y, heading = _mean(particles, wn)
        self._weight = weight
        self._pose = Pose(x, y, math.degrees(heading))
        self._p, self._wn, self._mean = particles, wn, (x, y, heading)
        self._radius95: float | None = None
        self._heading95: float | None = None

    @property
    def weight(self) -> float:
        """Share of the belief's weight [1]."""
        return self._weight

    @property
    def pose(self) -> Pose:
        """Weighted mean pose of the group (map frame)."""
        return self._pose

    @property
    def radius95_cm(self) -> float:
        """Radius round ``pose`` holding 95 % of the group's weight [cm]."""
        if self._radius95 is None:
            p, (x, y, _) = self._p, self._mean
            self._radius95 = _weighted_quantile(np.hypot(p[:, 0] - x, p[:, 1] - y), self._wn,
                                                0.95)
        return self._radius95

    @property
    def heading95_deg(self) -> float:
        """Heading deviation from ``pose`` holding 95 % of the group's weight [deg]."""
        if self._heading95 is None:
            off = np.abs(_wrap(self._p[:, 2] - self._mean[2]))
            self._heading95 = math.degrees(_weighted_quantile(off, self._wn, 0.95))
        return self._heading95


class Spread:
    """What the belief publishes: where the rover is and how sure it is (read-only).

    The hypotheses and the effective sample size are computed with it; the mean, the
    covariance and the 95 % radius and heading when first read (together: they share
    the particles' offsets from the mean), from the particles as they were, as
    `Cluster`'s spreads are.

    Args:
        particles: (N, 3) the belief's particles.
        weights: (N,) their normalised weights.
        clusters: the hypotheses, heaviest first.
    """

    __slots__ = ("_p", "_w", "_clusters", "_ess", "_whole")

    def __init__(self, particles: np.ndarray, weights: np.ndarray,
                 clusters: tuple[Cluster, ...]) -> None:
        self._p, self._w = particles, weights
        self._clusters = clusters
        self._ess = float(1.0 / np.dot(weights, weights))
        self._whole: tuple[Pose, np.ndarray, float, float] | None = None

    @property
    def pose(self) -> Pose:
        """Weighted mean pose (map frame); between the clusters when there are several."""
        return self._spread()[0]

    @property
    def covariance(self) -> np.ndarray:
        """3 x 3 covariance of (x [cm], y [cm], heading [rad]), read-only."""
        return self._spread()[1]

    @property
    def radius95_cm(self) -> float:
        """Radius round ``pose`` holding 95 % of the weight [cm]."""
        return self._spread()[2]

    @property
    def heading95_deg(self) -> float:
        """Heading deviation from ``pose`` holding 95 % of the weight [deg]."""
        return self._spread()[3]

    @property
    def clusters(self) -> tuple[Cluster, ...]:
        """The hypotheses, heaviest first (one when the belief is single-moded)."""
        return self._clusters

    @property
    def ess(self) -> float:
        """Effective sample size ``1 / sum(w**2)`` [particles]."""
        return self._ess

    @property
    def best(self) -> Cluster:
        """The heaviest hypothesis: the pose to act on when one must be chosen."""
        return self._clusters[0]

    def _spread(self) -> tuple[Pose, np.ndarray, float, float]:
        if self._whole is None:
            w, p = self._w, self._p
            mean = _mean_pose(p, w)
            e = np.column_stack([p[:, 0] - mean.x, p[:, 1] - mean.y,
                                 _wrap(p[:, 2] - mean.heading_rad)])
            cov = (e * w[:, None]).T @ e
            cov.flags.writeable = False
            r95 = _weighted_quantile(np.hypot(e[:, 0], e[:, 1]), w, 0.95)
            h95 = math.degrees(_weighted_quantile(np.abs(e[:, 2]), w, 0.95))
            self._whole = (mean, cov, r95, h95)
        return self._whole


@dataclass(frozen=True, slots=True)
class UpdateReport:
    """What one measurement update did."""

    ess: float
    """Effective sample size after weighting, before any resampling [particles]."""
    resampled: bool
    """Whether the particles were resampled."""
    log_mean_likelihood: float
    """Log of the weighted mean likelihood of the measurement: how well the belief
    as a whole expected it (a fall says the belief may be wrong)."""


def low_variance_resample(weights: np.ndarray, rng: np.random.Generator,
                          count: int | None = None) -> np.ndarray:
    """Indices of the particles drawn by the low-variance (systematic) sampler.

    One uniform draw ``r`` in ``[0, 1/n)``; particle ``i`` is drawn once per
    comb tooth ``r + k / n`` that falls in its share of the cumulative weight,
    so a particle of weight ``w`` is drawn ``floor(n w)`` or ``ceil(n w)`` times.

    Args:
        weights: (N,) non-negative, summing to 1.
        rng: the run's generator.
        count: how many to draw (``n``); N when None.

    Returns:
        (n,) int indices, non-decreasing.
    """
    n = weights.shape[0] if count is None else count
    cum = np.cumsum(weights)
    cum[-1] = 1.0  # rounding must not leave the last tooth past the end
    teeth = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(cum, teeth, side="right"), weights.shape[0] - 1)


def _mean(p: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """Weighted mean of particles ``p`` with normalised weights ``w``: x, y [cm] and the
    circular mean of the heading [rad]."""
    heading = math.atan2(float(w @ np.sin(p[:, 2])), float(w @ np.cos(p[:, 2])))
    return float(w @ p[:, 0]), float(w @ p[:, 1]), heading


def _mean_pose(p: np.ndarray, w: np.ndarray) -> Pose:
    """`_mean` as a `Pose` (heading in degrees)."""
    x, y, heading = _mean(p, w)
    return Pose(x, y, math.degrees(heading))


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = values.argsort(kind="stable")  # the array methods: no wrapper per call
    cum = weights[order].cumsum()
    k = int(np.searchsorted(cum, q * cum[-1], side="left"))
    return float(values[order][min(k, values.shape[0] - 1)])


class PoseBelief:
    """A particle cloud over the rover's map-frame pose, with its weights.

    Args:
        particles: (N, 3) initial particles, ``x``, ``y`` [cm], ``theta`` [rad].
        weights: (N,) initial weights (normalised here); uniform when None.
        options: the filter's parameters (``options.particles`` is not used here:
            the cloud has as many particles as given).

    Raises:
        ValueError: for a bad shape, non-finite values or weights not positive in sum.
    """

    def __init__(self, particles: np.ndarray, weights: np.ndarray | None = None,
                 options: BeliefOptions | None = None) -> None:
        p = np.array(particles, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] == 0:
            raise ValueError(f"particles must have shape (N, 3) with N >= 1, got {p.shape}")
        if not np.isfinite(p).all():
            raise ValueError("particles must be finite")
        n = p.shape[0]
        w = np.full(n, 1.0 / n) if weights is None else np.array(weights, dtype=float)
        if w.shape != (n,) or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
            raise ValueError(f"weights must be (N,) = ({n},) non-negative with a positive sum")
        p[:, 2] = _wrap(p[:, 2])
        self._p = p
        self._w = w / w.sum()
        self.options = options or BeliefOptions()
        """The filter's parameters."""

    @classmethod
    def around(cls, pose: Pose, rng: np.random.Generator, *, sigma_cm: float = 3.0,
               sigma_deg: float = 2.0, options: BeliefOptions | None = None) -> PoseBelief:
        """A belief of ``options.particles`` particles drawn round ``pose`` (Gaussian).

        Args:
            pose: where the rover is believed to be (map frame).
            rng: the run's generator.
            sigma_cm: standard deviation of x and y [cm].
            sigma_deg: standard deviation of the heading [deg].
            options: the filter's parameters.
        """
        o = options or BeliefOptions()
        n = o.particles
        d = rng.standard_normal((n, 3))
        p = np.column_stack([pose.x + sigma_cm * d[:, 0], pose.y + sigma_cm * d[:, 1],
                             pose.heading_rad + math.radians(sigma_deg) * d[:, 2]])
        return cls(p, None, o)

    # -- reading ----------------------------------------------------------------

    @property
    def particles(self) -> np.ndarray:
        """A read-only view of the particles (N, 3)."""
        view = self._p.view()
        view.flags.writeable = False
        return view

    @property
    def weights(self) -> np.ndarray:
        """A read-only view of the normalised weights (N,)."""
        view = self._w.view()
        view.flags.writeable = False
        return view

    def __len__(self) -> int:
        return self._p.shape[0]

    def ess(self) -> float:
        """Effective sample size ``1 / sum(w**2)`` [particles]."""
        return float(1.0 / np.dot(self._w, self._w))

    def mean_pose(self) -> Pose:
        """Weighted mean pose (circular mean of the heading)."""
        return _mean_pose(self._p, self._w)

    def map_to_odom(self, odom: Pose) -> Pose:
        """The correction ``c`` with ``compose(c, odom)`` the mean pose: the map -> odometry
        transform, for a rover whose odometry (own frame) reads ``odom`` now."""
        return compose(self.mean_pose(), inverse(odom))

    def spread(self) -> Spread:
        """The published uncertainty: mean, covariance, 95 % radius and heading, clusters."""
        return Spread(self._p, self._w, self._clusters())

    # -- filtering --------------------------------------------------------------

    def predict(self, motion: TreadMotion, track_width_cm: float, noise: MotionNoise,
                rng: np.random.Generator) -> None:
        """Move every particle by one motion (the weights stay).

        Args:
            motion: Motor Control's counts (and modelled travel of a reported tread).
            track_width_cm: distance between the treads' contact lines [cm].
            noise: the motion model's noise levels.
            rng: the run's generator.
        """
        p = sample_motion(self._p, motion, track_width_cm, noise, rng)
        p[:, 2] = _wrap(p[:, 2])
        self._p = p

    def reposition(self, particles: np.ndarray) -> None:
        """Put the particles where a part of the motion model that needs the map (`slide_model`)
        says they went; the weights stay.

        Raises:
            ValueError: for particles not of this belief's shape, or not finite.
        """
        p = np.array(particles, dtype=float)
        if p.shape != self._p.shape or not np.isfinite(p).all():
            raise ValueError(f"particles must be finite of shape {self._p.shape}, got "
                             f"shape {p.shape}")
        self._p = p

    def update(self, log_likelihood: np.ndarray, rng: np.random.Generator) -> UpdateReport:
        """Weigh the particles by a measurement and resample when they have thinned out.

        Args:
            log_likelihood: (N,) finite log-likelihood of the measurement at each particle
                (any constant offset; the models of this package give them).
            rng: the run's generator (used only when resampling).

        Raises:
            ValueError: when ``log_likelihood`` is not (N,) or not finite.
        """
        ll = np.asarray(log_likelihood, dtype=float)
        if ll.shape != self._w.shape or not np.isfinite(ll).all():
            raise ValueError(f"log_likelihood must be finite of shape {self._w.shape}, got "
                             f"shape {ll.shape}")
        top = float(ll.max())
        lik = np.exp(ll - top)
        w = self._w * lik
        total = float(w.sum())  # > 0: the best particle's lik is 1 and weights are > 0 somewhere
        if total <= 0.0:  # every weighted particle underflowed: keep the measurement alone
            w, total = lik, float(lik.sum())
        log_mean = top + math.log(total)
        self._w = w / total
        ess = self.ess()
        resampled = ess < RESAMPLE_ESS * self._w.shape[0]
        if resampled:
            idx = low_variance_resample(self._w, rng)
            self._p = self._p[idx]
            self._w = np.full(self._w.shape[0], 1.0 / self._w.shape[0])
        return UpdateReport(ess, resampled, log_mean)

    def mixed_with(self, other: PoseBelief, share: float, rng: np.random.Generator
                   ) -> PoseBelief:
        """A belief of as many particles as this one, drawn from the mixture of this
        belief (weight ``1 - share``) and ``other`` (weight ``share``).

        What it is for: a belief that may have been led astray (a route given up after
        its contacts) is widened by the prior it came from (dead reckoning alone, no
        measurement): every hypothesis either held is kept, so the mixture is never
        narrower than either part's support.

        Args:
            other: the second belief (any number of particles).
            share: the weight of ``other`` in the mixture, in [0, 1].
            rng: the run's generator (one draw: the low-variance sampler).

        Raises:
            ValueError: for a ``share`` outside [0, 1].
        """
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"share must be in [0, 1], got {share!r}")
        p = np.vstack([self._p, other._p])
        w = np.concatenate([(1.0 - share) * self._w, share * other._w])
        w = w / w.sum()
        return PoseBelief(p[low_variance_resample(w, rng, self._w.shape[0])], None, self.options)

    # -- clusters ---------------------------------------------------------------

    def _clusters(self) -> tuple[Cluster, ...]:
        lab = cluster_labels(self._p, self._w)
        cw = np.bincount(lab, weights=self._w)
        if cw.shape[0] == 1:  # one hypothesis: every particle
            return (Cluster(self._p, self._w, float(cw[0])),)
        order = [int(k) for k in np.argsort(-cw, kind="stable")
                 if cw[k] >= MIN_CLUSTER_WEIGHT][:MAX_CLUSTERS]
        if not order:
            order = [int(np.argmax(cw))]
        out = []
        for k in order:  # one pass per reported cluster (at most MAX_CLUSTERS)
            m = lab == k
            out.append(Cluster(self._p[m], self._w[m], float(cw[k])))
        return tuple(out)
