"""OTP supervisor semantics: one test per rule of the contract in `supervisors.supervisor`."""

from __future__ import annotations

import pytest
import trio
import trio.testing

from actors import (
    Actor,
    ActorState,
    ExitKind,
    StartFailed,
    open_actor_system,
)
from supervisors import (
    Backoff,
    ChildSpec,
    ChildType,
    Restart,
    Strategy,
    SupervisorSpec,
    backoff_delay,
    intensity_exceeded,
)


class Worker(Actor):
    """Logs start/stop; "boom" crashes it, "quit" exits normally, ("sleep", s) blocks."""

    def __init__(self, log: list, tag: str, *, fail_start: bool = False,
                 stubborn: float = 0.0) -> None:
        self.log, self.tag = log, tag
        self.fail_start = fail_start
        self.stubborn = stubborn  # on_stop takes this long [s]

    async def on_start(self) -> None:
        if self.fail_start:
            raise RuntimeError(f"{self.tag} cannot start")
        self.log.append(("start", self.tag))

    async def on_stop(self, reason) -> None:
        if self.stubborn:
            await trio.sleep(self.stubborn)
        self.log.append(("stop", self.tag, reason.kind.value))

    async def handle(self, message):
        if message == "boom":
            raise RuntimeError("boom")
        if message == "quit":
            self.ctx.stop()
        return message


def worker(log: list, tag: str, restart: Restart = Restart.PERMANENT, **kw) -> ChildSpec:
    shutdown = kw.pop("shutdown", -1.0)
    return ChildSpec(tag, lambda: Worker(log, tag, **kw), restart=restart, shutdown=shutdown)


async def settle() -> None:
    await trio.testing.wait_all_tasks_blocked()


# ---------------------------------------------------------------- 1. start and stop order
@pytest.mark.trio
async def test_children_start_in_spec_order_and_stop_in_reverse(autojump_clock) -> None:
    """Rule 1: start a, b, c; stop c, b, a."""
    log: list = []
    spec = SupervisorSpec([worker(log, t) for t in "abc"])
    async with open_actor_system() as system:
        await system.start_supervisor(spec)
        assert log == [("start", "a"), ("start", "b"), ("start", "c")]
        log.clear()
    assert log == [("stop", "c", "shutdown"), ("stop", "b", "shutdown"),
                   ("stop", "a", "shutdown")]


@pytest.mark.trio
async def test_failed_start_stops_started_children_and_fails_with_reason(autojump_clock):
    """Rule 1: b fails to start, so a is stopped and start fails naming the reason."""
    log: list = []
    spec = SupervisorSpec([worker(log, "a"), worker(log, "b", fail_start=True), worker(log, "c")])
    async with open_actor_system() as system:
        with pytest.raises(StartFailed) as info:
            await system.start_supervisor(spec, "top")
        assert info.value.reason.kind is ExitKind.START_FAILED
        assert "b cannot start" in str(info.value)
    assert log == [("start", "a"), ("stop", "a", "shutdown")]


class Interrupted(Actor):
    """Ctrl-C arrives while it starts."""

    async def on_start(self) -> None:
        raise KeyboardInterrupt


@pytest.mark.trio
@pytest.mark.parametrize("nested", [False, True], ids=["worker", "in-a-supervisor"])
async def test_an_interrupt_during_a_start_leaves_as_itself_not_as_a_failed_start(
        autojump_clock, nested) -> None:
    """Rule 1: a start is failed by what the child raised (an ``Exception``); a Ctrl-C while
    b starts (or a child of b) travels out of ``start_supervisor`` as the interrupt it is,
    and c never starts."""
    from tui.stopping import is_interrupt, leaves

    log: list = []
    b = ChildSpec("b", Interrupted)
    if nested:
        inner = SupervisorSpec([b])
        b = ChildSpec("inner", lambda: inner, type=ChildType.SUPERVISOR)
    spec = SupervisorSpec([worker(log, "a"), b, worker(log, "c")])
    with pytest.raises(BaseException) as info:  # noqa: PT011 - the interrupt, in groups
        async with open_actor_system() as system:
            await system.start_supervisor(spec, "top")
    assert is_interrupt(info.value), leaves(info.value)
    assert log == [("start", "a")]


# ---------------------------------------------------------------- 2. restart types
@pytest.mark.trio
@pytest.mark.parametrize(
    ("restart", "message", "restarted"),
    [
        (Restart.PERMANENT, "boom", True),
        (Restart.PERMANENT, "quit", True),
        (Restart.TRANSIENT, "boom", True),
        (Restart.TRANSIENT, "quit", False),
        (Restart.TEMPORARY, "boom", False),
        (Restart.TEMPORARY, "quit", False),
    ],
    ids=lambda v: getattr(v, "value", v),
)
async def test_restart_types(autojump_clock, restart, message, restarted) -> None:
    """Rule 2: permanent always, transient only after abnormal exits, temporary never."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(SupervisorSpec([worker(log, "a", restart)]))
        system.send_nowait("a", message)
        await settle()
        assert log.count(("start", "a")) == (2 if restarted else 1)
        ids = [c.id for c in sup.which_children()]
        if restart is Restart.TEMPORARY:
            assert ids == [] and system.whereis("a") is None  # forgotten
        else:
            assert ids == ["a"]


# ---------------------------------------------------------------- 3. strategies
def starts(log: list) -> list[str]:
    return [e[1] for e in log if e[0] == "start"]


@pytest.mark.trio
@pytest.mark.parametrize(
    ("strategy", "expected"),
    [
        (Strategy.ONE_FOR_ONE, [("start", "b")]),
        (Strategy.ONE_FOR_ALL, [("stop", "c", "shutdown"), ("stop", "a", "shutdown"),
                                ("start", "a"), ("start", "b"), ("start", "c")]),
        (Strategy.REST_FOR_ONE, [("stop", "c", "shutdown"), ("start", "b"), ("start", "c")]),
    ],
    ids=lambda v: getattr(v, "value", None),
)
async def test_strategies(autojump_clock, strategy, expected) -> None:
    """Rule 3: which siblings are stopped (reverse order) and restarted (start order)."""
    log: list = []
    spec = SupervisorSpec([worker(log, t) for t in "abc"], strategy=strategy)
    async with open_actor_system() as system:
        await system.start_supervisor(spec)
        log.clear()
        system.send_nowait("b", "boom")
        await settle()
        assert log == [("stop", "b", "crash")] + expected


@pytest.mark.trio
async def test_temporary_bystander_is_not_restarted(autojump_clock) -> None:
    """Rule 3: under one_for_all a temporary sibling is stopped and forgotten."""
    log: list = []
    spec = SupervisorSpec([worker(log, "a"), worker(log, "t", Restart.TEMPORARY)],
                          strategy=Strategy.ONE_FOR_ALL)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        log.clear()
        system.send_nowait("a", "boom")
        await settle()
        assert log == [("stop", "a", "crash"), ("stop", "t", "shutdown"), ("start", "a")]
        assert [c.id for c in sup.which_children()] == ["a"]


# ---------------------------------------------------------------- 4. intensity
def test_intensity_window_is_a_pure_function() -> None:
    """Rule 4: more than MaxR restarts within MaxT; older ones fall out."""
    assert intensity_exceeded([], 0.0, 5.0, 0) == (True, [0.0])
    assert intensity_exceeded([0.0], 1.0, 5.0, 2) == (False, [0.0, 1.0])
    assert intensity_exceeded([0.0, 1.0], 2.0, 5.0, 2) == (True, [0.0, 1.0, 2.0])
    assert intensity_exceeded([0.0, 1.0], 6.0, 5.0, 1) == (True, [1.0, 6.0])
    assert intensity_exceeded([0.0, 1.0], 6.5, 5.0, 1) == (False, [6.5])


@pytest.mark.trio
async def test_intensity_exceeded_stops_children_in_reverse_and_exits_shutdown(autojump_clock):
    """Rule 4: the (MaxR+1)-th restart in the window stops everyone and exits shutdown."""
    log: list = []
    spec = SupervisorSpec([worker(log, t) for t in "abc"], intensity=2, period=10.0)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        for _ in range(3):
            system.send_nowait("b", "boom")
            await settle()
            await trio.sleep(1)
        await sup.wait_stopped()
        assert sup.exit_reason.kind is ExitKind.SHUTDOWN
        assert sup.exit_reason.detail == "reached max restart intensity"
    assert starts(log).count("b") == 3
    assert log[-2:] == [("stop", "c", "shutdown"), ("stop", "a", "shutdown")]


@pytest.mark.trio
async def test_intensity_zero_escalates_on_first_failure(autojump_clock) -> None:
    """Rule 4: MaxR = 0 gives up at the first failure (no restart)."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(SupervisorSpec([worker(log, "a")], intensity=0))
        system.send_nowait("a", "boom")
        await sup.wait_stopped()
    assert starts(log) == ["a"]


@pytest.mark.trio
async def test_restarts_spaced_wider_than_period_never_escalate(autojump_clock) -> None:
    """Rule 4: one failure every 2 s with MaxR=1, MaxT=1 s never reaches the limit."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(
            SupervisorSpec([worker(log, "a")], intensity=1, period=1.0))
        for _ in range(10):
            system.send_nowait("a", "boom")
            await trio.sleep(2)
        assert sup.exit_reason is None
        assert sup.which_children()[0].restarts == 10


# ---------------------------------------------------------------- 5. escalation
@pytest.mark.trio
async def test_escalation_parent_handles_child_supervisor_exit(autojump_clock) -> None:
    """Rule 5: an inner supervisor that gives up is restarted by the outer one's strategy."""
    log: list = []
    inner = SupervisorSpec([worker(log, "x")], intensity=0)
    outer = SupervisorSpec(
        [worker(log, "a"),
         ChildSpec("inner", lambda: inner, type=ChildType.SUPERVISOR),
         worker(log, "z")],
        strategy=Strategy.REST_FOR_ONE, intensity=5)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(outer, "root")
        log.clear()
        system.send_nowait("root/inner/x", "boom")
        await settle()
        rows = {c.id: c for c in sup.which_children()}
        assert rows["inner"].restarts == 1
        assert rows["inner"].last_exit.detail == "reached max restart intensity"
        assert rows["a"].restarts == 0 and rows["z"].restarts == 1
    assert log[:4] == [("stop", "x", "crash"), ("stop", "z", "shutdown"),
                       ("start", "x"), ("start", "z")]


# ---------------------------------------------------------------- 6. shutdown
@pytest.mark.trio
async def test_child_missing_shutdown_timeout_is_killed(autojump_clock) -> None:
    """Rule 6: a child whose on_stop outlasts its shutdown timeout is cancelled: killed."""
    log: list = []
    spec = SupervisorSpec([worker(log, "slow", stubborn=10.0, shutdown=2.0)])
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        sup.stop()
        await sup.wait_stopped()
        assert trio.current_time() == 2.0
        assert sup.which_children()[0].last_exit.kind is ExitKind.KILLED
    assert ("stop", "slow", "shutdown") not in log


@pytest.mark.trio
async def test_supervisor_child_waits_for_its_own_children(autojump_clock) -> None:
    """Rule 6: stopping a supervisor child waits for its slow children (default: forever)."""
    log: list = []
    inner = SupervisorSpec([worker(log, "slow", stubborn=3.0, shutdown=None)])
    spec = SupervisorSpec([ChildSpec("inner", lambda: inner, type=ChildType.SUPERVISOR),
                           worker(log, "last")])
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        sup.stop()
        await sup.wait_stopped()
        assert trio.current_time() == 3.0
    assert log[-2:] == [("stop", "last", "shutdown"), ("stop", "slow", "shutdown")]


# ---------------------------------------------------------------- 7. backoff
def test_backoff_delay_doubles_to_max_with_jitter() -> None:
    """Rule 7: min * 2**(k-1) capped at max, scaled by 1 + jitter * u."""
    b = Backoff(min=0.1, max=1.0, jitter=0.5)
    assert [backoff_delay(b, k, 0.0) for k in (1, 2, 3, 4, 5)] == [0.1, 0.2, 0.4, 0.8, 1.0]
    assert backoff_delay(b, 1, -1.0) == pytest.approx(0.05)
    assert backoff_delay(b, 1, 0.999) == pytest.approx(0.14995)


@pytest.mark.trio
async def test_backoff_delays_restarts_and_resets_after_quiet(autojump_clock) -> None:
    """Rule 7: restarts wait 1, 2, 4 s; after a quiet period the delay is back to 1 s."""
    log: list = []
    restarts: list[float] = []
    spec = SupervisorSpec([worker(log, "a")], intensity=100, period=1.0,
                          backoff=Backoff(min=1.0, max=4.0, jitter=0.0, reset_after=20.0))
    async with open_actor_system() as system:
        system.trace.subscribe(lambda e: restarts.append(e.time) if e.kind == "restart" else 0)
        await system.start_supervisor(spec)
        for at in (0.0, 1.5, 4.0, 40.0):  # the last one after 32 s of quiet
            await trio.sleep(at - trio.current_time())
            system.send_nowait("a", "boom")
        await trio.sleep(5)
    assert restarts == [1.0, 3.5, 8.0, 41.0]
    assert starts(log) == ["a"] * 5


@pytest.mark.trio
async def test_stop_during_backoff_restarts_nothing(autojump_clock) -> None:
    """Rule 7: a supervisor stopped while waiting out a backoff does not restart the child."""
    log: list = []
    spec = SupervisorSpec([worker(log, "a")], backoff=Backoff(min=10.0, max=10.0, jitter=0.0))
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        system.send_nowait("a", "boom")
        await trio.sleep(1)
        assert sup.which_children()[0].state is ActorState.RESTARTING
        sup.stop()
        await sup.wait_stopped()
        assert trio.current_time() == 1.0
    assert starts(log) == ["a"]


@pytest.mark.trio
async def test_backoff_jitter_comes_from_the_seed(autojump_clock) -> None:
    """Rule 7: the same seed gives the same jittered delays, another seed different ones."""
    async def delays(seed: int) -> list[float]:
        times: list[float] = []
        spec = SupervisorSpec([worker([], "a")], intensity=100,
                              backoff=Backoff(min=1.0, max=1.0, jitter=0.5))
        t0 = trio.current_time()
        async with open_actor_system(seed=seed) as system:
            system.trace.subscribe(
                lambda e: times.append(round(e.time - t0, 9)) if e.kind == "restart" else 0)
            await system.start_supervisor(spec)
            for _ in range(3):
                system.send_nowait("a", "boom")
                await trio.sleep(2)
        return times

    a, b, c = await delays(1), await delays(1), await delays(2)
    assert a == b != c
    assert all(0.5 <= t - i * 2 <= 1.5 for i, t in enumerate(a))  # 1 s +- 50 %


# ---------------------------------------------------------------- 8. introspection
@pytest.mark.trio
async def test_which_children_and_snapshot(autojump_clock) -> None:
    """Rule 8: id, state, restarts, last exit; nested tree with mailbox statistics."""
    log: list = []
    inner = SupervisorSpec([worker(log, "x")])
    spec = SupervisorSpec([worker(log, "a", Restart.TRANSIENT),
                           ChildSpec("inner", lambda: inner, type=ChildType.SUPERVISOR)])
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec, "root")
        system.send_nowait("root/a", "boom")
        await settle()
        system.send_nowait("root/a", "quit")
        await settle()
        rows = sup.which_children()
        assert [(r.id, r.state, r.restarts) for r in rows] == [
            ("a", ActorState.STOPPED, 1), ("inner", ActorState.RUNNING, 0)]
        assert rows[0].last_exit.kind is ExitKind.NORMAL
        tree = sup.snapshot()
        assert tree.name == "root"
        assert [n.name for n in tree.children] == ["root/a", "root/inner"]
        assert [n.name for n in tree.children[1].children] == ["root/inner/x"]
        assert tree.children[0].mailbox.received == 2


def test_specs_reject_bad_values() -> None:
    """Clear errors naming the field, for specs built from user input."""
    with pytest.raises(ValueError, match="restart must be one of permanent, transient, "
                                         "temporary, got 'forever'"):
        ChildSpec("a", object, restart="forever")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="id must be a non-empty string without '/'"):
        ChildSpec("a/b", object)
    with pytest.raises(ValueError, match="child ids must be unique, got duplicates \\['a'\\]"):
        SupervisorSpec([ChildSpec("a", object), ChildSpec("a", object)])
    with pytest.raises(ValueError, match="strategy must be one of"):
        SupervisorSpec([], strategy="all_for_none")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="intensity must be an int >= 0, got -1"):
        SupervisorSpec([], intensity=-1)
