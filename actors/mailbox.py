"""Bounded mailboxes: the seed's RTOS queues.

A mailbox has a fixed depth. ``await send(item)`` waits for room
(backpressure, like a blocking queue send); ``send_nowait(item)`` never
blocks: on a full mailbox it drops the item, counts it and returns False,
like a queue send from an ISR. Mailboxes carry any object.

A mailbox belongs to the supervisor of its actor, not to the actor's task, so
it survives the actor's restart: messages waiting in it are not lost.

Speed: ``send`` appends without a checkpoint when there is room (it yields
only when it has to wait), and the receiving actor drains a whole burst with
`Mailbox.receive_nowait` and checkpoints once per burst. This is what makes
delivery several times faster than an awaited memory channel.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import trio
from trio.lowlevel import Abort, current_task, reschedule, wait_task_rescheduled

from .trace import EventKind, Trace

__all__ = ["Mailbox", "MailboxStatistics", "MailboxClosed"]


class MailboxClosed(Exception):
    """Raised by `Mailbox.send` on a mailbox whose actor was removed for good."""


@dataclass(frozen=True, slots=True)
class MailboxStatistics:
    """Counters of one mailbox (always kept, whatever the trace records)."""

    name: str
    depth: int  #: items waiting now
    capacity: int  #: the most items it holds
    sent: int  #: items accepted since creation
    received: int  #: items taken since creation
    dropped: int  #: items refused by send_nowait because it was full
    high_water: int  #: the most items ever waiting at once


class Mailbox:
    """A bounded FIFO of any objects, with one receiving actor.

    Made by the runtime (`ActorSystem.ensure_cell`), not by users.

    Args:
        name: the registered name of the owning actor (``mapper/motor``).
        capacity: the depth (>= 1).
        trace: where drops (and, when subscribed, sends) are reported.
    """

    __slots__ = ("name", "capacity", "_queue", "_receiver", "_senders", "_trace", "_sent",
                 "_received", "_dropped", "_high", "_closed", "_waiting")

    def __init__(self, name: str, capacity: int, trace: Trace) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int):
            raise TypeError(f"capacity must be an int, got {capacity!r}")
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity!r}")
        self.name = name
        self.capacity = capacity
        self._queue: deque[Any] = deque()
        self._receiver: Any = None  # the task parked in `wait` (one receiving actor), or None
        self._senders = trio.lowlevel.ParkingLot()  # tasks waiting for room
        self._trace = trace
        self._sent = self._received = self._dropped = self._high = 0
        self._closed = False
        # the lot's own dict of parked senders, read per message: its truth is the lot's,
        # without the lot's Python-level __bool__ (Trio never replaces the dict)
        self._waiting: Any = getattr(self._senders, "_parked", self._senders)

    # ---------------------------------------------------------------- sending
    def send_nowait(self, item: Any) -> bool:
        """Append ``item`` if there is room; else drop it, count it and return False."""
        queue = self._queue
        n = len(queue)
        if n >= self.capacity or self._closed:
            self._dropped += 1
            self._trace.emit(EventKind.DROP, self.name, self.name, item, n)
            return False
        queue.append(item)
        self._sent += 1
        n += 1
        if n > self._high:
            self._high = n
        if self._receiver is not None:
            self._wake()
        if self._trace.per_message:
            self._trace.emit(EventKind.SEND, self.name, self.name, item, n)
        return True

    async def send(self, item: Any) -> None:
        """Append ``item``, waiting for room while the mailbox is full.

        Checkpoints only when it has to wait.

        Raises:
            MailboxClosed: the mailbox's actor was removed for good.
        """
        while len(self._queue) >= self.capacity:
            if self._closed:
                raise MailboxClosed(f"mailbox {self.name!r} is closed")
            await self._senders.park()
        if self._closed:
            raise MailboxClosed(f"mailbox {self.name!r} is closed")
        self.send_nowait(item)

    # ---------------------------------------------------------------- receiving
    def receive_nowait(self) -> Any:
        """Take the oldest item (the mailbox must not be empty: check `depth`)."""
        item = self._queue.popleft()
        self._received += 1
        if self._waiting:
            self._senders.unpark()
        if self._trace.per_message_receive:
            self._trace.emit(EventKind.RECEIVE, self.name, self.name, item, len(self._queue))
        return item

    def take_all(self, kind: type) -> list[Any]:
        """Take every waiting item of exactly type ``kind`` (counted as received), keeping
        the others in order; wakes as many waiting senders as room was made.

        Used at an actor's exit to fail the calls waiting in its mailbox: O(depth),
        never on the per-message path.
        """
        queue = self._queue
        taken = [item for item in queue if type(item) is kind]
        if taken:
            kept = [item for item in queue if type(item) is not kind]
            queue.clear()
            queue.extend(kept)
            self._received += len(taken)
            if self._waiting:
                self._senders.unpark(count=len(taken))
        return taken

    async def wait(self) -> None:
        """Park the receiver until an item arrives or `poke` is called.

        Why not a `trio.lowlevel.ParkingLot`: one actor receives, so one task slot
        does; parking and waking are on every message's path, and the lot's
        bookkeeping for many waiters was a visible share of a whole game's time.
        The wake-up is the same `trio.lowlevel.reschedule` at the same moment.

        Raises:
            RuntimeError: another task is already parked on this mailbox.
        """
        if self._receiver is not None:
            raise RuntimeError(f"mailbox {self.name!r} already has a parked receiver")
        self._receiver = current_task()
        await wait_task_rescheduled(self._abort_wait)

    def _abort_wait(self, _raise_cancel: Any) -> Abort:
        self._receiver = None
        return Abort.SUCCEEDED

    def _wake(self) -> None:
        task, self._receiver = self._receiver, None
        reschedule(task)

    def poke(self) -> None:
        """Wake a parked receiver without an item (to look at a stop or fault request)."""
        if self._receiver is not None:
            self._wake()

    def close(self) -> None:
        """Refuse items from now on and wake waiting senders (they raise `MailboxClosed`)."""
        self._closed = True
        self._senders.unpark_all()

    # ---------------------------------------------------------------- reporting
    @property
    def closed(self) -> bool:
        """True once closed: it refuses every item for good."""
        return self._closed

    @property
    def depth(self) -> int:
        """Items waiting now."""
        return len(self._queue)

    def statistics(self) -> MailboxStatistics:
        """Current counters."""
        return MailboxStatistics(self.name, len(self._queue), self.capacity, self._sent,
                                 self._received, self._dropped, self._high)

    def __repr__(self) -> str:
        return (f"<Mailbox {self.name!r} {len(self._queue)}/{self.capacity} "
                f"sent={self._sent} dropped={self._dropped}>")
