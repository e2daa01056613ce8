"""The server timer's wake-up (`server.kick.Kick`): an Event that the waiter clears."""

from __future__ import annotations

import pytest
import trio

from actors import virtual_clock
from server.kick import Kick


def test_a_kick_given_before_the_wait_makes_it_return_at_once() -> None:
    async def main() -> float:
        kick = Kick()
        kick.set()
        await kick.wait()
        return trio.current_time()

    assert trio.run(main, clock=virtual_clock()) == 0.0


def test_set_wakes_the_waiter_and_clear_rearms_it() -> None:
    woke: list[float] = []

    async def waiter(kick: Kick) -> None:
        for _ in range(2):
            await kick.wait()
            woke.append(trio.current_time())
            kick.clear()

    async def main() -> None:
        kick = Kick()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(waiter, kick)
            await trio.sleep(1.0)
            kick.set()
            kick.set()  # a second kick before the waiter clears changes nothing
            await trio.sleep(2.0)
            assert not kick.is_set()
            kick.set()

    trio.run(main, clock=virtual_clock())
    assert woke == [1.0, 3.0]


def test_a_cancelled_wait_leaves_the_kick_usable() -> None:
    async def main() -> bool:
        kick = Kick()
        with trio.move_on_after(1.0):
            await kick.wait()
        kick.set()
        await kick.wait()
        return kick.is_set()

    assert trio.run(main, clock=virtual_clock())


def test_a_second_waiter_is_refused() -> None:
    async def main() -> None:
        kick = Kick()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(kick.wait)
            await trio.sleep(0.1)
            with pytest.raises(RuntimeError, match="waiting task already"):
                await kick.wait()
            kick.set()

    trio.run(main, clock=virtual_clock())


def _live_deadlines() -> int:
    from trio._core._run import GLOBAL_RUN_CONTEXT  # noqa: PLC0415

    return GLOBAL_RUN_CONTEXT.runner.deadlines._active  # noqa: SLF001


def test_wait_until_wakes_at_the_deadline_or_on_the_kick_and_leaves_the_heap() -> None:
    async def kicker(kick: Kick) -> None:
        await trio.sleep(0.5)
        kick.set()

    async def main() -> list[tuple[bool, float, int]]:
        kick = Kick()
        live = _live_deadlines()
        out = [(await kick.wait_until(2.0), trio.current_time(), _live_deadlines() - live)]
        async with trio.open_nursery() as nursery:
            nursery.start_soon(kicker, kick)
            out.append((await kick.wait_until(9.0), trio.current_time(),
                        _live_deadlines() - live))
        return out

    assert trio.run(main, clock=virtual_clock()) == [(False, 2.0, 0), (True, 2.5, 0)]


def test_wait_until_is_cancelled_like_any_wait() -> None:
    async def main() -> tuple[bool, int]:
        kick = Kick()
        live = _live_deadlines()
        with trio.move_on_after(1.0) as scope:
            await kick.wait_until(5.0)
        return scope.cancelled_caught, _live_deadlines() - live

    assert trio.run(main, clock=virtual_clock()) == (True, 0)


def test_the_timer_wakes_in_the_batches_of_an_event_in_a_cancel_scope() -> None:
    """A Kick waited on until a deadline wakes the same tasks at the same instants, in
    the same order, as the `trio.Event` in a `trio.move_on_at` scope it stands for."""
    from actors import seed_trio_scheduler  # noqa: PLC0415

    def play(with_kick: bool) -> list[tuple[float, str]]:
        log: list[tuple[float, str]] = []

        async def timer(box: list) -> None:
            for _ in range(30):
                now = trio.current_time()
                if with_kick:
                    box[0].clear()
                    await box[0].wait_until(now + 0.3)
                else:
                    box[0] = trio.Event()
                    with trio.move_on_at(now + 0.3):
                        await box[0].wait()
                log.append((trio.current_time(), "timer"))

        async def worker(box: list, name: str, period: float) -> None:
            for _ in range(40):
                await trio.sleep(period)
                log.append((trio.current_time(), name))
                box[0].set()

        async def main() -> None:
            box: list = [Kick() if with_kick else trio.Event()]
            async with trio.open_nursery() as nursery:
                nursery.start_soon(timer, box)
                for i, period in enumerate((0.25, 0.4, 0.7)):
                    nursery.start_soon(worker, box, f"w{i}", period)

        seed_trio_scheduler(3)
        trio.run(main, clock=virtual_clock())
        return log

    assert play(with_kick=True) == play(with_kick=False)
