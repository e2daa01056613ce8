"""The scan likelihood: a scan fits the map where the rover stands, and a bad fit,
new ground or a jump beyond the belief is refused, with the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.scan_likelihood import (
    MIN_FIT,
    MIN_JUDGED,
    FitVerdict,
    gate_fit,
    hits_to_points,
    judge_fit,
    scan_log_likelihood,
)
from server.protocol.pose import Pose
from tests.localisation_rooms import cast, room

ROOM = room(300.0, 200.0, (180.0, 60.0, 40.0, 30.0), (40.0, 140.0, 60.0, 20.0))
FIELD = DistanceField.from_grid(ROOM)
TRUTH = Pose(110.0, 80.0, 20.0)
ANGLES = np.arange(0.0, 360.0, 1.0)


def _scan(pose: Pose = TRUTH, seed: int = 1) -> np.ndarray:
    """The scan taken at ``pose`` with 0.5 cm of range noise, as rover-frame points."""
    ranges = cast(ROOM, pose, ANGLES)
    ranges = ranges + np.random.default_rng(seed).normal(0.0, 0.5, ranges.shape)
    return hits_to_points(ANGLES, ranges)


def test_a_scan_fits_where_it_was_taken() -> None:
    """At the true pose every hit lies on a mapped face: accepted, fit near 1; a few cm
    off is still accepted (scan matching refines it)."""
    fit = judge_fit(FIELD, TRUTH, _scan())
    assert fit.verdict is FitVerdict.ACCEPTED and fit.accepted
    assert fit.fit > 0.95 and fit.judged == 1.0 and fit.hits == 360
    near = Pose(TRUTH.x + 2.0, TRUTH.y - 2.0, TRUTH.heading_deg + 1.0)
    assert judge_fit(FIELD, near, _scan()).accepted


@pytest.mark.parametrize(("dx", "dy", "dh"), [(15.0, 10.0, 0.0), (0.0, -12.0, 0.0),
                                              (0.0, 0.0, 10.0), (8.0, 8.0, 6.0)],
                         ids=["15cm-10cm", "12cm-y", "10deg", "8cm-8cm-6deg"])
def test_a_bad_fit_is_refused(dx: float, dy: float, dh: float) -> None:
    """The same scan placed 12-18 cm or 10 deg off fits badly: refused as a bad fit."""
    off = Pose(TRUTH.x + dx, TRUTH.y + dy, TRUTH.heading_deg + dh)
    fit = judge_fit(FIELD, off, _scan())
    assert fit.verdict is FitVerdict.BAD_FIT and not fit.accepted
    assert fit.fit < MIN_FIT


def test_a_scan_of_new_ground_is_not_judged_a_bad_fit() -> None:
    """Where the map has not seen most of what the scan sees, the verdict is new ground."""
    unseen = DistanceField.from_grid(room(300.0, 200.0, (180.0, 60.0, 40.0, 30.0),
                                          unknown_beyond_x=40.0))
    fit = judge_fit(unseen, Pose(200.0, 120.0, 0.0), _scan(Pose(200.0, 120.0, 0.0)))
    assert fit.verdict is FitVerdict.NEW_GROUND
    assert fit.judged < MIN_JUDGED


def test_too_few_hits_are_not_judged() -> None:
    """Eleven hits are too few."""
    assert judge_fit(FIELD, TRUTH, _scan()[:11]).verdict is FitVerdict.TOO_FEW_HITS


def test_a_good_fit_far_outside_the_belief_is_refused() -> None:
    """The scan fits at the truth, but the belief (5 cm, 2 deg) is centred 30 cm away:
    refused as outside the belief; a belief that wide (30 cm) accepts it."""
    belief = Pose(TRUTH.x + 30.0, TRUTH.y, TRUTH.heading_deg)
    tight = np.diag([25.0, 25.0, math.radians(2.0) ** 2])
    wide = np.diag([900.0, 900.0, math.radians(10.0) ** 2])
    far = judge_fit(FIELD, TRUTH, _scan(), belief_pose=belief, belief_covariance=tight)
    assert far.verdict is FitVerdict.OUTSIDE_BELIEF and far.mahalanobis2 > 11.34
    near = judge_fit(FIELD, TRUTH, _scan(), belief_pose=belief, belief_covariance=wide)
    assert near.verdict is FitVerdict.ACCEPTED


def test_gating_a_judged_fit_keeps_the_fit_and_its_first_reason() -> None:
    """A fit judged without the belief, gated afterwards, reads as judged with it: the
    fit figures are kept and the distance recorded; a pose outside the belief is
    refused only when nothing refused it before (a bad fit or too few hits stay so)."""
    belief = Pose(TRUTH.x + 30.0, TRUTH.y, TRUTH.heading_deg)
    tight = np.diag([25.0, 25.0, math.radians(2.0) ** 2])
    scan = _scan()
    good = judge_fit(FIELD, TRUTH, scan)
    gated = gate_fit(good, TRUTH, belief, tight)
    assert gated == judge_fit(FIELD, TRUTH, scan, belief_pose=belief, belief_covariance=tight)
    assert gated.verdict is FitVerdict.OUTSIDE_BELIEF
    assert (gated.fit, gated.judged, gated.hits, gated.log_fit) == (
        good.fit, good.judged, good.hits, good.log_fit)
    assert gated.mahalanobis2 is not None and gated.mahalanobis2 > 11.34
    off = Pose(TRUTH.x + 15.0, TRUTH.y + 10.0, TRUTH.heading_deg)
    bad = gate_fit(judge_fit(FIELD, off, scan), off, belief, tight)
    assert bad.verdict is FitVerdict.BAD_FIT and bad.mahalanobis2 is not None
    few = gate_fit(judge_fit(FIELD, TRUTH, scan[:11]), TRUTH, belief, tight)
    assert few.verdict is FitVerdict.TOO_FEW_HITS


def test_the_scan_likelihood_is_highest_at_the_truth() -> None:
    """Among poses on a grid round the truth (+-10 cm, +-6 deg) the truth scores best."""
    dx, dy, dh = np.meshgrid([-10.0, -5.0, 0.0, 5.0, 10.0], [-10.0, -5.0, 0.0, 5.0, 10.0],
                             [-6.0, -3.0, 0.0, 3.0, 6.0], indexing="ij")
    poses = np.column_stack([TRUTH.x + dx.ravel(), TRUTH.y + dy.ravel(),
                             np.radians(TRUTH.heading_deg + dh.ravel())])
    ll = scan_log_likelihood(FIELD, poses, _scan())
    best = poses[int(np.argmax(ll))]
    assert best[0] == TRUTH.x and best[1] == TRUTH.y
    assert math.degrees(best[2]) == pytest.approx(TRUTH.heading_deg)


def test_a_scan_without_usable_hits_tells_nothing() -> None:
    """No return at all (ranges 0): every particle gets the same (zero) log-likelihood."""
    pts = hits_to_points(ANGLES, np.zeros_like(ANGLES))
    assert pts.shape == (0, 2)
    assert scan_log_likelihood(FIELD, np.zeros((4, 3)), pts).tolist() == [0.0] * 4


def test_bad_scan_arrays_are_refused() -> None:
    """Angles and ranges must be 1-D of one length."""
    with pytest.raises(ValueError, match="must be 1-D of one length"):
        hits_to_points(np.zeros(3), np.zeros(4))


def test_the_beams_taken_are_those_evenly_spaced_by_linspace() -> None:
    """At most ``max_beams`` hits, taken where ``np.linspace`` over the scan's indices
    rounds to (the first and last always), for every scan length up to 2,000 hits."""
    from actors.firmware.localisation.scan_likelihood import _beams  # noqa: PLC0415

    for k in range(1, 2000):
        pts = np.arange(2.0 * k).reshape(k, 2)
        for beams in (2, 7, 60):
            want = pts if k <= beams else pts[np.linspace(0, k - 1, beams).round().astype(int)]
            assert np.array_equal(_beams(pts, beams), want)
