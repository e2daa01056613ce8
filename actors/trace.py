"""Trace events of a run: what happened to which actor and queue, and when.

Every send, receive, overflow drop, crash, restart, escalation and fault is a
`TraceEvent` stamped with Trio's (virtual) time. To keep the hot path cheap,
per-message events (``send``, ``receive``) are only made when some subscriber
asked for them (``per_message=True``); lifecycle events are always made.
Mailbox counters are kept separately and always (``Mailbox.statistics()``).

Subscribers are callbacks (called synchronously; they must not block) or
bounded channels (`Trace.open_channel`; a full channel drops and counts).
`JsonLinesRecorder` writes events as JSON lines. A *message tap*
(`Trace.tap_messages`) is the cheap way to watch every message: it is handed
the message object itself, with no ``repr`` and no `TraceEvent` made, which
is what a console's live log needs at thousands of messages a second.

The trace hash (`Trace.hexdigest`) is a BLAKE2b digest of every event made
(per-message events only with ``Trace(per_message=True)``, not when a
subscriber alone asked for them: a console watching a run does not change
its hash), order-independent among events with the same timestamp: Trio may wake tasks
that became runnable at one instant in any order, so events are grouped by
timestamp and sorted within a group before hashing. Two runs of one seed on a
virtual clock give the same hash; `seed_trio_scheduler` additionally makes
Trio's own batch order follow the seed.
"""

from __future__ import annotations

import enum
import hashlib
import json
import random
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import IO, Any

import trio

__all__ = [
    "EventKind",
    "TraceEvent",
    "Trace",
    "Subscription",
    "MessageTap",
    "JsonLinesRecorder",
    "seed_trio_scheduler",
]


class EventKind(enum.StrEnum):
    """What a trace event records."""

    SEND = "send"  #: a message entered a mailbox (per-message)
    RECEIVE = "receive"  #: an actor took a message from its mailbox (per-message)
    DROP = "drop"  #: send_nowait on a full mailbox: the message was dropped
    START = "start"  #: an actor or supervisor started
    STOP = "stop"  #: an actor or supervisor stopped (detail: exit reason)
    CRASH = "crash"  #: an actor crashed (detail: exception)
    POISON = "poison"  #: the message an actor was handling when it failed, dropped
    HUNG = "hung"  #: the watchdog cancelled an actor stuck on one message
    KILLED = "killed"  #: a child missed its shutdown timeout and was cancelled hard
    RESTART = "restart"  #: a supervisor restarted a child
    ESCALATE = "escalate"  #: a supervisor reached its restart intensity and gave up
    FAULT = "fault"  #: a fault was injected (crash, hang, flood)
    LATE_REPLY = "late_reply"  #: a reply came after the caller's timeout and was dropped


PER_MESSAGE = frozenset((EventKind.SEND, EventKind.RECEIVE))


@dataclass(frozen=True, slots=True)
class TraceEvent:
    """One event. ``time`` is Trio's clock [s]; ``depth`` the queue depth after it [messages]."""

    time: float
    kind: EventKind
    actor: str
    queue: str = ""
    message: str = ""
    depth: int = 0
    detail: str = ""

    def key(self) -> str:
        """A stable text form used for hashing."""
        return (f"{self.time!r}|{self.kind.value}|{self.actor}|{self.queue}|"
                f"{self.message}|{self.depth}|{self.detail}")


#: A message tap's callback: ``(time [s], kind, queue, message, depth [messages])``.
MessageTap = Callable[[float, EventKind, str, Any, int], Any]


class Subscription:
    """A subscriber's handle; `close` detaches it."""

    __slots__ = ("_trace", "callback", "per_message", "receives", "tap", "_counter")

    def __init__(self, trace: Trace, callback: Callable[..., Any], per_message: bool,
                 receives: bool = True, tap: bool = False):
        self._trace = trace
        self.callback = callback
        self.per_message = per_message
        self.receives = receives
        self.tap = tap
        """A message tap (`Trace.tap_messages`): raw messages only, no events."""
        self._counter: _DropCounter | None = None  # channel subscriptions only

    @property
    def dropped(self) -> int:
        """Events a channel subscription dropped because its channel was full (else 0)."""
        return self._counter.dropped if self._counter is not None else 0

    def close(self) -> None:
        """Stop receiving events (idempotent)."""
        self._trace._detach(self)


class Trace:
    """The event hub of one actor system.

    Args:
        per_message: also make ``send``/``receive`` events even with no
            per-message subscriber (for hashing every message of a run).
    """

    def __init__(self, *, per_message: bool = False) -> None:
        self._always_per_message = per_message
        self.per_message: bool = per_message
        """True when per-message events are being made (read on the hot path)."""
        self.per_message_receive: bool = per_message
        """True when ``receive`` events are being made too (read on the hot path)."""
        self._subs: list[Subscription] = []
        self._taps: tuple[Subscription, ...] = ()  # message taps, read on the hot path
        self._event_per_message = per_message  # some per-message TraceEvent is wanted
        self._hash = hashlib.blake2b(digest_size=16)
        self._bucket_time: float | None = None
        self._bucket: list[str] = []
        self.count = 0
        """Events made so far."""

    # ---------------------------------------------------------------- subscribers
    def subscribe(self, callback: Callable[[TraceEvent], Any], *,
                  per_message: bool = False, receives: bool = True) -> Subscription:
        """Call ``callback(event)`` for every event from now on.

        The callback runs synchronously where the event happens: it must be
        quick and must not block. With ``per_message`` it also gets
        ``send``/``receive`` events (which slows every message down);
        ``receives=False`` asks for the sends only, so no ``receive`` event
        is made for it (a message log needs one line per message, not two).
        """
        sub = Subscription(self, callback, per_message, receives)
        self._subs.append(sub)
        self._refresh()
        return sub

    def tap_messages(self, callback: MessageTap, *, receives: bool = False) -> Subscription:
        """Call ``callback(time, kind, queue, message, depth)`` for every message sent.

        The cheapest way to watch every message: no `TraceEvent` and no
        ``repr`` is made for a tap (an event subscriber costs both per
        message), and taps never change the trace hash. ``message`` is the
        object itself: a tap that keeps it must treat it as read-only and
        format it later (the firmware's `Message` is frozen). ``time`` is
        Trio's clock [s], ``depth`` the queue depth after the send
        [messages]. ``receives=True`` also calls it (kind ``receive``) for
        every message taken from a mailbox. Drops are not tapped: they are
        ordinary ``drop`` events (`subscribe`).
        """
        sub = Subscription(self, callback, True, receives, tap=True)
        self._subs.append(sub)
        self._refresh()
        return sub

    def open_channel(self, capacity: int = 1024, *,
                     per_message: bool = False) -> tuple[trio.MemoryReceiveChannel, Subscription]:
        """A bounded channel of events; when it is full, events are dropped and counted.

        Returns:
            (receive channel, subscription); ``subscription.dropped`` counts
            events that did not fit.
        """
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity!r}")
        send, receive = trio.open_memory_channel[TraceEvent](capacity)
        counter = _DropCounter(send)
        sub = self.subscribe(counter, per_message=per_message)
        sub._counter = counter
        return receive, sub

    def _detach(self, sub: Subscription) -> None:
        if sub in self._subs:
            self._subs.remove(sub)
            self._refresh()

    def _refresh(self) -> None:
        self.per_message = self._always_per_message or any(s.per_message for s in self._subs)
        self.per_message_receive = self._always_per_message or any(
            s.per_message and s.receives for s in self._subs)
        self._taps = tuple(s for s in self._subs if s.tap)
        self._event_per_message = self._always_per_message or any(
            s.per_message and not s.tap for s in self._subs)

    # ---------------------------------------------------------------- events
    def emit(self, kind: EventKind, actor: str, queue: str = "", message: Any = None,
             depth: int = 0, detail: str = "") -> TraceEvent | None:
        """Make an event now (Trio's current time) and deliver it (``message`` as its repr).

        Returns:
            The event, or None for a per-message event that only message taps
            wanted (they get the message itself and no event is made).
        """
        if self._taps and kind in PER_MESSAGE:
            now = trio.current_time()
            receive = kind is EventKind.RECEIVE
            for tap in self._taps:
                if not receive or tap.receives:
                    tap.callback(now, kind, queue, message, depth)
            if not self._event_per_message:
                return None
        event = TraceEvent(trio.current_time(), kind, actor, queue,
                           "" if message is None else repr(message), depth, detail)
        self.count += 1
        per_message = kind in PER_MESSAGE
        if not per_message or self._always_per_message:
            # per-message events made only for a subscriber (a console's log) stay out
            # of the hash: watching a run must not change its hash
            if event.time != self._bucket_time:
                self._flush()
                self._bucket_time = event.time
            self._bucket.append(event.key())
        receive = kind is EventKind.RECEIVE
        for sub in tuple(self._subs):
            if sub.tap or (per_message and (
                    not sub.per_message or (receive and not sub.receives))):
                continue
            sub.callback(event)
        return event

    def _flush(self) -> None:
        if self._bucket:
            for key in sorted(self._bucket):
                self._hash.update(key.encode())
                self._hash.update(b"\n")
            self._bucket.clear()

    def hexdigest(self) -> str:
        """The run's trace hash so far (order-independent within one timestamp)."""
        h = self._hash.copy()
        for key in sorted(self._bucket):
            h.update(key.encode())
            h.update(b"\n")
        return h.hexdigest()


class _DropCounter:
    """A callback feeding a bounded channel, counting what did not fit."""

    __slots__ = ("_send", "dropped")

    def __init__(self, send: trio.MemorySendChannel) -> None:
        self._send = send
        self.dropped = 0

    def __call__(self, event: TraceEvent) -> None:
        try:
            self._send.send_nowait(event)
        except (trio.WouldBlock, trio.BrokenResourceError, trio.ClosedResourceError):
            self.dropped += 1


class JsonLinesRecorder:
    """Writes each event as one JSON object per line; subscribe it to a `Trace`.

    Args:
        stream: a text stream open for writing (the caller closes it).
        max_events: stop writing after this many lines (counted in ``skipped``).
    """

    def __init__(self, stream: IO[str], *, max_events: int = 1_000_000) -> None:
        self._stream = stream
        self._max = max_events
        self.written = 0
        self.skipped = 0

    def __call__(self, event: TraceEvent) -> None:
        if self.written >= self._max:
            self.skipped += 1
            return
        record = asdict(event)
        record["kind"] = event.kind.value
        self._stream.write(json.dumps(record, separators=(",", ":")) + "\n")
        self.written += 1


class BatchShuffle(random.Random):
    """`random.Random` whose ``shuffle`` of a list is Python's, draw for draw, in fewer
    calls: the same permutation, the same generator state after it.

    Why: Trio shuffles every batch of runnable tasks (some 65,000 a short game, most of
    them of none or one task), and ``Random.shuffle`` calls ``_randbelow`` per element
    and sets up its loop even for a batch that has nothing to shuffle. This one returns
    at once for fewer than two elements and draws ``getrandbits`` itself, as
    ``_randbelow`` does: ``k`` bits for a bound of ``k`` bits, drawn again while the
    value is not below the bound.
    """

    def shuffle(self, x: list[Any]) -> None:  # type: ignore[override]
        """Shuffle the list ``x`` in place (``random.Random.shuffle``)."""
        n = len(x)
        if n < 2:
            return
        getrandbits = self.getrandbits
        for i in range(n - 1, 0, -1):
            bound = i + 1
            k = bound.bit_length()
            j = getrandbits(k)
            while j >= bound:
                j = getrandbits(k)
            x[i], x[j] = x[j], x[i]


def seed_trio_scheduler(seed: int) -> None:
    """Make Trio's batch order follow ``seed`` (call before ``trio.run``).

    Trio shuffles or reverses each batch of runnable tasks with a module-level
    ``random.Random`` (``trio._core._run._r``) to flush out code that assumes
    an order. Seeding it makes a run's task order, and so a run's trace,
    repeatable for a seed. This touches Trio's private state, on purpose, in
    this one place; it affects every Trio run in the process that follows. The
    generator becomes a `BatchShuffle` (the same draws, a cheaper shuffle).
    """
    from trio._core import _run

    # Ties between tasks waking at the same instant are otherwise broken by
    # object id, which differs between two runs in one process.
    _run._ALLOW_DETERMINISTIC_SCHEDULING = True
    if not isinstance(_run._r, BatchShuffle):
        _run._r = BatchShuffle()
    _run._r.seed(seed)
