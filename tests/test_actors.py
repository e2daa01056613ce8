"""The actor runtime: sending, calls, monitors, poison, watchdog, faults, timers, bursts."""

from __future__ import annotations

import pytest
import trio
import trio.testing

import actors
from actors import (
    Actor,
    ActorState,
    CallFailed,
    CallTimeout,
    EventKind,
    ExitKind,
    UnknownActor,
    open_actor_system,
)
from supervisors import ChildSpec, SupervisorSpec

PUBLIC = [
    "Actor", "ActorContext", "ActorState", "ActorSystem", "BufferPool", "CallFailed",
    "CallTimeout", "Down", "EventKind", "ExitKind", "ExitReason", "HUNG", "InjectedCrash",
    "JsonLinesRecorder", "KILLED", "MAX_INTENSITY", "Mailbox", "MailboxStatistics", "Message",
    "Monitor", "NORMAL", "PoolExhausted", "SHUTDOWN", "Timer", "Trace", "TraceEvent",
    "UnknownActor", "ValueType", "open_actor_system", "real_clock", "scaled_clock",
    "seed_trio_scheduler", "set_rate", "virtual_clock", "NoProc", "NOPROC", "IGNORE",
    "AUTO_SHUTDOWN",
]


def test_public_names_exist() -> None:
    """The package re-exports its promised public names."""
    missing = [n for n in PUBLIC if not hasattr(actors, n)]
    assert missing == []
    assert set(PUBLIC) <= set(actors.__all__)


class Recorder(Actor):
    """Records messages in a shared log; replies to calls; obeys a few commands."""

    def __init__(self, log: list, tag: str = "r") -> None:
        self.log = log
        self.tag = tag

    async def on_start(self) -> None:
        self.log.append((self.tag, "start"))

    async def on_stop(self, reason) -> None:
        self.log.append((self.tag, "stop", reason.kind.value))

    async def handle(self, message):
        if message == "boom":
            raise ValueError("boom")
        if isinstance(message, tuple) and message[0] == "sleep":
            await trio.sleep(message[1])
            return "slept"
        if message == "quit":
            self.ctx.stop()
        self.log.append((self.tag, message))
        return ("reply", message)


def one(factory, **kw) -> SupervisorSpec:
    return SupervisorSpec([ChildSpec("a", factory, **kw)], intensity=10, period=1.0)


@pytest.mark.trio
async def test_call_returns_the_handle_value(autojump_clock) -> None:
    """call() gets handle()'s return value."""
    log: list = []
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder(log)))
        assert await system.call("a", 5, timeout=1) == ("reply", 5)


@pytest.mark.trio
async def test_call_timeout_and_late_reply_never_reaches_caller(autojump_clock) -> None:
    """A reply after the timeout is dropped (traced), the next call gets its own reply."""
    log: list = []
    async with open_actor_system(seed=1) as system:
        late = []
        system.trace.subscribe(lambda e: late.append(e) if e.kind == EventKind.LATE_REPLY else 0)
        await system.start_supervisor(one(lambda: Recorder(log)))
        with pytest.raises(CallTimeout, match="no reply from 'a' within 1 s"):
            await system.call("a", ("sleep", 2), timeout=1)
        assert await system.call("a", "next", timeout=5) == ("reply", "next")
        assert len(late) == 1
        assert trio.current_time() == 2.0


@pytest.mark.trio
async def test_call_fails_fast_when_the_actor_crashes(autojump_clock) -> None:
    """The caller gets CallFailed with the crash reason, not a timeout."""
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder([])))
        with pytest.raises(CallFailed) as info:
            await system.call("a", "boom", timeout=10)
        assert info.value.reason.kind is ExitKind.CRASH
        assert trio.current_time() == 0.0


@pytest.mark.trio
async def test_unknown_names(autojump_clock) -> None:
    """send/call to an unregistered name raise UnknownActor; cast returns False."""
    async with open_actor_system(seed=1) as system:
        with pytest.raises(UnknownActor, match="no actor registered as 'nobody'"):
            await system.send("nobody", 1)
        with pytest.raises(UnknownActor):
            system.send_nowait("nobody", 1)
        with pytest.raises(UnknownActor):
            await system.call("nobody", 1, timeout=1)
        assert await system.cast("nobody", 1) is False


@pytest.mark.trio
async def test_poison_message_is_dropped_and_the_rest_delivered(autojump_clock) -> None:
    """The message being handled at a crash is reported, not redelivered; later ones survive."""
    log: list = []
    async with open_actor_system(seed=1) as system:
        poison = []
        system.trace.subscribe(lambda e: poison.append(e) if e.kind == EventKind.POISON else 0)
        await system.start_supervisor(one(lambda: Recorder(log)))
        for m in (1, "boom", 2, 3):
            system.send_nowait("a", m)
        await trio.sleep(1)
    assert [e.message for e in poison] == ["'boom'"]
    assert log == [("r", "start"), ("r", 1), ("r", "stop", "crash"), ("r", "start"),
                   ("r", 2), ("r", 3), ("r", "stop", "shutdown")]


class PoolReader(Actor):
    """Takes the buffer behind each handle, but crashes on some handles and hangs on others."""

    def __init__(self, pool: actors.BufferPool, crash_on: set, hang_on: set) -> None:
        self.pool = pool
        self.crash_on = crash_on
        self.hang_on = hang_on

    async def handle(self, handle):
        if handle in self.crash_on:
            raise ValueError("boom")
        if handle in self.hang_on:
            await trio.sleep(10)
        self.pool.take(handle)

    def discard(self, handle) -> None:
        self.pool.take(handle)


@pytest.mark.trio
async def test_dropped_poison_and_hung_messages_release_their_pool_buffers(autojump_clock):
    """discard() sees the poison of a crash and of a hang, so no pool slot leaks."""
    pool = actors.BufferPool(8)
    handles = [pool.put(("scan", i)) for i in range(4)]
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(
            one(lambda: PoolReader(pool, {handles[1]}, {handles[2]}), watchdog=1.0))
        for h in handles:
            system.send_nowait("a", h)
        await trio.sleep(5)
        assert pool.statistics().in_use == 0
        assert pool.statistics().takes == 4


@pytest.mark.trio
async def test_a_raising_discard_is_traced_and_the_actor_still_restarts(autojump_clock):
    """A broken discard hook cannot hide the crash or stop the restart."""

    class Broken(Recorder):
        def discard(self, message) -> None:
            raise KeyError("gone")

    async with open_actor_system(seed=1) as system:
        poison = []
        system.trace.subscribe(lambda e: poison.append(e.message) if e.kind == EventKind.POISON
                               else 0)
        await system.start_supervisor(one(lambda: Broken([])))
        system.send_nowait("a", "boom")
        with pytest.raises(CallFailed) as info:  # queued behind the crash: fails with it
            await system.call("a", "queued", timeout=1)
        assert info.value.reason.kind is ExitKind.CRASH
        assert await system.call("a", "alive", timeout=1) == ("reply", "alive")
    assert poison == ["'boom'", "'boom'"]


@pytest.mark.trio
async def test_mailbox_outlives_the_actor(autojump_clock) -> None:
    """Messages sent while the actor restarts (with backoff) land and are handled."""
    from supervisors import Backoff

    log: list = []
    spec = SupervisorSpec([ChildSpec("a", lambda: Recorder(log))],
                          backoff=Backoff(min=1.0, max=1.0, jitter=0.0))
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(spec)
        system.send_nowait("a", "boom")
        await trio.sleep(0.5)
        assert system.whereis("a").state is ActorState.RESTARTING
        system.send_nowait("a", "while-down")
        await trio.sleep(1)
        assert ("r", "while-down") in log


@pytest.mark.trio
async def test_watchdog_restarts_a_hung_actor(autojump_clock) -> None:
    """Handling longer than the deadline cancels the actor with reason hung."""
    log: list = []
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder(log), watchdog=0.5))
        mon = system.monitor("a")
        system.send_nowait("a", ("sleep", 10))
        down = await mon.receive()
        assert down.reason.kind is ExitKind.HUNG
        assert down.time == 0.5
        assert await system.call("a", "alive", timeout=1) == ("reply", "alive")


@pytest.mark.trio
async def test_inject_hang_fires_the_watchdog(autojump_clock) -> None:
    """inject_hang blocks the actor at a checkpoint so its watchdog fires."""
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder([]), watchdog=1.0))
        mon = system.monitor("a")
        system.inject_hang("a", 5)
        down = await mon.receive()
        assert (down.reason.kind, down.time) == (ExitKind.HUNG, 1.0)


@pytest.mark.trio
async def test_inject_crash_on_an_idle_actor(autojump_clock) -> None:
    """inject_crash takes effect at once on an idle actor; it is restarted."""
    async with open_actor_system(seed=1) as system:
        sup = await system.start_supervisor(one(lambda: Recorder([])))
        mon = system.monitor("a")
        system.inject_crash("a")
        down = await mon.receive()
        assert down.reason.kind is ExitKind.CRASH
        assert "InjectedCrash" in down.reason.detail
        await trio.testing.wait_all_tasks_blocked()
        assert sup.which_children()[0].restarts == 1


@pytest.mark.trio
async def test_flood_counts_drops(autojump_clock) -> None:
    """flood() sends n with send_nowait; what does not fit is dropped and counted."""
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder([]), mailbox=8))
        accepted = system.flood("a", 20, "x")
        assert accepted == 8
        assert system.statistics("a").dropped == 12


@pytest.mark.trio
async def test_normal_exit_via_ctx_stop_is_seen_by_monitor(autojump_clock) -> None:
    """ctx.stop() exits normal; the monitor gets Down(name, normal)."""
    from supervisors import Restart

    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder([]), restart=Restart.TRANSIENT))
        with system.monitor("a") as mon:
            system.send_nowait("a", "quit")
            down = await mon.receive()
        assert (down.name, down.reason.kind) == ("a", ExitKind.NORMAL)


class Ticker(Actor):
    def __init__(self, log: list) -> None:
        self.log = log

    async def on_start(self) -> None:
        self.ctx.start_timer(1.0, "tick", interval=1.0)

    async def handle(self, message) -> None:
        self.log.append((trio.current_time(), message))
        if len(self.log) == 3:
            raise RuntimeError("third tick")


@pytest.mark.trio
@pytest.mark.parametrize("service", [False, True], ids=["task_timers", "timer_service"])
async def test_timers_tick_and_stop_with_the_actor(autojump_clock, service: bool) -> None:
    """A periodic timer posts to the actor's own mailbox and dies with its incarnation."""
    log: list = []
    async with open_actor_system(seed=1, timer_service=service) as system:
        spec = SupervisorSpec([ChildSpec("t", lambda: Ticker(log))], intensity=0)
        sup = await system.start_supervisor(spec)
        await sup.wait_stopped()
        # the supervisor gave up at the crash; had the timer survived, ticks would continue
        await trio.sleep(5)
    assert log == [(1.0, "tick"), (2.0, "tick"), (3.0, "tick")]


class Timers(Actor):
    """Starts the timers it is given at start; logs (time, tick); ("cancel", name) cancels
    one, ("start", name, delay) starts a one-shot."""

    def __init__(self, log: list, timers: list[tuple[str, float, float | None]]) -> None:
        self.log, self.timers, self.running = log, timers, {}

    async def on_start(self) -> None:
        for name, delay, interval in self.timers:
            self.running[name] = self.ctx.start_timer(delay, name, interval=interval)

    async def handle(self, message) -> None:
        if isinstance(message, tuple):
            if message[0] == "start":
                self.running[message[1]] = self.ctx.start_timer(message[2], message[1])
            else:
                self.running[message[1]].cancel()
            return
        self.log.append((trio.current_time(), message))


@pytest.mark.trio
async def test_timer_service_orders_same_instant_ticks_and_wakes_for_a_sooner_timer(
        autojump_clock) -> None:
    """Ticks due together arrive in start order; a timer started while the service sleeps
    toward a later deadline still fires on time; a cancelled timer stops; one-shots end."""
    log: list = []
    async with open_actor_system(seed=1, timer_service=True) as system:
        spec = SupervisorSpec([ChildSpec("far", lambda: Timers([], [("far", 100.0, None)])),
                               ChildSpec("t", lambda: Timers(log, [
                                   ("b", 0.5, 0.5), ("a", 0.5, 0.5), ("once", 0.75, None)]))])
        await system.start_supervisor(spec)
        await trio.sleep(1.1)
        system.send_nowait("t", ("cancel", "b"))
        system.send_nowait("t", ("start", "late", 0.2))  # the service sleeps toward 1.5
        await trio.sleep(1.0)
        actor = system.whereis("t").actor
        assert actor.running["once"].cancelled and actor.running["b"].cancelled
        assert not actor.running["a"].cancelled
    assert log == [(0.5, "b"), (0.5, "a"), (0.75, "once"), (1.0, "b"), (1.0, "a"),
                   (1.3, "late"), (1.5, "a"), (2.0, "a")]


@pytest.mark.trio
async def test_timer_service_stops_timers_of_a_killed_incarnation(autojump_clock) -> None:
    """A restarted actor's old timers stop (one tick stream, not two)."""
    log: list = []
    async with open_actor_system(seed=1, timer_service=True) as system:
        spec = SupervisorSpec([ChildSpec("t", lambda: Timers(log, [("x", 1.0, 1.0)]))])
        await system.start_supervisor(spec)
        await trio.sleep(1.5)
        system.inject_crash("t")  # idle: crashes at once, restarted at 1.5
        await trio.sleep(2.2)
    assert log == [(1.0, "x"), (2.5, "x"), (3.5, "x")]


class Batcher(Actor):
    def __init__(self, bursts: list) -> None:
        self.bursts = bursts

    async def handle_burst(self, messages: list) -> None:
        if "bad" in messages:
            raise RuntimeError("bad burst")
        self.bursts.append(list(messages))

    async def handle(self, message):
        return ("single", message)


@pytest.mark.trio
async def test_handle_burst_gets_drained_bursts_and_whole_burst_is_poison(autojump_clock):
    """Waiting messages arrive as one burst; a failing burst is dropped as a whole."""
    bursts: list = []
    async with open_actor_system(seed=1, max_burst=4) as system:
        poison = []
        system.trace.subscribe(lambda e: poison.append(e) if e.kind == EventKind.POISON else 0)
        await system.start_supervisor(one(lambda: Batcher(bursts)))
        for i in range(6):
            system.send_nowait("a", i)
        await trio.testing.wait_all_tasks_blocked()
        assert bursts == [[0, 1, 2, 3], [4, 5]]
        assert await system.call("a", "q", timeout=1) == ("single", "q")
        for m in ("x", "bad", "y"):
            system.send_nowait("a", m)
        await trio.testing.wait_all_tasks_blocked()
        system.send_nowait("a", "z")
        await trio.testing.wait_all_tasks_blocked()
    assert poison[0].message == "['x', 'bad', 'y']"
    assert bursts[-1] == ["z"]


@pytest.mark.trio
async def test_actor_rng_is_seeded_per_name(autojump_clock) -> None:
    """Same seed and name give the same stream; another seed differs."""
    draws = []
    for seed in (7, 7, 8):
        async with open_actor_system(seed=seed) as system:
            await system.start_supervisor(one(lambda: Recorder([])))
            draws.append(system.whereis("a").rng.integers(0, 2**32, 4).tolist())
    assert draws[0] == draws[1] != draws[2]


@pytest.mark.trio
async def test_fault_hooks_check_their_arguments(autojump_clock) -> None:
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(one(lambda: Recorder([])))
        with pytest.raises(ValueError, match="seconds must be > 0, got 0"):
            system.inject_hang("a", 0)
        with pytest.raises(ValueError, match="n must be >= 0, got -1"):
            system.flood("a", -1, "x")
        with pytest.raises(ValueError, match="timeout must be > 0"):
            await system.call("a", 1, timeout=0)
        with pytest.raises(UnknownActor):
            system.inject_crash("zzz")
