"""The hider's and seeker's pose belief as navigation keeps it (`nav/localiser.py`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors import BufferPool
from actors.firmware.localisation.belief import PoseBelief
from actors.firmware.localisation.odometry import advance, tread_travel
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.options import NavMemory
from actors.firmware.nav.route import Motion
from server.protocol.pose import Pose
from tests.test_nav_recovery import scraped_nav


@pytest.mark.parametrize("left, right", [(10.0, 10.0), (-6.0, 6.0), (3.0, 12.0), (-8.0, -2.0)])
def test_tread_travel_inverts_the_odometry_step(left: float, right: float) -> None:
    """The tread travel recovered from two poses is the one dead reckoning stepped with."""
    before = Pose(40.0, -20.0, 130.0)
    after = advance(before, left, right, 13.0)
    assert tread_travel(before, after, 13.0) == pytest.approx((left, right), abs=1e-9)


def test_the_same_role_draws_the_same_belief() -> None:
    """Determinism: the belief's generator is seeded from the role, so two incarnations
    that see the same motions hold the same particles; another role draws others."""
    def drive(role: str) -> np.ndarray:
        nav = make_nav(role, pool=BufferPool(4))
        nav.origin, nav.pose, nav.pose_known = Pose(50.0, 50.0, 0.0), Pose(0.0, 0.0, 0.0), True
        nav.localiser.track_belief()
        for k in range(1, 4):
            nav.last_motion = Motion("move", 20.0)
            nav.pose = Pose(20.0 * k, 0.0, 0.0)
            nav.localiser.track_belief()
        return np.array(nav.localiser.belief.particles)
    assert np.array_equal(drive("hider"), drive("hider"))
    assert not np.array_equal(drive("hider"), drive("seeker"))


def test_a_new_origin_starts_a_new_belief_round_it() -> None:
    """The server's origin replaces the belief: a narrow one round the new map pose."""
    nav = scraped_nav(0.0, sigma_cm=12.0)
    assert nav.drift_cm > 20.0
    nav.localiser.forget_belief()
    nav.origin = Pose(0.0, 0.0, 90.0)
    nav.localiser.track_belief()
    p = nav.map_pose
    assert (p.x, p.y, p.heading_deg) == pytest.approx((-100.0, 250.0, 90.0))
    assert nav.drift_cm < 4.0


def _to_the_left_wall(nav, legs: int) -> Pose:
    """Start ``nav`` at the server's origin (map (150, 150) @ 0, its own (0, 0)), drive
    ``legs`` quarter turns and 20 cm legs (the heading doubt grows), then west until
    blocked with the nose on the room's left wall (the contact narrows the belief across
    it); returns the origin."""
    start = Pose(150.0, 150.0, 0.0)  # in the room left of the corridor
    nav.pose = Pose(0.0, 0.0, 0.0)
    nav.set_origin(start)
    nav.localiser.on_server_origin()
    assert nav.drift_cm < 4.0
    for _ in range(legs):
        nav.last_motion = Motion("turn", 90.0)
        nav.pose = Pose(nav.pose.x, nav.pose.y, nav.pose.heading_deg + 90.0)
        nav.localiser.track_belief()
        nav.last_motion = Motion("move", 20.0)
        nav.pose = advance(nav.pose, 20.0, 20.0, 13.0)
        nav.localiser.track_belief()
    nav.last_motion = Motion("turn", 180.0 - nav.pose.heading_deg)
    nav.pose = Pose(nav.pose.x, nav.pose.y, 180.0)
    nav.localiser.track_belief()
    nav.motion_from = nav.map_pose
    nav.last_motion = Motion("move", 200.0)  # toward the left wall: blocked, nose on it
    nav.pose = Pose(10.0 - start.x, nav.pose.y, 180.0)
    nav.localiser.contact_update()
    assert nav.counters["contacts"] == 1
    return start


def test_a_retried_destination_keeps_the_belief_and_never_narrows_it() -> None:
    """The server sends the same ``origin`` with every ``hide``. After a route that
    turned (its doubt grew) and ended against the room's left wall (the contact narrowed
    the belief across it), the same origin again keeps the belief, widened by dead
    reckoning alone (which no contact narrowed): its 95 % radius grows, and the pose
    stays within it of where it was; it does not fall back to the start's 1 cm. A
    different origin is a new placement: a new, narrow belief round it."""
    nav = scraped_nav(0.0)
    start = _to_the_left_wall(nav, 6)
    tried, pose = nav.drift_cm, nav.map_pose
    assert tried > 4.0 and pose.x == pytest.approx(10.0, abs=3.0)
    nav.set_origin(start)  # what the base does with the frame, before the hook
    nav.localiser.on_server_origin()
    assert nav.drift_cm > tried
    assert math.dist((nav.map_pose.x, nav.map_pose.y), (pose.x, pose.y)) <= nav.drift_cm
    assert nav.counters["retry_widened"] == 1
    nav.set_origin(Pose(60.0, 40.0, 0.0))
    nav.localiser.on_server_origin()
    assert nav.drift_cm < 4.0


def test_a_restarted_navigation_goes_on_from_its_belief_and_its_given_origin() -> None:
    """A navigation restarted after a contact corrected and widened its belief takes the
    belief up from the retained `NavMemory` (same pose, same doubt) and moves it by what
    Motor Control counted meanwhile; the retried destination's ``origin`` that follows
    is known as the one it was given (the belief widened, not put back on dead
    reckoning from the start with the start's 1 cm)."""
    memory = NavMemory()
    nav = scraped_nav(0.0, memory=memory)
    start = _to_the_left_wall(nav, 3)
    learned, doubt = nav.map_pose, nav.drift_cm
    assert doubt > 4.0

    again = make_nav("hider", pool=BufferPool(4), memory=memory)  # the new incarnation
    again.map = again.work_map = nav.map
    again.origin = Pose(*memory.origin)  # as `NavBase.on_start` takes it
    again.pose, again.pose_known = nav.pose, True
    p = again.map_pose
    assert (p.x, p.y, p.heading_deg) == pytest.approx((learned.x, learned.y, learned.heading_deg))
    assert again.drift_cm == pytest.approx(doubt)
    again.last_motion = Motion("move", -6.0)  # driven while it restarted
    again.pose = advance(again.pose, -6.0, -6.0, 13.0)
    again.localiser.track_belief()
    assert again.map_pose.x == pytest.approx(learned.x + 6.0, abs=1.0)
    before = again.drift_cm
    again.set_origin(start)
    again.localiser.on_server_origin()
    assert again.counters["retry_widened"] == 1
    assert again.drift_cm > before
    assert math.dist((again.map_pose.x, again.map_pose.y),
                     (learned.x + 6.0, learned.y)) <= again.drift_cm


def test_the_pose_follows_the_heaviest_hypothesis_once_free_space_splits_the_belief() -> None:
    """Three groups of particles, one of them inside a box of the map, that no one has
    asked the spread of (the belief was counted as one hypothesis). A motion and its
    free-space weighing cut the group in the box: the pose is then the heavier of the
    two that remain, not their mean between them, though nothing read the spread."""
    nav = scraped_nav(0.0)
    n = 600
    rng = np.random.default_rng(7)
    centres = np.repeat(np.array([[100.0, 80.0, 0.0], [100.0, 220.0, 0.0],
                                  [350.0, 60.0, 0.0]]), n // 3, axis=0)
    particles = centres + rng.normal(0.0, [2.0, 2.0, 0.02], size=(n, 3))
    weights = np.repeat(np.array([0.4, 0.3, 0.3]) / (n // 3), n // 3)
    nav.localiser.adopt(PoseBelief(particles, weights))
    nav.last_motion = Motion("move", 2.0)
    nav.pose = advance(nav.pose, 2.0, 2.0, 13.0)
    nav.localiser.track_belief()
    p = nav.map_pose
    assert (p.x, p.y) == pytest.approx((102.0, 80.0), abs=3.0)
    assert len(nav.spread.clusters) == 2
