"""The mapper's pose belief: one Gaussian over its pose in the map frame (an EKF).

Why a Gaussian, not particles, for the mapper
    The mapper's measurement is scan matching against the map it is building:
    a scan of the room's walls pins the pose to one sharp, unimodal peak (a few
    cm, under a degree), so a mean and a covariance describe the posterior
    well, and they cost a few 3 x 3 products per LIDAR batch (about 20 per
    second) where particles weighed by `scan_likelihood` would cost a scan's
    likelihood per particle per batch. What a Gaussian cannot hold (two far
    apart hypotheses after an unseen turn) the mapper does not keep either: a
    wide belief makes Map Management search the whole of its 95 % bounds
    (`scan_match.relocalise`) and take only an unambiguous fit. The hider and
    seeker, whose contacts are two-sided, keep particles (`belief`).

Algorithm
    Extended Kalman filter (Thrun, Burgard, Fox, *Probabilistic Robotics*,
    section 3.3 and table 5.6's odometry motion model, here per tread):

    * ``predict``: the tread motion model of `motion_model`, linearised. Each
      tread's travel has a mean and a variance: healthy, the count and
      ``encoder_sigma**2 * |count|``; reported by Motor Control (driven but
      not counting, or counting short), ``count + u * D`` with ``u ~ U(0, 1)``
      and ``D`` the travel driven beyond the count, so mean ``count + D / 2``
      and variance ``D**2 / 12`` plus the modelled travel's own error
      (``driven_sigma``); two reported treads share ``u`` (covariance
      ``D_l D_r / 12``). The midpoint rule's Jacobians carry the treads'
      covariance into the pose's, and the scrub of a turn adds
      ``turn_sigma**2 * |dtheta|`` to the heading. No degrees are added by hand:
      a tread's doubt over the track width is the heading's.
    * ``update``: a matched pose ``z`` with its information matrix ``I`` (the
      Fisher information of the scan's hits on their faces, `face_information`),
      in information form so that a direction the scan
      does not constrain (along a corridor) keeps its doubt:
      ``P' = (P^-1 + I)^-1``, ``mu' = mu + P' I (z - mu)``. The odometry stamp's own
      error (its rounding to whole encoder interrupts) is the measurement's, not the
      belief's: it widens ``I``'s covariance, so it never adds up in ``P``.

Frame and units
    Map frame; the mean is a `Pose` ([cm], [deg]); the covariance is of (x [cm],
    y [cm], heading [rad]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.localisation.motion_model import MotionNoise, TreadReport
from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["GaussianPose", "CHI2_2D_95", "Z_95"]

CHI2_2D_95 = 5.991
"""The chi-square 95 % point for 2 degrees of freedom: the 95 % ellipse of the position
[1]."""
Z_95 = 1.96
"""The normal 95 % two-sided point: the 95 % interval of the heading [1]."""


_TINY = 1e-9 * np.eye(3)
"""Added to the covariance before it is inverted: a direction the belief has no doubt in
(the start) stays so, instead of making the inverse singular [cm^2, rad^2]."""
_TINY.flags.writeable = False


def _tread_moments(counted: float, uncounted: float, report: TreadReport,
                   noise: MotionNoise) -> tuple[float, float]:
    """Mean and variance [cm], [cm^2] of one tread's true travel (`motion_model`'s
    sampling, in moments); ``uncounted`` is the travel driven beyond the count."""
    var = noise.encoder_sigma ** 2 * abs(counted)
    if report == TreadReport.OK:
        return counted, var
    driven = counted + uncounted
    # one Gaussian cannot hold the particle model's two explanations (the count right,
    # the drive right); it spans them as a fault whose onset lies anywhere in the motion:
    # u ~ U(0, 1) times (uncounted + driven * z * driven_sigma): E[u] = 1/2, E[u^2] = 1/3
    var += uncounted ** 2 / 12.0 + (driven * noise.driven_sigma) ** 2 / 3.0
    return counted + 0.5 * uncounted, var


@dataclass(frozen=True, slots=True, eq=False)
class GaussianPose:
    """A pose belief: mean and covariance (immutable; each step gives a new one)."""

    mean: Pose
    """Mean pose (map frame)."""
    covariance: np.ndarray
    """3 x 3 covariance of (x [cm], y [cm], heading [rad])."""

    @classmethod
    def at(cls, pose: Pose, sigma_cm: float = 0.0, sigma_deg: float = 0.0) -> GaussianPose:
        """A belief round ``pose`` with independent spreads [cm], [deg]."""
        return cls(pose, np.diag([sigma_cm ** 2, sigma_cm ** 2, math.radians(sigma_deg) ** 2]))

    # -- what it publishes -------------------------------------------------------

    @property
    def radius95_cm(self) -> float:
        """Semi-major axis of the position's 95 % ellipse [cm]."""
        top = float(np.linalg.eigvalsh(self.covariance[:2, :2])[-1])
        return math.sqrt(CHI2_2D_95 * max(top, 0.0))

    def radius95_over(self, limit_cm: float) -> bool:
        """Whether `radius95_cm` exceeds ``limit_cm``.

        Why: the mapper asks it of every batch, and the ellipse's top eigenvalue is at
        most the position covariance's trace, so a belief well inside the limit (its
        trace's radius under 99 % of it) is answered without an eigenvalue solver; any
        other is answered by `radius95_cm` itself (the same answer either way).
        """
        c = self.covariance
        if CHI2_2D_95 * float(c[0, 0] + c[1, 1]) < 0.98 * limit_cm * limit_cm:
            return False
        return self.radius95_cm > limit_cm

    @property
    def heading95_deg(self) -> float:
        """Half-width of the heading's 95 % interval [deg]."""
        return math.degrees(Z_95 * math.sqrt(max(float(self.covariance[2, 2]), 0.0)))

    # -- filtering ---------------------------------------------------------------

    def predict(self, left_cm: float, right_cm: float, track_width_cm: float,
                noise: MotionNoise, uncounted: tuple[float, float] = (0.0, 0.0)) -> GaussianPose:
        """The belief after a motion the encoders counted as ``left_cm``, ``right_cm``.

        Args:
            left_cm, right_cm: each tread's counted travel [cm], signed.
            track_width_cm: distance between the treads' contact lines [cm].
            noise: the motion model's noise levels.
            uncounted: (left, right) travel [cm] Motor Control's model drove beyond the
                count of a tread it reported (signed; 0: not reported).
        """
        reports = [TreadReport.OK if d == 0.0 else TreadReport.SILENT for d in uncounted]
        ml, vl = _tread_moments(left_cm, uncounted[0], reports[0], noise)
        mr, vr = _tread_moments(right_cm, uncounted[1], reports[1], noise)
        both = reports[0] != TreadReport.OK and reports[1] != TreadReport.OK
        cov_lr = uncounted[0] * uncounted[1] / 12.0 if both else 0.0
        w = track_width_cm
        dtheta = (mr - ml) / w
        ds = 0.5 * (mr + ml)
        th = self.mean.heading_rad
        mid = th + 0.5 * dtheta
        c, s = math.cos(mid), math.sin(mid)
        f = np.array([[1.0, 0.0, -ds * s], [0.0, 1.0, ds * c], [0.0, 0.0, 1.0]])
        g = np.array([[0.5 * c + ds * s / (2 * w), 0.5 * c - ds * s / (2 * w)],
                      [0.5 * s - ds * c / (2 * w), 0.5 * s + ds * c / (2 * w)],
                      [-1.0 / w, 1.0 / w]])
        q = np.array([[vl, cov_lr], [cov_lr, vr]])
        cov = f @ self.covariance @ f.T + g @ q @ g.T
        cov[2, 2] += math.radians(1.0) ** 2 * noise.turn_sigma ** 2 * abs(math.degrees(dtheta))
        mean = Pose(self.mean.x + ds * c, self.mean.y + ds * s,
                    self.mean.heading_deg + math.degrees(dtheta))
        return GaussianPose(mean, 0.5 * (cov + cov.T))

    def innovation(self, pose: Pose) -> np.ndarray:
        """``pose - mean`` as (x [cm], y [cm], heading [rad]), the heading across the wrap."""
        return np.array([pose.x - self.mean.x, pose.y - self.mean.y,
                         math.radians(angle_diff_deg(pose.heading_deg, self.mean.heading_deg))])

    def distance2(self, pose: Pose, covariance: np.ndarray | None = None) -> float:
        """Squared Mahalanobis distance of ``pose`` from the mean under ``covariance``
        (3 x 3; the belief's own when None): what a gate compares with ``GATE_CHI2``."""
        e = self.innovation(pose)
        cov = self.covariance if covariance is None else covariance
        return float(e @ np.linalg.solve(cov, e))

    def update(self, pose: Pose, information: np.ndarray,
               stamp_covariance: np.ndarray | None = None) -> GaussianPose:
        """The belief after a measured pose with its information matrix (inverse
        covariance; rank-deficient where the measurement says nothing).

        ``stamp_covariance`` (3 x 3) is an error the measurement shares with nothing
        before it (an odometry stamp's rounding): it adds to the measurement's
        covariance, ``I_eff = (I^-1 + S)^-1``, written so that a singular ``I`` is
        fine (``S^-1 - S^-1 (I + S^-1)^-1 S^-1``), and never accumulates in the belief.
        """
        info = np.asarray(information, dtype=float)
        if stamp_covariance is not None:
            s_inv = np.linalg.inv(np.asarray(stamp_covariance, dtype=float))
            info = s_inv - s_inv @ np.linalg.inv(info + s_inv) @ s_inv
            info = 0.5 * (info + info.T)
        # a belief with no doubt in some direction (the start) keeps it there
        prior = np.linalg.inv(self.covariance + _TINY)
        cov = np.linalg.inv(prior + info)
        cov = 0.5 * (cov + cov.T)
        step = cov @ info @ self.innovation(pose)
        m = self.mean
        mean = Pose(m.x + float(step[0]), m.y + float(step[1]),
                    m.heading_deg + math.degrees(float(step[2])))
        return GaussianPose(mean, cov)

    def widened(self, extra: np.ndarray) -> GaussianPose:
        """The same mean with ``extra`` (3 x 3) added to the covariance."""
        return GaussianPose(self.mean, self.covariance + np.asarray(extra, dtype=float))

    def moved_to(self, mean: Pose) -> GaussianPose:
        """The same covariance round another mean (the odometry frame moved under it)."""
        return GaussianPose(mean, self.covariance)
