"""Trace events, subscribers, the JSON-lines recorder and the run's trace hash."""

from __future__ import annotations

import io
import json
import random

import pytest
import trio
from trio._core import _run

from actors import (
    Actor,
    EventKind,
    JsonLinesRecorder,
    Trace,
    open_actor_system,
    seed_trio_scheduler,
    virtual_clock,
)
from actors.trace import BatchShuffle
from supervisors import Backoff, ChildSpec, SupervisorSpec


def run(fn):
    return trio.run(fn, clock=virtual_clock())


def test_hash_ignores_order_within_one_timestamp() -> None:
    """Simultaneous events hash the same in any order; a change of time changes the hash."""
    async def emit(order: list[str], at: float) -> str:
        trace = Trace()
        await trio.sleep(at)
        for name in order:
            trace.emit(EventKind.CRASH, name)
        await trio.sleep(1)
        trace.emit(EventKind.RESTART, "later")
        return trace.hexdigest()

    a = run(lambda: emit(["x", "y", "z"], 1.0))
    b = run(lambda: emit(["z", "x", "y"], 1.0))
    c = run(lambda: emit(["x", "y", "z"], 2.0))
    d = run(lambda: emit(["x", "y"], 1.0))
    assert a == b
    assert len({a, c, d}) == 3


class Pinger(Actor):
    """Sends random numbers to its peer on a timer; crashes now and then."""

    def __init__(self, peer: str) -> None:
        self.peer = peer

    async def on_start(self) -> None:
        self.ctx.start_timer(0.1, "tick", interval=0.1)

    async def handle(self, message) -> None:
        if message == "tick":
            self.ctx.send_nowait(self.peer, int(self.ctx.rng.integers(0, 100)))
        elif message > 90:
            raise RuntimeError(f"unlucky {message}")


def traced_run(seed: int) -> str:
    seed_trio_scheduler(seed)

    async def main() -> str:
        trace = Trace(per_message=True)
        spec = SupervisorSpec([ChildSpec("a", lambda: Pinger("b")),
                               ChildSpec("b", lambda: Pinger("a"))],
                              intensity=100, backoff=Backoff(min=0.05, max=0.5, jitter=0.5))
        async with open_actor_system(seed=seed, trace=trace) as system:
            await system.start_supervisor(spec)
            await trio.sleep(20)
        assert trace.count > 100
        return trace.hexdigest()

    return run(main)


def test_same_seed_same_trace_hash() -> None:
    """Two runs of one seed give one hash; another seed gives another."""
    assert traced_run(3) == traced_run(3) != traced_run(4)


def test_lifecycle_events_are_always_made_and_recorded_as_json_lines() -> None:
    """Crashes and restarts are traced without per-message subscribers; lines parse as JSON."""
    out = io.StringIO()

    class Bomb(Actor):
        async def handle(self, message) -> None:
            raise RuntimeError("bang")

    async def main() -> None:
        async with open_actor_system(seed=1) as system:
            await system.start_supervisor(SupervisorSpec([ChildSpec("bomb", Bomb)]))
            recorder = JsonLinesRecorder(out, max_events=6)
            system.trace.subscribe(recorder)
            system.send_nowait("bomb", "go")
            await trio.sleep(1)
        assert recorder.skipped > 0

    run(main)
    lines = [json.loads(line) for line in out.getvalue().splitlines()]
    assert len(lines) == 6
    assert [r["kind"] for r in lines[:4]] == ["crash", "poison", "stop", "restart"]
    assert lines[0]["actor"] == "bomb" and lines[0]["detail"] == "RuntimeError: bang"
    assert set(lines[0]) == {"time", "kind", "actor", "queue", "message", "depth", "detail"}


def test_channel_subscriber_is_bounded() -> None:
    """A full subscriber channel drops events and counts them."""
    async def main() -> tuple[int, int]:
        trace = Trace()
        receive, sub = trace.open_channel(3)
        for i in range(5):
            trace.emit(EventKind.FAULT, f"a{i}")
        got = [receive.receive_nowait().actor for _ in range(3)]
        assert got == ["a0", "a1", "a2"]
        sub.close()
        trace.emit(EventKind.FAULT, "after-close")
        with pytest.raises(trio.WouldBlock):
            receive.receive_nowait()
        return sub.dropped, trace.count

    assert run(main) == (2, 6)


def test_a_sends_only_subscriber_gets_no_receive_events() -> None:
    """``receives=False``: sends (and drops) arrive, receive events are not even made;
    another subscriber asking for receives gets both."""
    class Sink(Actor):
        async def handle(self, message) -> None:
            pass

    async def main() -> tuple[list, list]:
        sends_only: list = []
        both: list = []
        async with open_actor_system(seed=1) as system:
            sub = system.trace.subscribe(lambda e: sends_only.append(e.kind),
                                         per_message=True, receives=False)
            await system.start_supervisor(SupervisorSpec([ChildSpec("a", Sink)]))
            system.send_nowait("a", 1)
            await trio.sleep(1)
            assert not system.trace.per_message_receive
            system.trace.subscribe(lambda e: both.append(e.kind), per_message=True)
            system.send_nowait("a", 2)
            await trio.sleep(1)
            sub.close()
        return sends_only, both

    sends_only, both = run(main)
    assert sends_only.count(EventKind.SEND) == 2 and EventKind.RECEIVE not in sends_only
    assert both.count(EventKind.SEND) == 1 and both.count(EventKind.RECEIVE) == 1


class Frozen:
    """A message whose repr is counted (a tap must never ask for it)."""

    reprs = 0

    def __repr__(self) -> str:
        Frozen.reprs += 1
        return "Frozen()"


def test_a_message_tap_gets_the_message_itself_and_no_event_is_made() -> None:
    """A tap sees every send as (time, kind, queue, object, depth) with no repr and no
    TraceEvent; event subscribers still get lifecycle events; closing stops the tap."""
    class Sink(Actor):
        async def handle(self, message) -> None:
            pass

    async def main() -> tuple[list, list, int]:
        tapped: list = []
        events: list = []
        async with open_actor_system(seed=1) as system:
            trace = system.trace
            system.trace.subscribe(lambda e: events.append(e.kind))
            await system.start_supervisor(SupervisorSpec([ChildSpec("a", Sink)]))
            count = trace.count
            sub = trace.tap_messages(lambda *args: tapped.append(args))
            assert trace.per_message and not trace.per_message_receive
            message = Frozen()
            await trio.sleep(2)
            system.send_nowait("a", message)
            await trio.sleep(1)
            made = trace.count - count
            sub.close()
            assert not trace.per_message
            system.send_nowait("a", Frozen())
            await trio.sleep(1)
        return tapped, events, made

    Frozen.reprs = 0
    tapped, events, made = run(main)
    assert len(tapped) == 1
    time, kind, queue, message, depth = tapped[0]
    assert (time, kind, queue, depth) == (2.0, EventKind.SEND, "a", 1)
    assert isinstance(message, Frozen) and Frozen.reprs == 0
    assert made == 0 and EventKind.SEND not in events and EventKind.START in events


def test_a_tap_asking_for_receives_gets_both_and_events_are_made_only_for_subscribers() -> None:
    """``receives=True`` taps receives too; an event subscriber beside a tap still gets
    its TraceEvents (with the repr), the tap its objects."""
    async def main() -> tuple[list, list]:
        trace = Trace()
        tapped: list = []
        events: list = []
        trace.tap_messages(lambda t, kind, q, m, d: tapped.append((kind, m)), receives=True)
        assert trace.per_message_receive
        assert trace.emit(EventKind.SEND, "a", "a", 7, 1) is None
        assert trace.emit(EventKind.RECEIVE, "a", "a", 7, 0) is None
        trace.subscribe(lambda e: events.append((e.kind, e.message)), per_message=True,
                        receives=False)
        trace.emit(EventKind.SEND, "a", "a", 8, 1)
        trace.emit(EventKind.RECEIVE, "a", "a", 8, 0)
        return tapped, events

    tapped, events = run(main)
    assert tapped == [(EventKind.SEND, 7), (EventKind.RECEIVE, 7), (EventKind.SEND, 8),
                      (EventKind.RECEIVE, 8)]
    assert events == [(EventKind.SEND, "8")]


def test_a_tap_does_not_change_the_trace_hash() -> None:
    """Watching every message with a tap leaves the run's hash as it was."""
    def hashed(tap: bool) -> str:
        seed_trio_scheduler(5)

        async def main() -> str:
            trace = Trace()
            seen: list = []
            if tap:
                trace.tap_messages(lambda *args: seen.append(args))
            spec = SupervisorSpec([ChildSpec("a", lambda: Pinger("b")),
                                   ChildSpec("b", lambda: Pinger("a"))], intensity=100)
            async with open_actor_system(seed=5, trace=trace) as system:
                await system.start_supervisor(spec)
                await trio.sleep(10)
            assert (len(seen) > 50) == tap
            return trace.hexdigest()

        return run(main)

    assert hashed(True) == hashed(False)


def test_the_batch_shuffle_is_pythons_draw_for_draw() -> None:
    """Every length and seed: the permutation of `random.Random.shuffle`, and the same
    generator state after it (Trio's later draws stay the same)."""
    for seed in range(60):
        ours, theirs = BatchShuffle(seed), random.Random(seed)
        for n in [0, 1, 2, 3, 5, 8, 17, 33, 2, 1, 4, 64, 7]:
            a, b = list(range(n)), list(range(n))
            ours.shuffle(a)
            theirs.shuffle(b)
            assert a == b
        assert ours.random() == theirs.random()
        assert ours.getstate() == theirs.getstate()


def test_seeding_the_scheduler_gives_trio_a_batch_shuffle() -> None:
    seed_trio_scheduler(3)
    assert isinstance(_run._r, BatchShuffle)
    first = _run._r.random()
    seed_trio_scheduler(3)
    assert _run._r.random() == first
