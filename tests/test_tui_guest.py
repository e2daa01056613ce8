"""TrioGuest: Trio as a guest on an asyncio loop, started and stopped cleanly."""

from __future__ import annotations

import asyncio

import outcome
import pytest
import trio

import tui.widgets
from tui.guest import TrioGuest


def test_guest_runs_trio_and_stop_cancels_it():
    """A sleeping Trio task runs in the guest; stop() cancels it and returns its outcome."""
    seen = []

    async def trio_main():
        seen.append("started")
        await trio.sleep_forever()

    async def main():
        guest = TrioGuest(on_done=seen.append)
        guest.start(trio_main)
        await asyncio.sleep(0.05)
        assert seen == ["started"] and not guest.finished
        result = await guest.stop()
        return guest, result

    guest, result = asyncio.run(main())
    assert guest.finished and isinstance(result, outcome.Value)
    assert seen[0] == "started" and isinstance(seen[1], outcome.Value)


def test_guest_reports_a_failing_run():
    """An exception in the Trio run comes back as an Error outcome, not a crash."""

    async def trio_main():
        raise ValueError("bad system")

    async def main():
        guest = TrioGuest()
        guest.start(trio_main)
        return await guest.stop()

    result = asyncio.run(main())
    assert isinstance(result, outcome.Error) and str(result.error) == "bad system"


def test_guest_synchronous_send_wakes_an_idle_trio():
    """send_nowait from the asyncio side wakes a Trio task waiting on the channel."""
    got = []

    async def main():
        send, receive = trio.open_memory_channel[int](4)

        async def trio_main():
            async for value in receive:
                got.append(value)

        guest = TrioGuest()
        guest.start(trio_main)
        await asyncio.sleep(0.02)
        send.send_nowait(7)
        for _ in range(100):
            if got:
                break
            await asyncio.sleep(0.005)
        await guest.stop()

    asyncio.run(main())
    assert got == [7]


def test_guest_starts_once_and_stop_before_start_is_harmless():
    """A second start is a RuntimeError; stop() before start() returns None."""

    async def main():
        guest = TrioGuest()
        assert await guest.stop() is None
        guest.start(trio.sleep_forever)
        with pytest.raises(RuntimeError, match="already started"):
            guest.start(trio.sleep_forever)
        await guest.stop()

    asyncio.run(main())


def test_widgets_package_exports_its_public_names():
    """Every name in tui.widgets.__all__ exists."""
    assert all(hasattr(tui.widgets, name) for name in tui.widgets.__all__)


def test_ready_trio_batches_run_back_to_back_while_the_host_is_idle():
    """With nothing else ready on the host loop, Trio batches run in bursts (far fewer
    host-loop callbacks than batches); a Trio task that never blocks still leaves the
    host loop running (a timer fires)."""
    batches = 2000

    async def main():
        done = asyncio.Event()

        async def trio_main():
            for _ in range(batches):
                await trio.lowlevel.checkpoint()  # one scheduler batch each
            done.set()
            while True:  # busy forever: never idle, never sleeping
                await trio.lowlevel.checkpoint()

        loop = asyncio.get_running_loop()
        host_callbacks = 0
        call_soon = loop.call_soon

        def counting_call_soon(*args, **kwargs):
            nonlocal host_callbacks
            host_callbacks += 1
            return call_soon(*args, **kwargs)

        loop.call_soon = counting_call_soon
        guest = TrioGuest()
        guest.start(trio_main)
        await asyncio.wait_for(done.wait(), 10.0)
        del loop.call_soon
        t0 = asyncio.get_running_loop().time()
        await asyncio.sleep(0.02)
        late = asyncio.get_running_loop().time() - t0 - 0.02
        await guest.stop()
        return host_callbacks, late

    host_callbacks, late = asyncio.run(main())
    assert host_callbacks < batches / 4, host_callbacks
    assert late < 0.5, late  # starved, it would never fire (bursts last BURST_S)


def test_a_burst_ends_as_soon_as_the_host_has_work():
    """A host task that is always ready gets a turn after every Trio batch or so:
    the two loops interleave instead of Trio running its bursts."""
    host_turns = 0
    batches = 500

    async def main():
        nonlocal host_turns
        done = asyncio.Event()

        async def trio_main():
            for _ in range(batches):
                await trio.lowlevel.checkpoint()
            done.set()

        async def count_turns():
            nonlocal host_turns
            while not done.is_set():
                host_turns += 1
                await asyncio.sleep(0)

        guest = TrioGuest()
        counter = asyncio.ensure_future(count_turns())
        guest.start(trio_main)
        await asyncio.wait_for(done.wait(), 10.0)
        await counter
        await guest.stop()

    asyncio.run(main())
    assert host_turns >= batches / 2, host_turns
