"""A window of LIDAR batches de-skewed into one frame by the odometry between its stamps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.drivers.lidar import Scan
from actors.firmware.hardware import HardwareSpec
from actors.firmware.mapping.scan_match import MatchOptions
from actors.firmware.mapping.scan_window import (
    WINDOW_SWEEP_DEG,
    WINDOW_TRAVEL_CM,
    WINDOW_TURN_DEG,
    ScanWindow,
)
from server.protocol.pose import Pose, compose

HEADING_QUANTUM_DEG = HardwareSpec.bench("mapper").heading_quantum_deg
"""The bench rover's dead-reckoned heading quantum (0.5 cm over the 13 cm track) [deg]."""
WALL_X = 150.0  # a straight wall along y at x = 150 cm (odometry frame)


def wall_batch(pose: Pose, first_deg: float, n: int = 60) -> Scan:
    """``n`` samples 1 deg apart from ``first_deg`` (rover frame), taken at ``pose``,
    each the range to the wall x = ``WALL_X`` (0, no return, where the ray misses it)."""
    angles = (first_deg + np.arange(n, dtype=np.float64)) % 360.0
    t = np.radians(angles + pose.heading_deg)
    c = np.cos(t)
    with np.errstate(divide="ignore"):
        r = np.where(c > 0.2, (WALL_X - pose.x) / c, 0.0)
    return Scan(pose, angles.astype(np.float32), r.astype(np.float32))


def turning_window() -> tuple[ScanWindow, list[Pose]]:
    """Four batches taken while the rover turns 0.5 deg and drives 1.5 cm per tick (a
    curve), the rotor sweeping on: each stamp is where the batch was taken. (Map
    Management cuts its windows before a turn of the counted heading, whose quanta
    are coarser than this; a stamp neither on the drive's heading nor a quantum off it
    is de-skewed by its own heading.)"""
    stamps = [Pose(10.0 + 1.5 * k, 5.0, -6.0 + 0.5 * k) for k in range(4)]
    window = ScanWindow(HEADING_QUANTUM_DEG)
    for k, stamp in enumerate(stamps):
        window.add(wall_batch(stamp, -40.0 + 20.0 * k, n=20))
    return window, stamps


def test_a_window_taken_while_turning_is_deskewed_onto_one_straight_wall() -> None:
    """The batches of a turning rover, each brought into the last batch's frame by the
    odometry between the stamps, put the wall's hits on one line (within float
    rounding); read as if all were taken at the last stamp, they spread over cm."""
    window, stamps = turning_window()
    pts = window.local_points(MatchOptions())
    assert len(pts) == 80
    last = stamps[-1]
    xs = np.array([last.to_parent(float(x), float(y))[0] for x, y in pts])
    assert np.abs(xs - WALL_X).max() < 1e-3
    # not de-skewed: every batch's beams from the last stamp
    skewed = [last.to_parent(r * math.cos(math.radians(a)), r * math.sin(math.radians(a)))[0]
              for s in window.scans for a, r in zip(s.angles_deg.tolist(), s.ranges_cm.tolist(),
                                                    strict=True) if r > 0]
    assert np.abs(np.array(skewed) - WALL_X).max() > 4.0


def test_each_beam_of_a_placed_window_starts_at_its_own_batch_pose() -> None:
    """Placed at a map-frame pose, the window's last batch lies there and every other
    batch where the odometry between the stamps puts it."""
    window, stamps = turning_window()
    placed = Pose(300.0, -20.0, 75.0)
    origins = window.beam_poses(placed)
    assert origins.shape == (3, 80)
    first = compose(placed, compose(Pose(*_inverse_xy(stamps[-1])), stamps[0]))
    np.testing.assert_allclose(origins[:, 0], [first.x, first.y, first.heading_deg], atol=1e-9)
    np.testing.assert_allclose(origins[:, -1], [placed.x, placed.y, placed.heading_deg],
                               atol=1e-9)
    assert window.sizes() == [20, 20, 20, 20]


def _inverse_xy(p: Pose) -> tuple[float, float, float]:
    """``inverse(p)`` as a tuple (written out, so the test does not use what it checks)."""
    c, s = math.cos(p.heading_rad), math.sin(p.heading_rad)
    return -(c * p.x + s * p.y), -(-s * p.x + c * p.y), -p.heading_deg


@pytest.mark.parametrize("budget", ["sweep", "travel"])
def test_a_window_is_full_at_a_revolution_or_its_travel_budget(budget) -> None:
    """A window is full once its batches swept a revolution, or the odometry counted its
    travel budget within it; before that it is not."""
    window = ScanWindow(HEADING_QUANTUM_DEG)
    step = {"sweep": Pose(), "travel": Pose(WINDOW_TRAVEL_CM / 2.5, 0.0, 0.0)}[budget]
    pose = Pose()
    k = 0
    while not window.full():
        window.add(wall_batch(pose, 30.0 * k, n=30))
        pose = compose(pose, step)
        k += 1
    expected = {"sweep": math.ceil(WINDOW_SWEEP_DEG / 30.0), "travel": 4}[budget]
    assert len(window) == expected
    assert window.moved == (budget != "sweep")


def test_a_batch_whose_stamp_turned_starts_a_new_window() -> None:
    """Batches driving straight on share a window; a stamp two quanta of the
    dead-reckoned heading off the drive's (2.2 deg each: one encoder interrupt of one
    tread), or one quantum off with the position still (a turn in place), does not join
    it."""
    window = ScanWindow(HEADING_QUANTUM_DEG)
    window.add(wall_batch(Pose(), 0.0))
    straight = wall_batch(Pose(1.0, 0.0, 0.1), 60.0)  # (within the stamps' rounding)
    assert window.fits(straight)
    window.add(straight)
    assert not window.fits(wall_batch(Pose(2.0, 0.0, 2 * HEADING_QUANTUM_DEG), 120.0))
    assert not window.fits(wall_batch(Pose(1.0, 0.0, HEADING_QUANTUM_DEG), 120.0))
    assert not window.fits(wall_batch(Pose(1.0, 0.0, -HEADING_QUANTUM_DEG), 120.0))
    assert WINDOW_TURN_DEG < HEADING_QUANTUM_DEG / 2


def flicker_drive() -> tuple[ScanWindow, list[Pose], list[Pose]]:
    """A straight drive along x at -6 deg, 1 cm per tick, whose stamps' heading flickers
    a quantum either side of the drive's (one tread's interrupt before the other's) while
    the rover's does not move: (the window, the true poses, the stamps)."""
    q = HEADING_QUANTUM_DEG
    flicker = [0.0, q, 0.0, -q]
    truths = [Pose(10.0 + k, 5.0, -6.0) for k in range(4)]
    stamps = [Pose(p.x, p.y, p.heading_deg + f) for p, f in zip(truths, flicker, strict=True)]
    window = ScanWindow(HEADING_QUANTUM_DEG)
    for k, (truth, stamp) in enumerate(zip(truths, stamps, strict=True)):
        batch = wall_batch(truth, -40.0 + 20.0 * k, n=20)
        assert window.fits(Scan(stamp, batch.angles_deg, batch.ranges_cm))
        window.add(Scan(stamp, batch.angles_deg, batch.ranges_cm))
    return window, truths, stamps


def test_a_straight_drives_heading_flicker_does_not_cut_a_window() -> None:
    """Stamps a quantum off the drive's heading, reached while the position advanced (or
    coming back to it), join the window."""
    window, _, _ = flicker_drive()
    assert len(window) == 4
    assert window.moved


def test_a_flickering_window_is_deskewed_by_the_drives_heading() -> None:
    """A flickering drive's batches are not rotated against each other: read in the
    window's frame (the last batch's position with the drive's heading) its wall hits lie
    on one line; de-skewed by each stamp's own heading (as if each flicker were a turn)
    they spread over cm."""
    window, truths, stamps = flicker_drive()
    frame = window.frame
    assert (frame.x, frame.y, frame.heading_deg) == (stamps[-1].x, stamps[-1].y,
                                                    stamps[0].heading_deg)
    pts = window.local_points(MatchOptions())
    last = truths[-1]
    xs = np.array([last.to_parent(float(x), float(y))[0] for x, y in pts])
    assert np.abs(xs - WALL_X).max() < 1e-3
    by_stamp = ScanWindow(quantum_deg=90.0)  # no stamp is a flicker: each its own heading
    for s in window.scans:
        by_stamp.add(s)
    pts = by_stamp.local_points(MatchOptions())
    xs = np.array([last.to_parent(float(x), float(y))[0] for x, y in pts])
    assert np.abs(xs - WALL_X).max() > 2.0
