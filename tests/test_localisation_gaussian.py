"""The mapper's Gaussian pose belief in isolation: prediction by the tread motion model,
the relayed travel of a reported tread, and the update (the scan's information is
`tests/test_localisation_face_information.py`'s)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.gaussian_pose import GaussianPose
from actors.firmware.localisation.motion_model import (
    MotionNoise,
    TreadMotion,
    TreadReport,
    sample_motion,
)
from actors.firmware.nav.route import Motion
from actors.firmware.nav.sensor_watch import SensorWatch, uncounted_travel
from actors.firmware.origin_wire import MM, xy_half
from server.protocol.pose import Pose

W = 13.0
NOISE = MotionNoise()


def _sampled(motion: TreadMotion, n: int = 40000) -> np.ndarray:
    """The motion model's own particles after ``motion`` from the origin."""
    rng = np.random.default_rng(3)
    return sample_motion(np.zeros((n, 3)), motion, W, NOISE, rng)


@pytest.mark.parametrize("motion", [TreadMotion(-10.0, 10.0), TreadMotion(20.0, 20.0)],
                         ids=["turn", "move"])
def test_prediction_matches_the_motion_models_samples(motion) -> None:
    """Healthy, the belief's predicted heading spread is the sampled motion model's
    (within 10 %): the Gaussian is the same model in moments, not a second one."""
    b = GaussianPose.at(Pose()).predict(motion.left_cm, motion.right_cm, W, NOISE)
    p = _sampled(motion)
    assert math.degrees(math.sqrt(b.covariance[2, 2])) == pytest.approx(
        math.degrees(p[:, 2].std()), rel=0.1)
    assert b.mean.heading_deg == pytest.approx(math.degrees(p[:, 2].mean()), abs=0.5)


@pytest.mark.parametrize("motion, uncounted", [
    (TreadMotion(0.0, 3.0, 3.0, None, TreadReport.SILENT), (3.0, 0.0)),
    (TreadMotion(0.0, 0.0, -10.0, 10.0, TreadReport.SILENT, TreadReport.SILENT), (-10.0, 10.0)),
], ids=["left-silent", "both-silent-turn"])
def test_a_reported_treads_gaussian_covers_both_explanations(motion, uncounted) -> None:
    """Reported, the sampled model keeps two explanations (the count right, the drive
    right); one Gaussian cannot, so the mapper's holds the span between them: its mean
    lies between the two modes' headings and its 2-sigma interval reaches both."""
    b = GaussianPose.at(Pose()).predict(motion.left_cm, motion.right_cm, W, NOISE, uncounted)
    heading = np.degrees(_sampled(motion)[:, 2])
    count = math.degrees((motion.right_cm - motion.left_cm) / W)
    drive = math.degrees((motion.right_cm + uncounted[1] - motion.left_cm - uncounted[0]) / W)
    # the fault began in this motion: half the particles as counted, the rest from the
    # count to the drive (the onset anywhere in it)
    assert float(np.mean(np.abs(heading - count) < 1.0)) > 0.4
    sigma = math.degrees(math.sqrt(b.covariance[2, 2]))
    lo, hi = sorted((count, drive))
    assert lo < b.mean.heading_deg < hi
    assert b.mean.heading_deg - 2 * sigma < lo and hi < b.mean.heading_deg + 2 * sigma


def test_a_reported_tread_widens_the_heading_by_its_doubt_not_by_added_degrees() -> None:
    """The same 90 deg turn, healthy and with both treads silent (10 cm each driven unseen):
    healthy, the 95 % heading is the scrub's few degrees; both silent, the mean moves on
    by half the unseen turn and the 95 % heading covers it from none to all."""
    healthy = GaussianPose.at(Pose()).predict(-10.2, 10.2, W, NOISE)
    assert healthy.heading95_deg < 5.0
    blind = GaussianPose.at(Pose()).predict(0.0, 0.0, W, NOISE, (-10.2, 10.2))
    assert blind.mean.heading_deg == pytest.approx(45.0, abs=0.1)
    assert 45.0 < blind.heading95_deg < 60.0


def test_the_belief_widens_with_every_unmatched_motion() -> None:
    """Motion after motion with no update, the doubt only grows: heading with each turn,
    position with each move."""
    b = GaussianPose.at(Pose())
    h, r = [], []
    for _ in range(6):
        b = b.predict(-5.0, 5.0, W, NOISE).predict(30.0, 30.0, W, NOISE)
        h.append(b.heading95_deg)
        r.append(b.radius95_cm)
    assert np.all(np.diff(h) > 0) and np.all(np.diff(r) > 0)


def test_an_update_moves_the_mean_toward_the_measurement_by_the_weights() -> None:
    """Equal doubt before and in the measurement: the mean moves halfway, and the
    covariance halves."""
    b = GaussianPose.at(Pose(0.0, 0.0, 0.0), 2.0, 2.0)
    z = Pose(2.0, -2.0, 2.0)
    after = b.update(z, np.linalg.inv(b.covariance))
    assert (after.mean.x, after.mean.y, after.mean.heading_deg) == pytest.approx(
        (1.0, -1.0, 1.0))
    assert np.allclose(after.covariance, 0.5 * b.covariance)


def test_navigation_relays_the_travel_driven_beyond_the_count() -> None:
    """Each reported tread's travel beyond its count by Motor Control's drive model
    (``NAV_TREAD_DRIVEN``), signed as driven; a tread not reported, or one that counted
    as far as the model, relays nothing."""
    assert uncounted_travel((True, False), (0.0, 3.0), (3.2, 3.2)) == pytest.approx((3.2, 0.0))
    assert uncounted_travel((True, True), (-1.0, 1.0), (-4.5, 4.5)) == pytest.approx(
        (-3.5, 3.5))
    assert uncounted_travel((False, True), (8.0, 4.0), (8.0, 8.5)) == pytest.approx((0.0, 4.5))
    assert uncounted_travel((True, True), (-6.0, -6.0), (-5.0, -14.0)) == pytest.approx(
        (0.0, -8.0))


class _MapperState:
    """The mapper's navigation state `SensorWatch` reads, and what it posts to Map
    Management."""

    def __init__(self, odometry_from: Pose, pose: Pose, motion_from: Pose,
                 map_pose: Pose) -> None:
        self.state, self.moving, self.odometry_faults = "exploring", True, 0
        self.last_motion = Motion("turn", 90.0)
        self.odometry_from, self.pose = odometry_from, pose
        self.motion_from, self.map_pose = motion_from, map_pose
        self.spec, self.map_name = HardwareSpec.bench("mapper"), "mapper/map"
        self.posted: list[tuple[float, float]] = []

    async def stop_motor(self) -> None:
        self.moving = False

    async def status(self, state: str, detail: str) -> None:
        pass

    async def post(self, name: str, message: object) -> bool:
        self.posted.append(xy_half(message, MM))
        return True


def test_the_relayed_travel_is_counted_in_the_own_frame_not_the_map_frame() -> None:
    """Motor Control's counts move its own-frame pose; the map-frame pose also moves by
    Map Management's corrections, which are no tread's travel. Two stuck encoders in a
    turn (nothing counted, the model drove 7.1 cm a tread) relay all of the 7.1 cm,
    whatever the origin did meanwhile."""
    still = Pose(10.0, 20.0, 30.0)
    # meanwhile the correction moved the map-frame pose 3 cm along the heading
    nav = _MapperState(still, still, Pose(40.0, 50.0, 30.0),
                       Pose(40.0 + 3.0 * math.cos(math.radians(30.0)),
                            50.0 + 3.0 * math.sin(math.radians(30.0)), 30.0))
    watch = SensorWatch(nav)  # type: ignore[arg-type]
    trio.run(watch.on_tread_fault, TreadFault.BOTH_SILENT)  # reported in the turn
    trio.run(watch.relay_tread_driven, -7.1, 7.1)
    assert nav.posted == [pytest.approx((-7.1, 7.1))]


def test_whether_the_95_radius_exceeds_a_limit_is_what_the_radius_says() -> None:
    """Answered from the trace when the belief is well inside the limit, else from the
    eigenvalues: the same answer as comparing `radius95_cm`, at limits on both sides of
    the radius and right at it, for round, long and tilted ellipses."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        a = rng.normal(0.0, rng.uniform(0.1, 20.0), (3, 3))
        cov = a @ a.T + np.diag([1e-6, 1e-6, 1e-6])
        belief = GaussianPose(Pose(), cov)
        r = belief.radius95_cm
        for limit in (0.5 * r, 0.97 * r, r, np.nextafter(r, 0.0), 1.001 * r, 1.2 * r, 3.0 * r):
            assert belief.radius95_over(limit) == (r > limit)
