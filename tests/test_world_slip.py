"""Tread slip is drawn per distance travelled: the room's physics do not depend on the tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.test_physics import ROOM  # a 4 x 3 m box, the mapper at (100, 50) @ 0
from world.drive import slipped_travel
from world.scenario import parse_scenario
from world.world import World

SAMPLES = 120  # seeded runs per tick length


def test_the_count_error_over_a_path_does_not_depend_on_the_step() -> None:
    """100 cm counted in 100 steps of 1 cm or 4 steps of 25 cm: the same spread,
    slip_sigma * sqrt(100 cm)."""
    rng = np.random.default_rng(1)
    sigma = 0.022
    errors = {}
    for step in (1.0, 25.0):
        n = round(100.0 / step)
        z = rng.standard_normal((20000, n))
        counted = np.vectorize(slipped_travel)(np.full_like(z, step), z, sigma).sum(axis=1)
        errors[step] = float(np.std(counted - 100.0))
    assert errors[1.0] == pytest.approx(sigma * 10.0, rel=0.03)
    assert errors[25.0] == pytest.approx(sigma * 10.0, rel=0.03)


def _heading_drift_deg(tick_s: float, seed: int) -> tuple[float, float]:
    """Drive the mapper straight at PWM 0.8 for 4 s; the heading the encoders count
    less the true heading change [deg], and the distance travelled [cm]."""
    world = World(parse_scenario(ROOM), np.random.default_rng(seed), tick_s=tick_s,
                  substep_s=min(0.01, tick_s))
    p = world.params
    left, right = world.treads["mapper"]
    start = world.true_pose("mapper")
    t_left, t_right = left.ticks, right.ticks
    world.hardware("mapper").set_tread_pwm(0.8, 0.8)
    while world.time < 4.0 - 1e-9:
        world.step()
    end = world.true_pose("mapper")
    d_left = (left.ticks - t_left) / p.ticks_per_cm
    d_right = (right.ticks - t_right) / p.ticks_per_cm
    counted = math.degrees((d_right - d_left) / p.track_width_cm)
    true = (end.heading_deg - start.heading_deg + 180.0) % 360.0 - 180.0
    return counted - true, math.hypot(end.x - start.x, end.y - start.y)


def test_two_tick_lengths_give_the_same_heading_drift_over_the_same_path() -> None:
    """The same 4 s straight drive with 20 ms and 50 ms ticks, 120 seeds each: the spread
    of the counted heading's error agrees within 25 % (per-tick slip gave a ratio of
    sqrt(50 / 20) = 1.58) and matches slip_sigma * sqrt(2 D) / track width."""
    spread = {}
    for tick_s in (0.02, 0.05):
        runs = [_heading_drift_deg(tick_s, seed) for seed in range(SAMPLES)]
        drift = np.array([r[0] for r in runs])
        travelled = float(np.mean([r[1] for r in runs]))
        spread[tick_s] = float(np.std(drift))
        p = World(parse_scenario(ROOM), np.random.default_rng(0)).params
        want = math.degrees(p.slip_sigma * math.sqrt(2 * travelled) / p.track_width_cm)
        assert spread[tick_s] == pytest.approx(want, rel=0.25)
        assert abs(float(np.mean(drift))) < 3 * want / math.sqrt(SAMPLES)  # no bias
    assert spread[0.02] / spread[0.05] == pytest.approx(1.0, abs=0.25)
