"""The tread motion model: healthy noise, and noise widening on Motor Control's reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from actors.firmware.localisation.motion_model import (
    MotionNoise,
    TreadMotion,
    TreadReport,
    reports_from_value,
    sample_motion,
)
from actors.firmware.localisation.odometry import advance
from server.protocol.pose import Pose

W = 13.0  # track width [cm]
N = 20000
NOISE = MotionNoise()


def _start(n: int = N) -> np.ndarray:
    return np.zeros((n, 3))


def _heading_sd_deg(p: np.ndarray) -> float:
    return float(np.degrees(np.std(p[:, 2])))


def test_a_healthy_motion_is_centred_on_dead_reckoning() -> None:
    """Without reports the particles' mean is the odometry's own step (midpoint rule)."""
    p = sample_motion(_start(), TreadMotion(18.0, 22.0), W, NOISE, np.random.default_rng(1))
    want = advance(Pose(0.0, 0.0, 0.0), 18.0, 22.0, W)
    assert np.mean(p[:, 0]) == pytest.approx(want.x, abs=0.05)
    assert np.mean(p[:, 1]) == pytest.approx(want.y, abs=0.05)
    assert math.degrees(np.mean(p[:, 2])) == pytest.approx(want.heading_deg, abs=0.1)


def test_a_healthy_straight_move_spreads_as_the_encoder_noise_says() -> None:
    """Along the move: var = sigma^2 D / 2 (two treads averaged); heading: sqrt(2 sigma^2 D)/w."""
    d = 100.0
    p = sample_motion(_start(), TreadMotion(d, d), W, NOISE, np.random.default_rng(2))
    s = NOISE.encoder_sigma
    assert np.std(p[:, 0]) == pytest.approx(s * math.sqrt(d / 2), rel=0.05)
    assert _heading_sd_deg(p) == pytest.approx(math.degrees(s * math.sqrt(2 * d) / W), rel=0.05)


def test_the_healthy_spread_does_not_depend_on_how_the_path_is_cut() -> None:
    """One 100 cm step or twenty 5 cm steps: the same heading spread (variance per cm)."""
    rng = np.random.default_rng(3)
    one = sample_motion(_start(), TreadMotion(100.0, 100.0), W, NOISE, rng)
    many = _start()
    for _ in range(20):
        many = sample_motion(many, TreadMotion(5.0, 5.0), W, NOISE, rng)
    assert _heading_sd_deg(many) == pytest.approx(_heading_sd_deg(one), rel=0.05)


def test_heading_noise_widens_on_a_tread_report() -> None:
    """A 20 cm straight move: healthy, left tread counting short (10 of 20 cm), left
    tread silent (0 of 20 cm), each the first motion reported. The heading spread follows
    the tread's doubt: half the particles as counted, half from the count to the drive
    (the fault's onset anywhere in the motion), over the track width; no degrees added."""
    rng = np.random.default_rng(4)
    healthy = sample_motion(_start(), TreadMotion(20.0, 20.0), W, NOISE, rng)
    short = sample_motion(_start(), TreadMotion(10.0, 20.0, driven_left_cm=20.0,
                                                left=TreadReport.SHORT), W, NOISE, rng)
    silent = sample_motion(_start(), TreadMotion(0.0, 20.0, driven_left_cm=20.0,
                                                 left=TreadReport.SILENT), W, NOISE, rng)
    sd = [_heading_sd_deg(p) for p in (healthy, short, silent)]
    assert sd[0] < 1.0 < sd[1] < sd[2]
    # the share of the gap: 0 or U(0, 1), half each: variance 1/6 - 1/16 = 5/48
    assert sd[1] == pytest.approx(math.degrees(10 * math.sqrt(5 / 48) / W), rel=0.15)
    assert sd[2] == pytest.approx(math.degrees(20 * math.sqrt(5 / 48) / W), rel=0.15)
    # the truth of either explanation lies inside: a weak motor (heading as counted,
    # 44 deg left) and a slipping encoder (straight, heading 0)
    counted = math.degrees((20.0 - 10.0) / W)
    for truth in (0.0, counted):
        assert np.any(np.abs(np.degrees(short[:, 2]) - truth) < 2.0)


def test_a_continued_report_keeps_two_narrow_explanations() -> None:
    """The left tread counted short in the motion before too: its fault began before this
    one, so the tread went either as counted (a weak motor) or as driven (a slipping
    encoder, within the drive model's error), not in between: half the particles at
    each."""
    rng = np.random.default_rng(8)
    p = sample_motion(_start(), TreadMotion(10.0, 20.0, driven_left_cm=20.0,
                                            left=TreadReport.SHORT, left_continued=True),
                      W, NOISE, rng)
    heading = np.degrees(p[:, 2])
    counted = math.degrees((20.0 - 10.0) / W)
    as_counted = np.abs(heading - counted) < 4.0  # the scrub: 1.3 deg over 44 deg
    assert float(np.mean(as_counted)) == pytest.approx(0.5, abs=0.05)
    assert float(np.mean(heading[~as_counted])) == pytest.approx(0.0, abs=1.5)


def test_both_treads_short_keep_a_straight_move_straight() -> None:
    """Both treads counting short (value 6) share one draw: the distance is in doubt,
    the heading is not."""
    rng = np.random.default_rng(5)
    left, right = reports_from_value(6)
    both = sample_motion(_start(), TreadMotion(8.0, 8.0, 20.0, 20.0, left, right), W,
                         NOISE, rng)
    assert _heading_sd_deg(both) < 1.5
    assert np.std(both[:, 0]) > 3.0  # uniform over 12 cm: 3.5 cm
    # between what was counted and what was driven (with its 10 % model error)
    assert 7.0 < np.min(both[:, 0]) and np.max(both[:, 0]) < 20.0 * (1 + 5 * 0.1)


def test_both_treads_short_in_a_turn_scale_the_turn() -> None:
    """In a turn, the shared draw scales the whole turn: 45 deg counted of 90 driven
    spreads the heading over 45..90 deg."""
    half = math.radians(45.0) * W / 2
    full = math.radians(90.0) * W / 2
    motion = TreadMotion(-half, half, -full, full, TreadReport.SHORT, TreadReport.SHORT)
    p = sample_motion(_start(), motion, W, NOISE, np.random.default_rng(6))
    h = np.degrees(p[:, 2])
    assert np.percentile(h, 2) > 40.0 and np.percentile(h, 98) < 100.0
    assert np.std(h) == pytest.approx(45.0 / math.sqrt(12), rel=0.2)


@pytest.mark.parametrize(("value", "want"), [
    (0, (TreadReport.SILENT, TreadReport.OK)),
    (1, (TreadReport.OK, TreadReport.SILENT)),
    (2, (TreadReport.SHORT, TreadReport.OK)),
    (3, (TreadReport.OK, TreadReport.SHORT)),
    (4, (TreadReport.SILENT, TreadReport.SILENT)),
    (6, (TreadReport.SHORT, TreadReport.SHORT)),
], ids=["left-silent", "right-silent", "left-short", "right-short", "both-silent",
        "both-short"])
def test_reports_from_a_tread_fault_value(value: int, want: tuple) -> None:
    """NAV_TREAD_FAULT's bits read as per-tread reports."""
    assert reports_from_value(value) == want


def test_bad_inputs_are_refused() -> None:
    """A reported tread needs its modelled travel; values and shapes are checked."""
    with pytest.raises(ValueError, match="driven_left_cm must be a finite number"):
        TreadMotion(0.0, 20.0, left=TreadReport.SILENT)
    with pytest.raises(ValueError, match="tread fault value must be"):
        reports_from_value(5)
    with pytest.raises(ValueError, match="encoder_sigma"):
        MotionNoise(encoder_sigma=-1.0)
    with pytest.raises(ValueError, match="particles must have shape"):
        sample_motion(np.zeros((3, 2)), TreadMotion(1.0, 1.0), W, NOISE,
                      np.random.default_rng(0))


def test_the_same_generator_seed_gives_the_same_particles() -> None:
    """All randomness comes from the generator passed in."""
    m = TreadMotion(5.0, 20.0, driven_left_cm=20.0, left=TreadReport.SHORT)
    a = sample_motion(_start(100), m, W, NOISE, np.random.default_rng(9))
    b = sample_motion(_start(100), m, W, NOISE, np.random.default_rng(9))
    assert np.array_equal(a, b)
