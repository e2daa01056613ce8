"""The pose belief: resampling, the published spread and clusters, convergence on a
known pose in a small synthetic room, determinism, and vectorised predict / update."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from actors.firmware.localisation import belief as belief_module
from actors.firmware.localisation import free_space_model
from actors.firmware.localisation.belief import (
    BeliefOptions,
    PoseBelief,
    low_variance_resample,
)
from actors.firmware.localisation.contact_model import contact_log_likelihood
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import free_space_log_likelihood
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion, TreadReport
from actors.firmware.localisation.odometry import advance
from actors.firmware.localisation.scan_likelihood import hits_to_points, scan_log_likelihood
from server.protocol.pose import Pose, compose
from tests.localisation_rooms import cast, room, turn_treads

W = 13.0  # track width [cm]
ROOM = room(300.0, 200.0, (180.0, 60.0, 40.0, 30.0), (40.0, 140.0, 60.0, 20.0))
FIELD = DistanceField.from_grid(ROOM)
ANGLES = np.arange(0.0, 360.0, 1.0)


def test_low_variance_resampling_draws_each_particle_by_its_weight() -> None:
    """Weights 1/2, 1/4, 1/4, 0 of 4 particles: drawn exactly 2, 1, 1, 0 times; for any
    weights each particle is drawn floor(N w) or ceil(N w) times."""
    rng = np.random.default_rng(1)
    idx = low_variance_resample(np.array([0.5, 0.25, 0.25, 0.0]), rng)
    assert np.bincount(idx, minlength=4).tolist() == [2, 1, 1, 0]
    w = rng.random(1000)
    w /= w.sum()
    counts = np.bincount(low_variance_resample(w, rng), minlength=1000)
    assert np.all(counts >= np.floor(1000 * w) - 1e-9)
    assert np.all(counts <= np.ceil(1000 * w) + 1e-9)


def test_the_spread_of_a_gaussian_cloud() -> None:
    """x, y ~ N(0, 10 cm), heading ~ N(30 deg, 4 deg): the 95 % radius is 10 sqrt(-2 ln
    0.05) = 24.5 cm, the 95 % heading deviation 1.96 x 4 = 7.8 deg, the covariance's
    diagonal the variances; one cluster."""
    b = PoseBelief.around(Pose(50.0, -20.0, 30.0), np.random.default_rng(2), sigma_cm=10.0,
                          sigma_deg=4.0, options=BeliefOptions(particles=20000))
    s = b.spread()
    assert s.pose.distance_to(Pose(50.0, -20.0, 30.0)) < 0.5
    assert s.radius95_cm == pytest.approx(10.0 * math.sqrt(-2 * math.log(0.05)), rel=0.03)
    assert s.heading95_deg == pytest.approx(1.96 * 4.0, rel=0.03)
    assert s.covariance[0, 0] == pytest.approx(100.0, rel=0.05)
    assert s.covariance[2, 2] == pytest.approx(math.radians(4.0) ** 2, rel=0.05)
    assert s.ess == pytest.approx(20000.0)
    assert len(s.clusters) == 1 and s.best.weight > 0.95


def test_a_hypothesis_across_180_deg_is_one_cluster() -> None:
    """Headings either side of +-180 deg are neighbours: one cluster, mean near 180."""
    b = PoseBelief.around(Pose(0.0, 0.0, 179.0), np.random.default_rng(3), sigma_cm=2.0,
                          sigma_deg=5.0)
    s = b.spread()
    assert len(s.clusters) == 1
    assert abs(abs(s.best.pose.heading_deg) - 179.0) < 1.5


def test_map_to_odom_is_the_correction_from_odometry_to_the_mean() -> None:
    """compose(map_to_odom(odom), odom) is the belief's mean pose."""
    b = PoseBelief.around(Pose(120.0, 40.0, 75.0), np.random.default_rng(4))
    odom = Pose(30.0, -5.0, 10.0)
    got = compose(b.map_to_odom(odom), odom)
    mean = b.mean_pose()
    assert got.distance_to(mean) < 1e-9
    assert got.heading_deg == pytest.approx(mean.heading_deg)


def test_update_refuses_a_likelihood_of_the_wrong_shape_or_not_finite() -> None:
    """One finite log-likelihood per particle."""
    b = PoseBelief.around(Pose(), np.random.default_rng(5), options=BeliefOptions(particles=10))
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"log_likelihood must be finite of shape \(10,\)"):
        b.update(np.zeros(9), rng)
    with pytest.raises(ValueError, match="log_likelihood must be finite"):
        b.update(np.full(10, -np.inf), rng)
    with pytest.raises(ValueError, match="particles must be an integer"):
        BeliefOptions(particles=0)


# the path: (left, right) tread travel [cm] of each motion, driven in the test room
PATH = [(10.0, 10.0)] * 4 + [turn_treads(45.0, W)] + [(10.0, 10.0)] * 4 \
    + [turn_treads(-90.0, W)] + [(10.0, 10.0)] * 4


def _run_filter(seed: int) -> tuple[PoseBelief, Pose]:
    """Drive PATH from (60, 60) @ 0 with the belief starting 12 cm and 6 deg off (doubt
    15 cm, 8 deg); each motion is counted with encoder noise, then a scan taken at the
    true pose weighs the particles."""
    world = np.random.default_rng(1000 + seed)  # the truth's noise, apart from the filter's
    rng = np.random.default_rng(seed)
    truth = Pose(60.0, 60.0, 0.0)
    noise = MotionNoise()
    belief = PoseBelief.around(Pose(70.0, 53.0, 6.0), rng, sigma_cm=15.0, sigma_deg=8.0,
                               options=BeliefOptions(particles=2000))
    for left, right in PATH:
        truth = advance(truth, left, right, W)
        counted = [d + world.normal(0.0, noise.encoder_sigma * math.sqrt(abs(d)))
                   for d in (left, right)]
        belief.predict(TreadMotion(*counted), W, noise, rng)
        ranges = cast(ROOM, truth, ANGLES) + world.normal(0.0, 0.5, ANGLES.shape)
        belief.update(scan_log_likelihood(FIELD, belief.particles,
                                          hits_to_points(ANGLES, ranges)), rng)
    return belief, truth


def test_the_filter_converges_on_the_true_pose_in_a_small_room() -> None:
    """After 14 motions with a scan each, the belief is within 3 cm and 2 deg of the
    truth, its 95 % radius under 6 cm and covering the error, one hypothesis."""
    belief, truth = _run_filter(7)
    s = belief.spread()
    assert s.pose.distance_to(truth) < 3.0
    assert abs(s.pose.heading_deg - truth.heading_deg) < 2.0
    assert s.pose.distance_to(truth) < s.radius95_cm < 6.0
    assert s.best.weight > 0.95


def test_the_same_seed_gives_the_same_belief() -> None:
    """All randomness comes from the generator passed in: two runs are identical."""
    a, _ = _run_filter(8)
    b, _ = _run_filter(8)
    assert np.array_equal(a.particles, b.particles)
    assert np.array_equal(a.weights, b.weights)


def _localisation_lines(n: int) -> int:
    """Python lines run inside the localisation package for one predict and three
    updates (free space, contact, scan) of an n-particle belief (each update resamples:
    the caller sets ``RESAMPLE_ESS`` to 1)."""
    rng = np.random.default_rng(9)
    b = PoseBelief.around(Pose(60.0, 60.0, 0.0), rng, sigma_cm=10.0,
                          options=BeliefOptions(particles=n))
    pts = hits_to_points(ANGLES, cast(ROOM, Pose(60.0, 60.0, 0.0), ANGLES))
    motion = TreadMotion(6.0, 10.0, driven_left_cm=10.0, left=TreadReport.SHORT)
    package = str(Path(belief_module.__file__).parent)
    free_space_model._body_lattice.cache_clear()  # each count makes the body lattice
    count = 0

    def trace(frame, event, arg):  # noqa: ANN001, ANN202 (sys.settrace's signature)
        nonlocal count
        if frame.f_code.co_filename.startswith(package):
            if event == "line":
                count += 1
            return trace
        return None

    sys.settrace(trace)
    try:
        b.predict(motion, W, MotionNoise(), rng)
        b.update(free_space_log_likelihood(FIELD, b.particles, (20.0, 15.0)), rng)
        b.update(contact_log_likelihood(FIELD, b.particles, (20.0, 15.0)), rng)
        b.update(scan_log_likelihood(FIELD, b.particles, pts), rng)
    finally:
        sys.settrace(None)
    return count


def test_predict_and_update_run_no_python_loop_over_particles(monkeypatch) -> None:
    """The Python lines run for 20 particles and for 5000 are the same: every
    per-particle step is numpy's."""
    monkeypatch.setattr(belief_module, "RESAMPLE_ESS", 1.0)  # every update resamples
    small = _localisation_lines(20)
    assert small > 50  # the tracer saw the package run
    assert _localisation_lines(5000) == small
