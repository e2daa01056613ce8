"""Bounded mailboxes: backpressure, ISR-style drops, counters."""

from __future__ import annotations

import pytest
import trio
import trio.testing

from actors import EventKind, Mailbox, MailboxClosed, Trace


@pytest.mark.trio
async def test_send_nowait_drops_and_counts_when_full() -> None:
    """A full mailbox refuses send_nowait, counts the drop and traces it."""
    trace = Trace()
    seen = []
    trace.subscribe(seen.append)
    box = Mailbox("m", 2, trace)
    assert box.send_nowait(1) and box.send_nowait(2)
    assert not box.send_nowait(3)
    s = box.statistics()
    assert (s.depth, s.sent, s.dropped, s.high_water) == (2, 2, 1, 2)
    assert [e.kind for e in seen] == [EventKind.DROP]
    assert box.receive_nowait() == 1 and box.receive_nowait() == 2


@pytest.mark.trio
async def test_send_waits_for_room(autojump_clock) -> None:
    """await send blocks while full and completes once the receiver takes one."""
    box = Mailbox("m", 1, Trace())
    box.send_nowait("a")
    done = []

    async def sender() -> None:
        await box.send("b")
        done.append(trio.current_time())

    async with trio.open_nursery() as nursery:
        nursery.start_soon(sender)
        await trio.sleep(1)
        assert done == []
        assert box.receive_nowait() == "a"
    assert done == [1.0]
    assert box.receive_nowait() == "b"


@pytest.mark.trio
async def test_send_does_not_checkpoint_when_there_is_room() -> None:
    """The fast path: appending with room never yields (bursts are cheap)."""
    box = Mailbox("m", 10, Trace())
    with trio.testing.assert_no_checkpoints():
        await box.send(1)


@pytest.mark.trio
async def test_closed_mailbox_wakes_blocked_senders(autojump_clock) -> None:
    """Closing a full mailbox makes waiting senders raise MailboxClosed."""
    box = Mailbox("m", 1, Trace())
    box.send_nowait(1)
    errors = []

    async def sender() -> None:
        try:
            await box.send(2)
        except MailboxClosed as exc:
            errors.append(str(exc))

    async with trio.open_nursery() as nursery:
        nursery.start_soon(sender)
        await trio.testing.wait_all_tasks_blocked()
        box.close()
    assert errors == ["mailbox 'm' is closed"]
    assert not box.send_nowait(3)


@pytest.mark.trio
async def test_per_message_events_only_when_subscribed() -> None:
    """send/receive events are made only for per-message subscribers."""
    trace = Trace()
    lifecycle, every = [], []
    trace.subscribe(lifecycle.append)
    box = Mailbox("m", 4, trace)
    box.send_nowait(1)
    assert trace.count == 0
    sub = trace.subscribe(every.append, per_message=True)
    box.send_nowait(2)
    box.receive_nowait()
    assert [e.kind for e in every] == [EventKind.SEND, EventKind.RECEIVE]
    assert every[0].depth == 2 and every[1].depth == 1
    assert lifecycle == []
    sub.close()
    box.send_nowait(3)
    assert len(every) == 2


def test_capacity_checked() -> None:
    with pytest.raises(ValueError, match="capacity must be >= 1, got 0"):
        Mailbox("m", 0, Trace())
    assert "sent=0" in repr(Mailbox("m", 1, Trace()))


@pytest.mark.trio
async def test_take_all_takes_one_type_in_order_and_wakes_senders(autojump_clock) -> None:
    """take_all removes the items of one type (counted as received), keeps the others in
    order, and lets as many blocked senders in as it made room for."""
    box = Mailbox("m", 4, Trace())
    for item in (1, "a", 2, "b"):
        box.send_nowait(item)
    done = []

    async def sender(item: object) -> None:
        await box.send(item)
        done.append(item)

    async with trio.open_nursery() as nursery:
        for item in ("c", "d", "e"):
            nursery.start_soon(sender, item)
        await trio.testing.wait_all_tasks_blocked()
        assert box.take_all(str) == ["a", "b"]
        await trio.testing.wait_all_tasks_blocked()
        assert len(done) == 2  # room for two: the third sender still waits
        assert box.take_all(int) == [1, 2]
    assert box.statistics().received == 4
    assert box.depth == 3


@pytest.mark.trio
async def test_cast_counts_like_send_and_waits_when_full(autojump_clock) -> None:
    """A cast into room counts sent and high water as send_nowait does; into a full
    mailbox it waits for room; to a name retired while waiting it returns False."""
    from actors import Actor, open_actor_system
    from supervisors import ChildSpec, SupervisorSpec

    class Slow(Actor):
        async def handle(self, message):
            await trio.sleep(1)

    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([ChildSpec("a", Slow, mailbox=2)]))
        assert await system.cast("a", 1) and await system.cast("a", 2)
        await trio.testing.wait_all_tasks_blocked()  # a takes 1: depth 1
        assert await system.cast("a", 3)
        stats = system.statistics("a")
        assert (stats.sent, stats.high_water, stats.depth) == (3, 2, 2)
        results = []

        async def caster() -> None:
            results.append(await system.cast("a", 4))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(caster)
            await trio.testing.wait_all_tasks_blocked()
            assert results == []  # waiting for room
            system.retire("a")
        assert results == [False]


@pytest.mark.trio
async def test_cast_nowait_queues_into_room_and_says_none_when_full(autojump_clock) -> None:
    """cast_nowait queues (counted as a cast) while there is room, answers None without
    queuing when the mailbox is full, and False for an unknown or retired name."""
    from actors import Actor, open_actor_system
    from supervisors import ChildSpec, SupervisorSpec

    class Slow(Actor):
        async def handle(self, message):
            await trio.sleep(1)

    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([ChildSpec("a", Slow, mailbox=2)]))
        assert system.cast_nowait("a", 1) is True
        assert system.cast_nowait("a", 2) is True
        assert system.cast_nowait("a", 3) is None  # full: nothing queued
        stats = system.statistics("a")
        assert (stats.sent, stats.depth, stats.dropped) == (2, 2, 0)
        assert system.cast_nowait("nobody", 1) is False
        system.retire("a")
        assert system.cast_nowait("a", 4) is False


@pytest.mark.trio
async def test_call_into_a_full_mailbox_waits_then_times_out(autojump_clock) -> None:
    """A call that first waits for room keeps one timeout for both waits."""
    from actors import Actor, CallTimeout, open_actor_system
    from supervisors import ChildSpec, SupervisorSpec

    class Slow(Actor):
        async def handle(self, message):
            await trio.sleep(10)
            return message

    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([ChildSpec("a", Slow, mailbox=1)]))
        system.send_nowait("a", "busy")
        await trio.testing.wait_all_tasks_blocked()
        system.send_nowait("a", "queued")  # full now
        with pytest.raises(CallTimeout, match="no reply from 'a' within 3 s"):
            await system.call("a", "x", timeout=3)
        assert trio.current_time() == 3.0


def test_benchmark_baselines_run() -> None:
    """The hand-written baselines of benchmarks.mailbox measure something."""
    from benchmarks.mailbox import batched_channel, hand_restart_latency

    assert trio.run(batched_channel, 100) > 0
    assert len(trio.run(hand_restart_latency, 3)) == 3
