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
