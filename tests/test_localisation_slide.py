"""The slide model: a body the motion carried into a face at a slant slides along it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.contact_model import contact_gap_cm
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import inside_obstacle
from actors.firmware.localisation.slide_model import slide_along_faces
from tests.localisation_rooms import room

BODY = (20.0, 15.0)  # length, width [cm]
FIELD = DistanceField.from_grid(room(200.0, 100.0))  # the top wall's cells: y 95..100
SHARE = 0.5  # both treads reported short under half their driven travel


def _moved(x: float, y: float, heading_deg: float, counted_cm: float) -> tuple[np.ndarray,
                                                                              np.ndarray]:
    h = math.radians(heading_deg)
    before = np.array([[x, y, h]])
    after = np.array([[x + counted_cm * math.cos(h), y + counted_cm * math.sin(h), h]])
    return before, after


def _counted(before: np.ndarray, after: np.ndarray) -> float:
    """The motion's part along the heading: what the encoders count."""
    h = after[0, 2]
    return float((after[0, 0] - before[0, 0]) * math.cos(h)
                 + (after[0, 1] - before[0, 1]) * math.sin(h))


def test_a_body_driven_into_a_wall_at_a_slant_slides_along_it() -> None:
    """Heading 30 deg into the top wall, 17.4 cm counted: the body goes on until its front
    edge meets the wall, then along the wall, and ends touching it; the slide's part along
    the heading is still the 17.4 cm counted."""
    before, after = _moved(60.0, 82.0, 30.0, 17.4)
    assert inside_obstacle(FIELD, after, BODY)[0]
    slid = slide_along_faces(FIELD, before, after, BODY, SHARE)
    assert contact_gap_cm(FIELD, slid, BODY, 1, 0)[0] == pytest.approx(0.0, abs=0.3)
    assert _counted(before, slid) == pytest.approx(17.4, abs=0.05)
    assert slid[0, 1] < after[0, 1] and slid[0, 0] > after[0, 0]  # along the wall, not in
    assert slid[0, 2] == after[0, 2]


def test_a_wall_met_too_steeply_for_a_slide_leaves_the_particle_to_free_space() -> None:
    """At 70 deg a slide would count cos(70)**2 = 0.12 of the drive: Motor Control would have
    reported both treads short, so this motion was no slide."""
    before, after = _moved(60.0, 82.0, 70.0, 17.4)
    assert inside_obstacle(FIELD, after, BODY)[0]
    assert np.array_equal(slide_along_faces(FIELD, before, after, BODY, SHARE), after)


def test_particles_clear_of_the_walls_or_inside_before_do_not_slide() -> None:
    """Only a motion that entered an obstacle slides: one that stayed clear, and one that
    started inside already (the free-space model's to judge), are as the motion left them."""
    clear = _moved(60.0, 50.0, 30.0, 17.4)
    inside = _moved(60.0, 95.0, 0.0, 10.0)
    before = np.vstack([clear[0], inside[0]])
    after = np.vstack([clear[1], inside[1]])
    assert np.array_equal(slide_along_faces(FIELD, before, after, BODY, SHARE), after)


def test_a_backward_slide_goes_back_along_the_face() -> None:
    """Reversing at a slant into the bottom wall (its cells y 0..5): the rear edge meets the
    wall and the body slides the other way along it, ending against it."""
    before, after = _moved(100.0, 18.0, 30.0, -17.4)
    assert inside_obstacle(FIELD, after, BODY)[0]
    slid = slide_along_faces(FIELD, before, after, BODY, SHARE)
    assert contact_gap_cm(FIELD, slid, BODY, -1, 0)[0] == pytest.approx(0.0, abs=0.3)
    assert _counted(before, slid) == pytest.approx(-17.4, abs=0.05)
    assert slid[0, 1] > after[0, 1] and slid[0, 0] < after[0, 0]
