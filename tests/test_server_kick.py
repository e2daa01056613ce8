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
