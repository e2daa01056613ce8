"""The mapper's "odometry broke unseen" hypothesis: the second component of its pose belief.

Why
    The mapper's Gaussian belief (`gaussian_pose`) widens only as the motion model says:
    by the encoders' counting noise, and by what Motor Control reports. A slip that
    Motor Control does not see (an encoder counting 70 % of the travel in a turn) leaves
    the belief narrow round a pose tens of degrees off. A gate on that narrow belief
    then refuses every fit near the truth, the local match cannot reach it, and the map
    grows on the wrong pose: the gate locks the truth out. Nothing in the Gaussian alone
    can tell "the scans fit badly here" from noise, so the belief is a mixture of two
    hypotheses (a switching model, as in Gaussian-sum and multiple-model filters):

    * **odometry right** (weight ``1 - w``): the Gaussian ``N(mu, P)``;
    * **odometry broken** (weight ``w``): the same mean with the wide covariance
      ``P + B``, where ``B`` spans what the wide search (`scan_match.relocalise`) reaches:
      a 95 % heading of a half turn and a 95 % radius of the local match's reach.

    Its weight is a probability, updated by Bayes' rule from each batch's scan:

    * **prior**: before each batch, the hazard of an unseen fault over the time since
      the last, ``w <- w + (1 - w) (1 - exp(-rate * dt))`` (per time, not per counted
      travel: an encoder that counts nothing while its tread turns counts no travel);
    * **evidence**: the likelihood of the scan under each component (`evidence`). Under
      "right", the scan fits where the narrow Gaussian allows: at its mean, or at the
      local match weighed by its density there. Under "broken", it fits where the wide
      one allows: at the same poses weighed by the wide density, or somewhere else in
      the wide region as well as an acceptable fit does (`scan_likelihood.MIN_FIT`).
      The wide density's lower peak is the Occam factor: one bad batch does not
      outweigh it, scans that keep fitting badly, or keep fitting well far from the
      mean, do.

    When "broken" is the more probable (``w > 1/2``), the belief becomes the broken
    component, wide round the mean: it is then wider than the local match reaches, so Map
    Management places nothing unmatched and searches the wide region for an
    unambiguous fit, which narrows it again. No count of refusals is a trigger: a run
    of good fits away from the mean and a run of bad fits are both evidence, weighed
    by how bad and how far.

Frame and units
    As `gaussian_pose`: covariance of (x [cm], y [cm], heading [rad]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.localisation.gaussian_pose import CHI2_2D_95, Z_95

__all__ = ["OdometryFaultNoise", "FitEvidence", "broken_spread", "hazard", "evidence",
           "posterior"]


@dataclass(frozen=True, slots=True)
class OdometryFaultNoise:
    """The noise level of the "odometry broken" hypothesis."""

    unseen_fault_per_s: float = 0.01
    """Rate of odometry faults Motor Control does not report (a slip it does not see)
    [1/s]: the prior of the hypothesis, a pessimistic one per 100 s of mapping (a higher
    rate makes the mapper search sooner, on less evidence)."""

    def __post_init__(self) -> None:
        if not self.unseen_fault_per_s >= 0:
            raise ValueError(f"unseen_fault_per_s must be >= 0, got "
                             f"{self.unseen_fault_per_s!r}")


@dataclass(frozen=True, slots=True)
class FitEvidence:
    """What one batch's scan says about the two hypotheses (see `evidence`)."""

    n_eff: float
    """Independent measurements the scan counts as [1]."""
    log_fit_mean: float
    """Mean log hit likelihood of the scan at the belief's mean [1]."""
    log_fit_match: float | None = None
    """The same at the local match, when the matcher found one [1]."""
    d2_match: float = 0.0
    """The match's squared Mahalanobis distance from the narrow component [1]."""
    d2_match_wide: float = 0.0
    """The same from the broken component [1]."""
    log_fit_alt: float | None = None
    """Mean log hit likelihood at the broken component's learnt pose, when it has one [1]."""
    d2_match_alt: float = 0.0
    """The match's squared Mahalanobis distance from that pose (narrow covariance) [1]."""


def broken_spread(max_shift_cm: float) -> np.ndarray:
    """``B``: the covariance the broken component adds (3 x 3): a 95 % radius of
    ``max_shift_cm`` and a 95 % heading of a half turn, what the wide search reaches."""
    s = max_shift_cm / math.sqrt(CHI2_2D_95)
    return np.diag([s * s, s * s, (math.pi / Z_95) ** 2])


def hazard(dt_s: float, noise: OdometryFaultNoise) -> float:
    """Probability [1] that an unseen odometry fault happened within ``dt_s`` [s]."""
    return 1.0 - math.exp(-noise.unseen_fault_per_s * max(dt_s, 0.0))


def _half_logdet(cov: np.ndarray) -> float:
    sign, logdet = np.linalg.slogdet(cov)
    return 0.5 * logdet if sign > 0 else 0.0


def evidence(ev: FitEvidence, narrow: np.ndarray, wide: np.ndarray,
             log_fit_acceptable: float, *, charged: bool = False) -> float:
    """Log likelihood ratio (broken over right) [1] of one batch's scan.

    Each hypothesis explains the scan by the best of the poses it holds, weighed by its
    density there: the mean (d2 = 0) and the local match (``d2`` from each component);
    the broken one also by a pose elsewhere in its region (density of a typical point,
    ``exp(-3/2)`` below the peak for three dimensions) fitting as an acceptable fit does.

    The Occam factor is paid once per run of scans that weigh for "broken"
    (``charged``: the batches before paid it): every scan of the run was taken from the
    same unknown pose, so the wide prior's volume is spent once, and after it the broken
    component stands for that one pose, a pose away from the mean that fits as an
    acceptable fit does (or its learnt pose: a confident fit away from the mean showed
    where it is, and it moves with odometry since). The caller clears ``charged`` when a
    scan weighs for "right".
    """
    n = ev.n_eff
    half_narrow = _half_logdet(narrow)
    ok = [n * ev.log_fit_mean]
    if ev.log_fit_match is not None:
        ok.append(n * ev.log_fit_match - 0.5 * ev.d2_match)
    right = max(ok) - half_narrow
    if charged:
        broken = n * log_fit_acceptable - 1.5 - half_narrow
    else:
        br = [n * ev.log_fit_mean, n * log_fit_acceptable - 1.5]
        if ev.log_fit_match is not None:
            br.append(n * ev.log_fit_match - 0.5 * ev.d2_match_wide)
        broken = max(br) - _half_logdet(wide)
    if ev.log_fit_alt is not None:
        alt = [n * ev.log_fit_alt]
        if ev.log_fit_match is not None:
            alt.append(n * ev.log_fit_match - 0.5 * ev.d2_match_alt)
        broken = max(broken, max(alt) - half_narrow)
    return broken - right


def posterior(prior: float, log_ratio: float) -> float:
    """The broken hypothesis's weight [1] after a batch with ``log_ratio`` (`evidence`)."""
    p = min(max(prior, 1e-12), 1.0 - 1e-12)
    logit = math.log(p / (1.0 - p)) + log_ratio
    return 1.0 / (1.0 + math.exp(-logit)) if logit > -700 else 0.0
