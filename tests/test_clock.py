"""The three clocks: real, scaled (rate changeable inside Trio), virtual."""

from __future__ import annotations

import math

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


def test_virtual_clock_answers_as_trios_mock_clock() -> None:
    """The virtual clock's shortcuts give `MockClock`'s values: the time, the sleep until
    a deadline (0 when due, "forever" otherwise at rate 0), and after a jump."""
    ours, trios = virtual_clock(), MockClock(autojump_threshold=0)
    for clock in (ours, trios):
        clock.jump(12.5)
    assert ours.current_time() == trios.current_time() == 12.5
    for deadline in (0.0, 12.5, 12.500001, 13.0, 1e9, math.inf):
        assert ours.deadline_to_sleep_time(deadline) == trios.deadline_to_sleep_time(deadline)
    ours.rate = trios.rate = 2.0  # a rate set later: Trio's formula, on the real clock
    assert ours.deadline_to_sleep_time(1e9) == pytest.approx(
        trios.deadline_to_sleep_time(1e9), abs=1.0)


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


def _wake_log(sleeper, seed: int) -> list[tuple[float, str]]:
    """Who wakes when: tasks sleeping overlapping periods, one cancelled mid-sleep,
    under the seeded (shuffled) scheduler a game runs with."""
    from actors import seed_trio_scheduler  # noqa: PLC0415

    log: list[tuple[float, str]] = []

    async def ticker(name: str, period: float, n: int) -> None:
        for _ in range(n):
            await sleeper(period)
            log.append((trio.current_time(), name))

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            for i, period in enumerate((0.05, 0.1, 0.25, 0.05, 0.02)):
                nursery.start_soon(ticker, f"t{i}", period, 40)
            with trio.CancelScope() as scope:
                scope.deadline = trio.current_time() + 0.33
                await sleeper(5.0)  # cancelled from outside: must raise, not wake
                log.append((trio.current_time(), "not cancelled"))
            log.append((trio.current_time(), f"cancelled {scope.cancelled_caught}"))

    seed_trio_scheduler(seed)
    trio.run(main, clock=virtual_clock())
    return log


@pytest.mark.parametrize("seed", [1, 2])
def test_cheap_sleep_wakes_like_trios(seed: int) -> None:
    """`actors.sleep` wakes the same tasks at the same instants in the same order as
    `trio.sleep` (so games keep their trace), and an outer cancel still cancels it."""
    from actors import sleep  # noqa: PLC0415

    ours, trios = _wake_log(sleep, seed), _wake_log(trio.sleep, seed)
    assert ours == trios
    assert (0.33, "cancelled True") in ours
    assert all(name != "not cancelled" for _, name in ours)


def test_cheap_sleep_checks_its_argument() -> None:
    """0 is a checkpoint; negative or NaN is refused as by Trio."""
    from actors import sleep, sleep_until  # noqa: PLC0415

    async def main() -> float:
        await sleep(0)
        for bad in (-1.0, float("nan")):
            with pytest.raises(ValueError):
                await sleep(bad)
        with pytest.raises(ValueError):
            await sleep_until(float("nan"))
        await sleep_until(trio.current_time() - 1.0)  # past: returns at once
        return trio.current_time()

    assert trio.run(main, clock=virtual_clock()) == 0.0


def test_cheap_sleep_keeps_trios_deadline_heap_consistent() -> None:
    """Thousands of sleeps cancelled from outside leave stale heap entries; Trio's
    pruning (which asserts its count of live deadlines) and later sleeps still work."""
    from actors import sleep  # noqa: PLC0415

    async def main() -> tuple[int, float]:
        cancelled = 0
        for _ in range(3000):
            with trio.move_on_after(0.01) as scope:
                await sleep(1.0)
            cancelled += scope.cancelled_caught
        start = trio.current_time()
        await sleep(2.5)
        return cancelled, trio.current_time() - start

    cancelled, slept = trio.run(main, clock=virtual_clock())
    assert cancelled == 3000
    assert slept == 2.5


def test_an_endless_sleep_stays_out_of_trios_deadline_heap() -> None:
    """``sleep(inf)`` parks until cancelled, as Trio's does, without an entry in the
    heap (whose count of live deadlines Trio checks when it prunes)."""
    from trio._core._run import GLOBAL_RUN_CONTEXT  # noqa: PLC0415

    from actors import sleep  # noqa: PLC0415

    async def main() -> tuple[bool, int]:
        with trio.move_on_after(3.0) as scope:
            active = GLOBAL_RUN_CONTEXT.runner.deadlines._active  # noqa: SLF001
            async with trio.open_nursery() as nursery:
                nursery.start_soon(sleep, math.inf)
                await trio.sleep(1.0)
                added = GLOBAL_RUN_CONTEXT.runner.deadlines._active - active  # noqa: SLF001
        return scope.cancelled_caught, added

    cancelled, added = trio.run(main, clock=virtual_clock())
    assert cancelled
    assert added == 0


def test_outside_a_run_a_sleep_is_refused() -> None:
    from actors import sleep  # noqa: PLC0415

    with pytest.raises(RuntimeError):
        sleep(1.0).send(None)


def test_fast_instruments_keep_trios_instrument_hooks() -> None:
    """After `fast_instruments`, Trio still calls instruments added later and stops
    calling removed ones (its own add/remove/call run on the replacement)."""
    from actors.clock import fast_instruments

    calls: list[str] = []

    class Steps(trio.abc.Instrument):
        def before_task_step(self, task: object) -> None:
            calls.append("step")

    async def main() -> tuple[int, int]:
        fast_instruments()
        fast_instruments()  # a second call keeps the same registry
        steps = Steps()
        trio.lowlevel.add_instrument(steps)
        await trio.sleep(0)
        seen = len(calls)
        trio.lowlevel.remove_instrument(steps)
        await trio.sleep(0)
        await trio.sleep(0)
        return seen, len(calls)

    seen, after = trio.run(main, clock=virtual_clock())
    assert seen >= 1
    assert after == seen  # nothing after the removal


def test_skipped_idle_io_polls_still_hear_threads_and_sockets() -> None:
    """After `skip_idle_io_polls`, a thread's result (Trio's entry queue) and a socket's
    data still wake their tasks on the virtual clock, and a second call changes nothing."""
    from actors.clock import skip_idle_io_polls

    async def main() -> tuple[int, bytes]:
        skip_idle_io_polls()
        manager = type(trio.lowlevel.current_root_task()._runner.io_manager)  # noqa: SLF001
        skip_idle_io_polls()
        assert type(trio.lowlevel.current_root_task()._runner.io_manager) is manager  # noqa: SLF001
        value = await trio.to_thread.run_sync(lambda: 7)
        a, b = trio.socket.socketpair()
        with a, b:
            await trio.sleep(1.0)  # a clock jump with the socket waited on next
            await b.send(b"x")
            data = await a.recv(1)
        return value, data

    assert trio.run(main, clock=virtual_clock()) == (7, b"x")
