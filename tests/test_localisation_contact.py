"""The contact and free-space models, alone and in the belief: a contact at a gap's
corner keeps both explanations, and a later contact resolves them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from actors.firmware.localisation.belief import BeliefOptions, PoseBelief
from actors.firmware.localisation.contact_model import (
    contact_gap_cm,
    contact_log_likelihood,
    edge_points,
)
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.free_space_model import (
    body_points,
    free_space_log_likelihood,
    inside_obstacle,
    to_map,
)
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion
from actors.firmware.mapping.occupancy import OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose
from tests.localisation_rooms import room, turn_treads

W = 13.0  # track width [cm]
BODY = (20.0, 15.0)  # the rover's body: length, width [cm]
# a 200 x 100 cm room split by a wall at x 100..105 with a 30 cm gap at y 35..65
GAP_ROOM = room(200.0, 100.0, (100.0, 0.0, 5.0, 35.0), (100.0, 65.0, 5.0, 35.0))
FIELD = DistanceField.from_grid(GAP_ROOM)


def _particles(*poses: tuple[float, float, float]) -> np.ndarray:
    return np.array([(x, y, math.radians(h)) for x, y, h in poses])


def test_the_distance_field_reads_the_distance_to_the_nearest_wall() -> None:
    """Cell-centre distances, bilinear between centres; the cap off the map."""
    assert FIELD.at(np.array([52.5]), np.array([52.5]))[0] == pytest.approx(45.0)
    assert FIELD.at(np.array([90.0]), np.array([20.0]))[0] == pytest.approx(12.5)
    assert FIELD.at(np.array([-50.0]), np.array([20.0]))[0] == FIELD.max_dist_cm
    assert FIELD.occupied_at(np.array([102.0, 90.0]), np.array([10.0, 10.0])).tolist() == [
        True, False]


def test_a_field_built_on_the_known_window_reads_as_the_whole_grid_would() -> None:
    """A map mostly unknown (a mapper's early grid) keeps only its known part and the
    cap round it; distance, occupancy and knowledge read the same everywhere."""
    cells = np.full((160, 200), UNKNOWN, np.int8)
    h, w = GAP_ROOM.cells.shape
    cells[60:60 + h, 80:80 + w] = GAP_ROOM.cells
    grid = GridMap(cells, GAP_ROOM.resolution_cm, (-300.0, -200.0))
    window = DistanceField.from_grid(grid)
    assert window.distance_cm.size < grid.cells.size / 4
    occupied = grid.cells == OCCUPIED
    whole = np.minimum(distance_transform_edt(~occupied, sampling=grid.resolution_cm), 50.0)
    rng = np.random.default_rng(3)
    x = rng.uniform(-320.0, 720.0, 5000)
    y = rng.uniform(-220.0, 620.0, 5000)
    c = np.floor((x + 300.0) / grid.resolution_cm).astype(int)
    r = np.floor((y + 200.0) / grid.resolution_cm).astype(int)
    on = (r >= 0) & (r < 160) & (c >= 0) & (c < 200)
    rc, cc = np.clip(r, 0, 159), np.clip(c, 0, 199)
    assert window.occupied_at(x, y).tolist() == (on & occupied[rc, cc]).tolist()
    assert window.known_at(x, y).tolist() == (on & (grid.cells[rc, cc] != UNKNOWN)).tolist()
    near = window.at(x, y) < 50.0
    assert near.any()
    gx = (x[near] + 300.0) / grid.resolution_cm - 0.5
    gy = (y[near] + 200.0) / grid.resolution_cm - 0.5
    c0, r0 = np.floor(gx).astype(int), np.floor(gy).astype(int)
    fx, fy = gx - c0, gy - r0
    expected = ((1 - fx) * (1 - fy) * whole[r0, c0] + fx * (1 - fy) * whole[r0, c0 + 1]
                + (1 - fx) * fy * whole[r0 + 1, c0] + fx * fy * whole[r0 + 1, c0 + 1])
    assert window.at(x[near], y[near]) == pytest.approx(expected, abs=1e-9)


def test_a_body_overlapping_a_wall_is_unlikely_and_unknown_ground_is_not() -> None:
    """Inside the wall: log(1e-3); free or unknown ground: 0."""
    p = _particles((90.0, 20.0, 0.0), (101.0, 20.0, 0.0), (50.0, 50.0, 90.0))
    assert inside_obstacle(FIELD, p, BODY).tolist() == [False, True, False]
    ll = free_space_log_likelihood(FIELD, p, BODY)
    assert ll[0] == 0.0 and ll[1] == pytest.approx(math.log(1e-3))
    half_known = DistanceField.from_grid(room(200.0, 100.0, unknown_beyond_x=100.0))
    assert free_space_log_likelihood(half_known, _particles((150.0, 50.0, 0.0)), BODY)[0] == 0.0


def test_a_body_inside_an_obstacle_is_found_as_by_looking_up_every_body_point() -> None:
    """Only the particles near an obstacle have their body points looked up: the same
    answer as looking up every point of every particle, near walls, in the gap, far from
    them and off the map, for bodies of several sizes."""
    rng = np.random.default_rng(9)
    fields = (FIELD, DistanceField.from_grid(room(200.0, 100.0, unknown_beyond_x=150.0)))
    for field in fields:
        for body in (BODY, (12.0, 9.0), (40.0, 30.0), (11.0, 11.0)):
            p = np.column_stack([rng.uniform(-30.0, 230.0, 3000),
                                 rng.uniform(-30.0, 130.0, 3000),
                                 rng.uniform(-math.pi, math.pi, 3000)])
            res = field.resolution_cm
            x, y = to_map(p, body_points(*body, res, 0.5 * res))
            every = field.occupied_at(x, y).any(axis=1)
            assert 0 < every.sum() < every.size
            assert inside_obstacle(field, p, body).tolist() == every.tolist()


def test_a_body_up_to_a_cell_past_a_mapped_face_is_not_inside_the_wall() -> None:
    """A mapped face lies up to a cell (5 cm) in front of the wall's face, so a rover
    touching the wall overlaps the wall's cells by up to a cell: its front edge 4 cm past
    the face (x 100, or the top wall's y 95) is free ground, 6 cm past it is inside."""
    p = _particles((94.0, 20.0, 0.0), (96.0, 20.0, 0.0), (20.0, 89.0, 90.0))
    assert inside_obstacle(FIELD, p, BODY).tolist() == [False, True, False]


def test_the_gap_is_zero_for_a_body_touching_a_face_and_grows_with_distance() -> None:
    """Front edge on the wall's face (x 100): 0; 10 cm short: 10 cm; backward: the rear."""
    gaps = contact_gap_cm(FIELD, _particles((90.0, 25.0, 0.0), (80.0, 25.0, 0.0)), BODY)
    assert gaps[0] == pytest.approx(0.0, abs=0.3)
    assert gaps[1] == pytest.approx(10.0, abs=0.3)
    back = contact_gap_cm(FIELD, _particles((115.0, 25.0, 0.0)), BODY, direction=-1)
    assert back[0] == pytest.approx(0.0, abs=0.3)
    assert edge_points(20.0, 15.0, 1, 1, 2.5)[:, 1].min() == 0.0


def test_edge_points_refuse_a_bad_direction_or_side() -> None:
    """Direction is +1 / -1, side -1 / 0 / +1."""
    with pytest.raises(ValueError, match="direction must be 1 or -1, got 0"):
        edge_points(20.0, 15.0, 0, 0, 2.5)
    with pytest.raises(ValueError, match="side must be -1, 0 or 1, got 2"):
        edge_points(20.0, 15.0, 1, 2, 2.5)


def _believed_in_the_gap(seed: int) -> tuple[PoseBelief, np.random.Generator]:
    """The rover believes it stands before the gap's middle, sideways doubt 10 cm."""
    rng = np.random.default_rng(seed)
    o = BeliefOptions(particles=2000)
    d = rng.standard_normal((o.particles, 3))
    p = np.column_stack([90.0 + 4.0 * d[:, 0], 50.0 + 10.0 * d[:, 1],
                         np.radians(2.0) * d[:, 2]])
    return PoseBelief(p, None, o), rng


def test_a_contact_at_a_corner_keeps_two_hypotheses() -> None:
    """Blocked moving forward at the gap's mouth: the right front corner on the lower
    wall's end or the left front corner on the upper wall's end explain it alike; the
    belief keeps both (two clusters), the particles in the gap's middle lose."""
    belief, rng = _believed_in_the_gap(11)
    belief.update(contact_log_likelihood(FIELD, belief.particles, BODY, direction=1), rng)
    spread = belief.spread()
    heavy = [c for c in spread.clusters if c.weight > 0.25]
    assert len(heavy) == 2
    below, above = sorted(heavy, key=lambda c: c.pose.y)
    assert below.pose.y < 42.0 and above.pose.y > 58.0
    assert below.pose.x == pytest.approx(90.0, abs=3.0)
    assert above.pose.x == pytest.approx(90.0, abs=3.0)
    # the mean lies between them, and the published radius says so
    assert spread.radius95_cm > 12.0


def test_a_later_contact_resolves_the_two_hypotheses() -> None:
    """After the corner contact (truth: right corner on the lower wall, y 38) the rover
    backs off 10 cm, turns left 90 deg and drives 47 cm until the room's top wall stops
    it. Only the lower hypothesis meets that wall there: one cluster is left, at the
    true pose."""
    belief, rng = _believed_in_the_gap(12)
    noise = MotionNoise()
    belief.update(contact_log_likelihood(FIELD, belief.particles, BODY, direction=1), rng)
    assert len([c for c in belief.spread().clusters if c.weight > 0.25]) == 2
    belief.predict(TreadMotion(-10.0, -10.0), W, noise, rng)
    belief.predict(TreadMotion(*turn_treads(90.0, W)), W, noise, rng)
    belief.predict(TreadMotion(47.0, 47.0), W, noise, rng)
    belief.update(contact_log_likelihood(FIELD, belief.particles, BODY, direction=1), rng)
    spread = belief.spread()
    assert spread.best.weight > 0.9
    truth = Pose(80.0, 85.0, 90.0)
    assert spread.best.pose.distance_to(truth) < 4.0
    assert spread.best.pose.heading_deg == pytest.approx(90.0, abs=4.0)


def test_the_stalled_side_weighs_the_hypotheses_touching_with_it() -> None:
    """Told that the right side stalled, the lower hypothesis (right corner on the lower
    wall's end) gains weight over the upper one."""
    weights = []
    for side in (0, -1):
        belief, rng = _believed_in_the_gap(13)
        belief.update(contact_log_likelihood(FIELD, belief.particles, BODY, 1, side), rng)
        below = sum(c.weight for c in belief.spread().clusters if c.pose.y < 50.0)
        weights.append(below)
    assert weights[1] > weights[0] + 0.15
