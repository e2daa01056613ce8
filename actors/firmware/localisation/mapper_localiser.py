"""The mapper's pose belief: a Gaussian over its map-frame pose, and "odometry broke".

`MapperLocaliser` is pure (no actor, no map of its own): Map Management
(`mapping.map_management`) owns one, feeds it the odometry stamps of the scan
batches, the tread reports and the scans it matched, and places each window
where the localiser says. Why a Gaussian and not particles:
[localisation.md](../../../docs/localisation.md); the loop batch by batch:
[mapping.md](../../../docs/mapping.md) "The pose belief".

* **Predict** (`predict`): the treads' counted travel between two stamps
  (`odometry.tread_travel`) moves the belief through the motion model in
  moments (`GaussianPose.predict`); a tread report (`tread_fault`) widens it by
  the travel the drive model says was driven beyond the count.
* **Gate and weigh** (`weigh_odometry`): a matched scan's fit at the mean and at
  the match is evidence for the second hypothesis, "odometry broke unseen"
  (`odometry_fault`), a mixture component with its own probability
  (`broken`); when it is the more probable, the belief becomes its wide
  component.
* **Update** (`update`): the window is placed where the prediction and the
  match, weighed by the scan's information (`face_information`), put it; the
  belief counts the scan as ``independent_hits`` measurements.
* **The correction** (`correction`): odometry frame -> map frame, the belief's
  mean composed with the inverse of its odometry stamp; navigation keeps it as
  its origin.

Units: [cm], [deg] (covariances in [cm^2] and [rad^2]); the map frame is the
mapper's start frame.
"""

from __future__ import annotations

import numpy as np

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.face_information import face_information
from actors.firmware.localisation.gaussian_pose import GaussianPose
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.localisation.odometry import tread_travel
from actors.firmware.localisation.odometry_fault import (
    FitEvidence,
    OdometryFaultNoise,
    broken_spread,
    evidence,
    hazard,
    posterior,
)
from actors.firmware.localisation.scan_likelihood import (
    GATE_CHI2,
    MAX_BEAMS,
    MIN_FIT,
    FitVerdict,
    ScanFit,
    ScanOptions,
    acceptable_log_fit,
    judge_fit,
    odometry_floor,
)
from server.protocol.pose import Pose, compose, inverse

__all__ = ["MapperLocaliser"]

_SCAN = ScanOptions()  # immutable default: the scan likelihood's noise levels
_ACCEPTABLE = acceptable_log_fit(_SCAN)  # what a just acceptable fit scores per measurement


class MapperLocaliser:
    """The mapper's pose belief (see the module docstring).

    Args:
        track_width_cm: distance between the treads' contact lines [cm] (the motion
            model's geometry; `HardwareSpec.track_width_cm`).
        noise: the motion model's noise levels.
        fault_noise: the prior of the "odometry broke unseen" hypothesis.
        broken_shift_cm: the 95 % radius of the broken component [cm]: what the wide
            search reaches (`MatchOptions.max_shift_cm`).
    """

    def __init__(self, track_width_cm: float, noise: MotionNoise,
                 fault_noise: OdometryFaultNoise, broken_shift_cm: float) -> None:
        self.track_width_cm = track_width_cm
        self.noise = noise
        self.fault_noise = fault_noise
        self.broken_shift_cm = broken_shift_cm
        self.belief = GaussianPose.at(Pose())
        """The pose belief (map frame) at the odometry stamp `stamp`."""
        self.stamp: Pose | None = None
        """The odometry stamp the belief was last moved to (None before the first)."""
        self.correction = Pose()
        """Odometry frame -> map frame: the belief's mean composed with the inverse of
        its odometry stamp (identity until a match or a report moves it)."""
        self.broken = 0.0
        """Weight of the "odometry broke unseen" hypothesis (`odometry_fault`) [1]."""
        self.switches = 0
        """Times the belief became the broken component (data for metrics)."""
        self.reported_at = -float("inf")
        """Trio time of the last tread report that moved the belief [s]."""
        self.step = (0.0, 0.0)
        """The last step between two stamps: travel [cm], turn [rad]."""
        self._weighed_at = -float("inf")  # time of the last scan weighed (`weigh_odometry`)
        # odometry -> map frame under "broken", learnt from a confident fit the narrow
        # belief could not hold (None: not learnt, the broken component is wide)
        self._alt_correction: Pose | None = None
        self._charged = False  # the scans since the last that weighed for "right" paid the
        # broken component's Occam factor (`odometry_fault.evidence`)

    # ------------------------------------------------------------------ motion
    def tread_fault(self, left_cm: float, right_cm: float, now: float) -> bool:
        """Motor Control reported a tread (or both) in the motion that just ended: the
        travel each was driven beyond its count [cm] widens the belief (and moves its
        mean halfway), as the motion model says. False when there is nothing to widen
        (no travel, or no stamp yet)."""
        if (left_cm == 0.0 and right_cm == 0.0) or self.stamp is None:
            return False
        self.belief = self.belief.predict(0.0, 0.0, self.track_width_cm, self.noise,
                                          (left_cm, right_cm))
        self.correction = compose(self.belief.mean, inverse(self.stamp))
        self.reported_at = now
        return True

    def predict(self, odom: Pose) -> None:
        """Move the belief by the treads' counted travel from its stamp to ``odom``, a
        stamp that moved (the first stamp puts it at the corrected stamp)."""
        if self.stamp is None:
            self.stamp = odom
            self.belief = GaussianPose.at(compose(self.correction, odom))
            return
        left, right = tread_travel(self.stamp, odom, self.track_width_cm)
        self.step = (0.5 * (left + right), (right - left) / self.track_width_cm)
        self.belief = self.belief.predict(left, right, self.track_width_cm, self.noise)
        self.stamp = odom
        # the mean moved with the counts: the correction is unchanged, up to rounding
        self.belief = self.belief.moved_to(compose(self.correction, odom))

    def take_frame(self, odom: Pose) -> Pose:
        """A window's frame ``odom`` that is not its last stamp (a flicker: the drive's
        heading): the belief moves to it; returns the guess there (map frame)."""
        self.stamp = odom
        guess = compose(self.correction, odom)
        self.belief = self.belief.moved_to(guess)
        return guess

    def restart_at(self, correction: Pose) -> None:
        """A restarted Map Management takes navigation's copy of the correction back."""
        self.correction = correction

    def wide(self, max_turn_deg: float, max_shift_cm: float) -> bool:
        """Whether the belief is wider than the local match reaches (its 95 % heading over
        ``max_turn_deg`` or its 95 % radius over ``max_shift_cm``)."""
        b = self.belief
        return b.heading95_deg > max_turn_deg or b.radius95_over(max_shift_cm)

    def stamp_covariance(self, moving: bool, travel_cm: float | None) -> np.ndarray:
        """The covariance of a window's stamps' own error: the encoders' rounding
        (`odometry_floor`), the motion within the last batch's tick, uniform over the step
        between two stamps (its variance: the step squared over 12; ``moving``: the rover
        has not stood long enough to have stopped between interrupts), and the odometry's
        error over the window's counted ``travel_cm`` of a drive (None: not a drive; the
        motion model's noise misplaces the earlier batches against the last)."""
        ds, dtheta = self.step if moving else (0.0, 0.0)
        cov = odometry_floor() + np.diag([ds * ds / 12.0, ds * ds / 12.0,
                                          dtheta * dtheta / 12.0])
        if travel_cm is not None:
            within = GaussianPose(self.belief.mean, np.zeros((3, 3))).predict(
                travel_cm, travel_cm, self.track_width_cm, self.noise)
            cov += within.covariance
        return cov

    def within_gate(self, pose: Pose, stamp: np.ndarray) -> bool:
        """Whether ``pose`` lies inside the belief's gate, its covariance widened by the
        stamp's own error ``stamp``."""
        return self.belief.distance2(pose, self.belief.covariance + stamp) <= GATE_CHI2

    # ------------------------------------------------------------------ scans
    def weigh_odometry(self, distance: DistanceField, pts: np.ndarray, match: Pose | None,
                       now: float, stamp: np.ndarray
                       ) -> tuple[ScanFit, ScanFit | None] | None:
        """Weigh a window's scan ``pts`` (local hits) as evidence for "odometry broke
        unseen" (`odometry_fault`) and return its fit at the belief's mean and, when the
        local ``match`` (None: refused) was judged, at the match (`judge_fit` without the
        belief: the caller gates it); when that hypothesis is the more probable, the
        belief becomes its wide component and None is returned (the window's pose is in
        doubt)."""
        if self._weighed_at > -float("inf"):
            self.broken += (1.0 - self.broken) * hazard(now - self._weighed_at,
                                                        self.fault_noise)
        self._weighed_at = now
        at_mean = judge_fit(distance, self.belief.mean, pts, _SCAN)
        if at_mean.verdict in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS):
            return at_mean, None  # nothing to judge the pose by
        narrow = self.belief.covariance + stamp
        spread = broken_spread(self.broken_shift_cm)
        wide = narrow + spread
        odom = self.stamp
        assert odom is not None
        alt = None if self._alt_correction is None else compose(self._alt_correction, odom)
        found: dict[str, float] = {}  # `FitEvidence`'s optional fields this batch fills
        if alt is not None:
            at_alt = judge_fit(distance, alt, pts, _SCAN)
            if at_alt.fit < MIN_FIT:
                alt = self._alt_correction = None  # the scan refutes it
            else:
                found["log_fit_alt"] = at_alt.log_fit
        at_match = None
        if match is not None:
            at_match = judge_fit(distance, match, pts, _SCAN)
            if at_match.verdict not in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS):
                d2 = self.belief.distance2(match, narrow)
                found.update(log_fit_match=at_match.log_fit, d2_match=d2,
                             d2_match_wide=self.belief.distance2(match, wide))
                if alt is not None:
                    found["d2_match_alt"] = GaussianPose(alt, narrow).distance2(match)
                if at_match.fit >= MIN_FIT and d2 > GATE_CHI2:
                    # a confident fit the narrow belief cannot hold: where "broken" would be
                    self._alt_correction = compose(match, inverse(odom))
        ev = FitEvidence(min(float(at_mean.hits), _SCAN.independent_hits), at_mean.log_fit,
                         **found)
        step = evidence(ev, narrow, wide, _ACCEPTABLE, charged=self._charged)
        self._charged = step > 0.0  # a run of scans for "broken" pays its Occam factor once
        self.broken = posterior(self.broken, step)
        if self.broken <= 0.5:
            return at_mean, at_match
        # wide round the mean, not narrow round the learnt pose: one match (a scan blurred
        # by a turn) may have put it a few degrees off; the wide search's unambiguous fit
        # decides where the rover is
        self.belief = self.belief.widened(spread)
        self.broken = 0.0
        self._alt_correction = None
        self._charged = False
        self.switches += 1
        return None

    def update(self, distance: DistanceField, match: Pose, pts: np.ndarray,
               stamp: np.ndarray, batches: int, odom: Pose) -> Pose:
        """An accepted match of a window of ``batches`` batches whose frame is ``odom``:
        returns where the window is placed, and updates the belief and the correction.

        The window's pose is the prediction (the belief and the stamp's own error) and
        the match, weighed by what this one scan's hits say (each of its beams counted);
        the belief (the correction's) counts each batch of the window as
        ``independent_hits`` measurements (its errors repeat from scan to scan) and takes
        the stamp's error as the match's, since it does not carry over to the next
        stamp."""
        info = face_information(distance, match, pts, _SCAN)
        beams = min(len(pts), MAX_BEAMS)
        every_beam = info * max(1.0, beams / _SCAN.independent_hits)
        placed = self.belief.widened(stamp).update(match, every_beam).mean
        self.belief = self.belief.update(match, info * batches, stamp).moved_to(placed)
        self.correction = compose(self.belief.mean, inverse(odom))
        return placed
