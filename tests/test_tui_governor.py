"""`GovernedClock`: virtual time released to the wall clock (a fake wall clock here)."""

from __future__ import annotations

import math

import pytest

from tui.governor import MAX_DEBT_S, POLL_S, GovernedClock


class Wall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_a_deadline_is_jumped_to_only_once_the_wall_clock_released_it() -> None:
    wall = Wall()
    clock = GovernedClock(4.0, wall=wall)
    clock.start_clock()
    assert clock.deadline_to_sleep_time(1.0) == pytest.approx(0.25 if 0.25 < POLL_S else POLL_S)
    assert clock.current_time() == 0.0
    wall.t += 0.25  # x4: one simulated second released
    assert clock.deadline_to_sleep_time(1.0) == 0.0
    assert clock.current_time() == 1.0
    assert clock.deadline_to_sleep_time(1.01) == pytest.approx(0.0025)


def test_as_fast_as_possible_jumps_at_once_and_pause_releases_nothing() -> None:
    wall = Wall()
    clock = GovernedClock(None, wall=wall)
    clock.start_clock()
    assert clock.deadline_to_sleep_time(50.0) == 0.0 and clock.current_time() == 50.0
    clock.set(1.0, paused=True)
    wall.t += 10.0
    assert clock.deadline_to_sleep_time(51.0) == POLL_S and clock.current_time() == 50.0
    clock.set(1.0, paused=False)  # resumed: released from now on, not for the pause
    assert clock.deadline_to_sleep_time(51.0) > 0
    wall.t += 1.0
    assert clock.deadline_to_sleep_time(51.0) == 0.0 and clock.current_time() == 51.0
    assert clock.deadline_to_sleep_time(math.inf) == POLL_S


def test_time_the_machine_could_not_use_is_not_caught_up_in_a_burst() -> None:
    wall = Wall()
    clock = GovernedClock(16.0, wall=wall)
    clock.start_clock()
    wall.t += 10.0  # a slow stretch: 160 s released, none used
    assert clock.deadline_to_sleep_time(1.0) == 0.0
    assert clock.deadline_to_sleep_time(1.0 + 16.0 * MAX_DEBT_S + 1.0) > 0.0


def test_reached_speed_is_measured_over_wall_time() -> None:
    wall = Wall()
    clock = GovernedClock(16.0, wall=wall)
    clock.start_clock()
    assert clock.reached() is None
    for _ in range(10):
        wall.t += 0.1
        clock.deadline_to_sleep_time(clock.current_time() + 0.5)  # the machine: x5
    assert clock.reached() == pytest.approx(5.0)


def test_rate_must_be_positive_or_none() -> None:
    with pytest.raises(ValueError, match="rate must be"):
        GovernedClock(0.0)
    with pytest.raises(TypeError):
        GovernedClock("fast")  # type: ignore[arg-type]
