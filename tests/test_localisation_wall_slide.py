"""The map-constrained motion: a body driven at a slant into a wall slides along it by
what the encoders counted; a square push and free motion are left to the motion model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.belief import PoseBelief
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import inside_obstacle
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion
from actors.firmware.localisation.wall_slide import slide_along_walls
from tests.localisation_rooms import room

BODY = (20.0, 15.0)  # the rover's body: length, width [cm]
W = 13.0  # track width [cm]
# a 200 x 100 cm room with a wall across it at x 100..105 (its face at x = 100)
FIELD = DistanceField.from_grid(room(200.0, 100.0, (100.0, 0.0, 5.0, 100.0)))


def _straight(x: float, y: float, heading_deg: float, travel_cm: float) -> np.ndarray:
    """The pose ``travel_cm`` straight on from (x, y, heading): what the motion model
    makes of equal tread counts (noise aside)."""
    h = math.radians(heading_deg)
    return np.array([[x + travel_cm * math.cos(h), y + travel_cm * math.sin(h), h]])


def test_a_body_driven_at_a_slant_into_a_wall_slides_along_it_by_the_counted_travel() -> None:
    """12 cm counted at -30 deg toward the face: about 5 cm to the face, then a slide down
    it whose share along the heading (half its length) is the other 7 cm."""
    before = np.array([[86.0, 50.0, math.radians(-30.0)]])
    after = _straight(86.0, 50.0, -30.0, 12.0)
    assert inside_obstacle(FIELD, after, BODY)[0]
    slid, _ = slide_along_walls(FIELD, before, after, BODY)
    x, y, h = slid[0]
    assert not inside_obstacle(FIELD, slid, BODY)[0]
    assert h == pytest.approx(math.radians(-30.0))
    assert 89.0 < x < 93.0  # stopped against the face, not through it
    assert 50.0 - y > 14.0  # far further down than the 6 cm of the straight motion
    counted = (x - 86.0) * math.cos(h) + (y - 50.0) * math.sin(h)
    assert counted == pytest.approx(12.0, abs=0.5)  # the slide explains the counts


def test_a_square_push_into_a_wall_is_left_to_the_free_space_model() -> None:
    """Square to the face no slide explains counted travel: the particle stays inside
    the wall, where free space weighs it down."""
    before = np.array([[86.0, 50.0, 0.0]])
    after = _straight(86.0, 50.0, 0.0, 12.0)
    slid, _ = slide_along_walls(FIELD, before, after, BODY)
    assert np.array_equal(slid, after)
    assert inside_obstacle(FIELD, slid, BODY)[0]


def test_a_motion_in_free_space_is_the_motion_model_s() -> None:
    before = np.array([[40.0, 50.0, 0.3], [60.0, 30.0, -0.5]])
    after = before + np.array([[10.0, 3.0, 0.1], [5.0, -2.0, 0.0]])
    slid, inside = slide_along_walls(FIELD, before, after, BODY)
    assert slid is after
    assert not inside.any()


def test_a_backward_motion_slides_with_its_rear_edge_leading() -> None:
    """Reversing at a slant into the face slides along it as well."""
    before = np.array([[86.0, 50.0, math.radians(150.0)]])  # rear toward the wall, slanted
    after = _straight(86.0, 50.0, 150.0, -12.0)
    assert inside_obstacle(FIELD, after, BODY)[0]
    slid, _ = slide_along_walls(FIELD, before, after, BODY)
    assert not inside_obstacle(FIELD, slid, BODY)[0]
    assert 50.0 - slid[0, 1] > 14.0


def test_the_belief_keeps_the_particles_that_slid_down_a_wall() -> None:
    """A cloud straddling the face, driven at a slant into it: with the map's constraint
    the particles that met the wall end on free ground beside it instead of in it."""
    rng = np.random.default_rng(3)
    start = np.column_stack([rng.uniform(84.0, 88.0, 200), rng.uniform(40.0, 60.0, 200),
                             np.full(200, math.radians(-30.0))])
    motion = TreadMotion(12.0, 12.0)
    quiet = MotionNoise(encoder_sigma=0.0, turn_sigma=0.0)
    plain, walled = PoseBelief(start), PoseBelief(start)
    plain.predict(motion, W, quiet, np.random.default_rng(1))
    walled.predict(motion, W, quiet, np.random.default_rng(1),
                   lambda b, a: slide_along_walls(FIELD, b, a, BODY)[0])
    assert inside_obstacle(FIELD, plain.particles, BODY).mean() > 0.5
    assert not inside_obstacle(FIELD, walled.particles, BODY).any()


def test_the_slide_tells_which_poses_it_returns_still_overlap_a_wall() -> None:
    """The mask given with the poses is the free-space model's for those poses: the
    square push still inside, the slanted one slid out, the free one free."""
    before = np.array([[86.0, 50.0, 0.0], [86.0, 50.0, math.radians(-30.0)], [40.0, 50.0, 0.0]])
    after = np.vstack([_straight(86.0, 50.0, 0.0, 12.0), _straight(86.0, 50.0, -30.0, 12.0),
                       _straight(40.0, 50.0, 0.0, 12.0)])
    slid, inside = slide_along_walls(FIELD, before, after, BODY)
    assert inside.tolist() == [True, False, False]
    assert np.array_equal(inside, inside_obstacle(FIELD, slid, BODY))
