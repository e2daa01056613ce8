"""Trace events, subscribers, the JSON-lines recorder and the run's trace hash."""

from __future__ import annotations

import io
import json

import pytest
import trio

from actors import (
    Actor,
    EventKind,
    JsonLinesRecorder,
    Trace,
    open_actor_system,
    seed_trio_scheduler,
    virtual_clock,
)
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
