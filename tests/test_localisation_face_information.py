"""What a matched scan tells the mapper's belief (`face_information`), against a map the
occupancy grid drew from noisy scans, as Map Management's is."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.face_information import face_information
from actors.firmware.localisation.gaussian_pose import GaussianPose
from actors.firmware.localisation.scan_likelihood import hits_to_points
from actors.firmware.mapping.occupancy import OccupancyGrid
from server.protocol.pose import Pose

from .test_scan_match import ray_scan, room_map

RANGE_SIGMA_CM = 1.0  # the scans' range noise [cm]
MAPPED_FROM = [Pose(80.0, 50.0, 0.0), Pose(150.0, 150.0, 90.0), Pose(230.0, 60.0, 200.0),
               Pose(60.0, 160.0, 300.0), Pose(170.0, 170.0, 45.0), Pose(120.0, 40.0, 135.0)]
"""Where the rover stood while the grid was drawn (free space of `room_map`)."""
SEEN_FROM = [Pose(120.0, 80.0, 20.0), Pose(90.0, 140.0, -60.0), Pose(240.0, 150.0, 170.0),
             Pose(180.0, 50.0, 95.0)]


def _noisy_scan(pose: Pose, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    a, r = ray_scan(room_map(), pose, 360)
    return a, np.where(r > 0, r + rng.normal(0.0, RANGE_SIGMA_CM, r.shape), 0.0)


@pytest.fixture(scope="module")
def mapped() -> DistanceField:
    """The distance field of a grid drawn from noisy scans (walls a band, not a line)."""
    rng = np.random.default_rng(5)
    grid = OccupancyGrid(800.0, 800.0, 5.0)
    for pose in MAPPED_FROM:
        for _ in range(3):
            grid.integrate(pose, *_noisy_scan(pose, rng))
    return DistanceField.from_grid(grid.snapshot())


@pytest.mark.parametrize("truth", SEEN_FROM, ids=str)
def test_a_scan_against_a_drawn_map_pins_the_heading_and_the_position(
        mapped: DistanceField, truth: Pose) -> None:
    """Every direction is pinned, the heading by the hits' lever: counted as ten
    measurements, the scan puts the heading within 2 deg and the position within 2 cm (one
    standard deviation; a hit's spread round its face is 3 cm), in no direction nowhere."""
    pts = hits_to_points(*_noisy_scan(truth, np.random.default_rng(9)))
    info = face_information(mapped, truth, pts)
    assert np.linalg.eigvalsh(info)[0] > 0.0
    cov = np.linalg.inv(info)
    assert math.degrees(math.sqrt(cov[2, 2])) < 2.0
    assert math.sqrt(cov[0, 0]) < 2.0 and math.sqrt(cov[1, 1]) < 2.0


def test_a_corridor_scan_says_nothing_along_the_corridor(mapped: DistanceField) -> None:
    """Only the beams that meet the long walls: the information along them is nil, so the
    update keeps that doubt and takes the doubt across them away."""
    truth = Pose(120.0, 80.0, 0.0)
    a, r = _noisy_scan(truth, np.random.default_rng(2))
    side = np.abs(np.sin(np.radians(a))) > 0.9
    info = face_information(mapped, truth, hits_to_points(a[side], r[side]))
    along = np.array([1.0, 0.0, 0.0])
    across = np.array([0.0, 1.0, 0.0])
    assert along @ info @ along < 0.02 * (across @ info @ across)
    wide = GaussianPose.at(truth, 20.0, 10.0)
    after = wide.update(truth, info)
    assert after.covariance[0, 0] == pytest.approx(wide.covariance[0, 0], rel=0.1)
    assert after.covariance[1, 1] < 0.1 * wide.covariance[1, 1]


def test_hits_the_map_does_not_explain_add_nothing(mapped: DistanceField) -> None:
    """Hits far from every mapped face (another rover, a box the map lacks) or on new ground
    barely change what the scan says: they have no face to be pinned to."""
    truth = Pose(120.0, 80.0, 20.0)
    a, r = _noisy_scan(truth, np.random.default_rng(4))
    pts = hits_to_points(a, r)
    strays = np.array([[40.0, 12.0], [35.0, -20.0], [60.0, 30.0], [900.0, 0.0], [0.0, 950.0]])
    with_strays = np.vstack([pts[::8], strays])
    info = face_information(mapped, truth, pts[::8])
    noisy = face_information(mapped, truth, with_strays)
    # the same hits are scaled to the same ten measurements over a few more beams
    scale = len(pts[::8]) / len(with_strays)
    assert np.allclose(noisy, info * scale, rtol=0.05, atol=1e-6)


def test_too_few_hits_say_nothing(mapped: DistanceField) -> None:
    """Under scan matching's least number of hits the information is zero."""
    pts = np.array([[100.0, 0.0], [0.0, 80.0], [-90.0, 0.0]])
    assert not face_information(mapped, Pose(120.0, 80.0, 0.0), pts).any()
