"""The mapper's "odometry broke unseen" hypothesis: its weight grows with scans that fit
badly at the belief's mean or well far from it, and falls with scans that fit at the
mean; one bad scan does not outweigh the wide component's Occam factor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.odometry_fault import (
    FitEvidence,
    OdometryFaultNoise,
    broken_spread,
    evidence,
    hazard,
    posterior,
)
from actors.firmware.localisation.scan_likelihood import (
    ScanOptions,
    acceptable_log_fit,
    hits_to_points,
    judge_fit,
)
from server.protocol.pose import Pose
from tests.localisation_rooms import cast
from tests.test_localisation_scan import ANGLES, FIELD, ROOM, TRUTH

POINTS = hits_to_points(ANGLES, cast(ROOM, TRUTH, ANGLES))
NARROW = np.diag([1.0, 1.0, math.radians(1.0) ** 2])
WIDE = NARROW + broken_spread(12.0)
N_EFF = ScanOptions().independent_hits
ACCEPTABLE = acceptable_log_fit()


def _at(pose: Pose) -> float:
    return judge_fit(FIELD, pose, POINTS).log_fit


def _d2(cov: np.ndarray, pose: Pose, mean: Pose) -> float:
    e = np.array([pose.x - mean.x, pose.y - mean.y,
                  math.radians(pose.heading_deg - mean.heading_deg)])
    return float(e @ np.linalg.solve(cov, e))


def test_a_scan_that_fits_at_the_mean_is_evidence_for_right_odometry() -> None:
    ev = FitEvidence(N_EFF, _at(TRUTH), None, 0.0, 0.0)
    assert evidence(ev, NARROW, WIDE, ACCEPTABLE) < -5.0


def test_one_bad_scan_does_not_outweigh_the_prior_but_a_run_of_them_does() -> None:
    """The mean 15 deg off the truth (an unseen slip): each batch's scan fits badly there
    and the local match cannot reach the truth. The weight of "broken" starts at one
    batch's hazard; the first bad scan pays the wide component's Occam factor and leaves
    it under one half; the run's later scans, taken from the same pose, pass it."""
    mean = Pose(TRUTH.x, TRUTH.y, TRUTH.heading_deg - 15.0)
    ev = FitEvidence(N_EFF, _at(mean))
    first = evidence(ev, NARROW, WIDE, ACCEPTABLE)
    later = evidence(ev, NARROW, WIDE, ACCEPTABLE, charged=True)
    assert later > 3.0 and later > first
    noise = OdometryFaultNoise()
    w = posterior(hazard(0.05, noise), first)
    assert w < 0.5
    for _ in range(3):
        w = posterior(w + (1 - w) * hazard(0.05, noise), later)
    assert w > 0.5


def test_a_charged_run_ends_with_a_scan_that_fits_at_the_mean() -> None:
    """After scans that weighed for "broken", one that fits at the mean weighs for "right"
    again, strongly."""
    ev = FitEvidence(N_EFF, _at(TRUTH))
    assert evidence(ev, NARROW, WIDE, ACCEPTABLE, charged=True) < -3.0


def test_confident_fits_away_from_the_mean_make_broken_odometry_the_more_probable() -> None:
    """The local match keeps finding the truth 5 deg and 4 cm from a belief that allows
    1 deg. The first such fit pays the wide component's Occam factor; once it has shown
    where the broken component's pose is, each later fit there weighs for it, and a few
    batches make it the more probable."""
    mean = Pose(TRUTH.x - 4.0, TRUTH.y, TRUTH.heading_deg - 5.0)
    first = FitEvidence(N_EFF, _at(mean), _at(TRUTH), _d2(NARROW, TRUTH, mean),
                        _d2(WIDE, TRUTH, mean))
    later = FitEvidence(N_EFF, _at(mean), _at(TRUTH), _d2(NARROW, TRUTH, mean),
                        _d2(WIDE, TRUTH, mean), log_fit_alt=_at(TRUTH), d2_match_alt=0.0)
    assert evidence(later, NARROW, WIDE, ACCEPTABLE) > evidence(first, NARROW, WIDE, ACCEPTABLE)
    assert evidence(later, NARROW, WIDE, ACCEPTABLE) > 3.0
    noise = OdometryFaultNoise()
    w = posterior(hazard(0.05, noise), evidence(first, NARROW, WIDE, ACCEPTABLE))
    assert w < 0.5
    for _ in range(3):
        w = posterior(w + (1 - w) * hazard(0.05, noise), evidence(later, NARROW, WIDE, ACCEPTABLE))
    assert w > 0.5


def test_a_good_fit_within_the_belief_is_evidence_for_right_odometry() -> None:
    mean = Pose(TRUTH.x - 0.5, TRUTH.y, TRUTH.heading_deg - 0.5)
    ev = FitEvidence(N_EFF, _at(mean), _at(TRUTH), _d2(NARROW, TRUTH, mean),
                     _d2(WIDE, TRUTH, mean))
    assert evidence(ev, NARROW, WIDE, ACCEPTABLE) < 0.0


def test_the_hazard_grows_with_time_and_the_posterior_is_a_probability() -> None:
    noise = OdometryFaultNoise()
    assert hazard(0.0, noise) == 0.0
    assert 0.0 < hazard(0.05, noise) < hazard(1.0, noise) < 1.0
    assert posterior(0.5, 0.0) == pytest.approx(0.5)
    assert posterior(0.01, 1e4) == pytest.approx(1.0)
    assert posterior(0.01, -1e4) == 0.0
    with pytest.raises(ValueError, match="unseen_fault_per_s"):
        OdometryFaultNoise(unseen_fault_per_s=-1.0)


def test_the_broken_component_spans_the_wide_searchs_reach() -> None:
    """Its 95 % heading is a half turn and its 95 % radius the local match's reach."""
    b = broken_spread(12.0)
    assert math.degrees(1.96 * math.sqrt(b[2, 2])) == pytest.approx(180.0)
    assert math.sqrt(5.991 * b[0, 0]) == pytest.approx(12.0)
