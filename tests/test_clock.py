"""The three clocks: real, scaled (rate changeable inside Trio), virtual."""

from __future__ import annotations

import pytest
import trio
from trio.testing import MockClock

from actors import real_clock, scaled_clock, set_rate, set_rate_soon, virtual_clock


def test_virtual_clock_jumps_when_idle() -> None:
    """A 1000 s sleep on the virtual clock ends at exactly 1000 s of Trio time."""
    async def main() -> float:
        start = trio.current_time()
        await trio.sleep(1000)
        return trio.current_time() - start

    assert trio.run(main, clock=virtual_clock()) == 1000.0


def test_real_clock_is_trios_default() -> None:
    assert real_clock() is None


def test_scaled_clock_rate_changes_from_inside_trio() -> None:
    """Raising the rate mid-run makes the remaining sleeps pass faster in wall terms."""
    clock = scaled_clock(1000.0)

    async def main() -> tuple[float, float]:
        await trio.sleep(2)  # about 2 ms of wall time
        set_rate(clock, 100_000.0)
        await trio.sleep(50)  # about 0.5 ms of wall time
        set_rate_soon(trio.lowlevel.current_trio_token(), clock, 7.0)
        await trio.sleep(0)
        await trio.sleep(0)
        return trio.current_time(), clock.rate

    now, rate = trio.run(main, clock=clock)
    assert now >= 52.0
    assert rate == 7.0
    assert isinstance(clock, MockClock) and clock.autojump_threshold == float("inf")


@pytest.mark.parametrize("bad", [0, -1.0, float("inf"), float("nan")])
def test_rates_must_be_finite_and_positive(bad: float) -> None:
    with pytest.raises(ValueError, match="rate must be a finite number > 0"):
        scaled_clock(bad)
    with pytest.raises(ValueError, match="rate must be a finite number > 0"):
        set_rate(scaled_clock(1.0), bad)


def test_rate_must_be_a_number() -> None:
    with pytest.raises(TypeError, match="rate must be a number, got 'fast'"):
        scaled_clock("fast")  # type: ignore[arg-type]
