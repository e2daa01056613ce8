"""OTP promises beyond the basics, in the style of OTP's supervisor_SUITE: each test
drives a tree on the autojump clock and asserts the exact sequence of events.

Calls tied to the callee's life, noproc and unregistering; self-chosen exits;
ignore and the per-child init hook; ``restarting`` during a restart;
significant children and auto-shutdown.
"""

from __future__ import annotations

import pytest
import trio
import trio.testing

from actors import (
    AUTO_SHUTDOWN,
    IGNORE,
    MAX_INTENSITY,
    Actor,
    ActorState,
    CallFailed,
    ExitKind,
    ExitReason,
    NoProc,
    StartFailed,
    UnknownActor,
    open_actor_system,
)
from supervisors import AutoShutdown, ChildSpec, Restart, SupervisorSpec


class Worker(Actor):
    """Logs its life. Messages: "boom" crashes, "hang" blocks forever, ("stop", kind, term)
    ends it by its own choice; anything else is echoed back."""

    def __init__(self, log: list, tag: str, *, ignore: bool = False,
                 slow_restart: float = 0.0) -> None:
        self.log, self.tag = log, tag
        self.ignore = ignore
        self.slow_restart = slow_restart  # on_start of a restart takes this long [s]

    async def on_start(self):
        if self.ignore:
            self.log.append(("ignore", self.tag))
            return IGNORE
        if self.slow_restart and any(e == ("start", self.tag) for e in self.log):
            await trio.sleep(self.slow_restart)
        self.log.append(("start", self.tag))
        return None

    async def on_stop(self, reason: ExitReason) -> None:
        self.log.append(("stop", self.tag, str(reason)))

    async def handle(self, message):
        if message == "boom":
            raise RuntimeError("boom")
        if message == "hang":
            await trio.sleep_forever()
        if isinstance(message, tuple) and message[0] == "sleep":
            await trio.sleep(message[1])
        if isinstance(message, tuple) and message[0] == "stop":
            self.ctx.stop(*message[1:])
        return message


def child(log: list, tag: str, restart: Restart = Restart.PERMANENT, **kw) -> ChildSpec:
    opts = {k: kw.pop(k) for k in ("shutdown", "significant", "init", "watchdog") if k in kw}
    return ChildSpec(tag, lambda: Worker(log, tag, **kw), restart=restart, **opts)


async def settle() -> None:
    await trio.testing.wait_all_tasks_blocked()


def registered(system, name: str) -> bool:
    """A name is registered while it has a cell that is not closed (retired)."""
    cell = system.whereis(name)
    return cell is not None and not cell.closed


async def call_outcome(system, name: str, request, timeout: float = 30.0) -> tuple:
    """("reply", value) or ("failed", exception type name, reason text), and when [s]."""
    try:
        value = await system.call(name, request, timeout=timeout)
    except CallFailed as exc:
        return ("failed", type(exc).__name__, str(exc.reason), trio.current_time())
    return ("reply", value, trio.current_time())


# ---------------------------------------------------------------- calls tied to the callee
@pytest.mark.trio
async def test_killed_callee_fails_its_caller_in_the_same_pass(autojump_clock) -> None:
    """The supervisor kills an actor holding a call: the caller fails with ``killed`` at the
    instant of the kill, not after its 30 s timeout."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(
            SupervisorSpec([child(log, "a", shutdown=2.0)]), "s")
        async with trio.open_nursery() as nursery:
            outcomes: list = []

            async def caller() -> None:
                outcomes.append(await call_outcome(system, "s/a", "hang"))
            nursery.start_soon(caller)
            await trio.sleep(1.0)
            await sup.terminate_child("a")  # asks, waits 2 s, kills at t = 3
        assert outcomes == [("failed", "CallFailed", "killed", 3.0)]
        assert trio.current_time() == 3.0


@pytest.mark.trio
@pytest.mark.parametrize(("first", "reason", "when"), [
    ("boom", "crash(RuntimeError: boom)", 1.0),
    ("hang", "hung", 3.0),
    (("stop", "shutdown", "bye"), "shutdown(bye)", 1.0),
    (("stop",), "normal", 1.0),
], ids=["crash", "hung", "shutdown_term", "normal"])
async def test_calls_queued_behind_an_exit_fail_with_its_reason(autojump_clock, first, reason,
                                                                when) -> None:
    """Calls waiting in the mailbox when the callee exits fail at that instant with its
    reason; the restarted (permanent) actor keeps its name and answers the next call."""
    log: list = []
    async with open_actor_system() as system:
        await system.start_supervisor(
            SupervisorSpec([child(log, "a", watchdog=2.0)], intensity=10))
        system.send_nowait("a", ("sleep", 1.0))  # busy until t = 1: the rest queues
        system.send_nowait("a", first)
        async with trio.open_nursery() as nursery:
            outcomes: list = []

            async def caller(request) -> None:
                outcomes.append(await call_outcome(system, "a", request))
            for request in ("q1", "q2"):
                nursery.start_soon(caller, request)
        assert outcomes == [("failed", "CallFailed", reason, when)] * 2
        assert await system.call("a", "again", timeout=1) == "again"
        assert [e for e in log if e[0] == "start"] == [("start", "a")] * 2


@pytest.mark.trio
async def test_unregistered_name_is_noproc_for_call_send_and_cast(autojump_clock) -> None:
    """A temporary child that ended is gone for good: call, send and send_nowait raise
    NoProc (an UnknownActor), cast returns False; no time passes."""
    log: list = []
    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([child(log, "t", Restart.TEMPORARY)]))
        system.send_nowait("t", "boom")
        await settle()
        assert system.whereis("t") is None
        with pytest.raises(NoProc) as info:
            await system.call("t", "x", timeout=30)
        assert info.value.reason.kind is ExitKind.NOPROC and trio.current_time() == 0.0
        with pytest.raises(UnknownActor):
            system.send_nowait("t", "x")
        with pytest.raises(NoProc):
            await system.send("t", "x")
        assert await system.cast("t", "x") is False


@pytest.mark.trio
async def test_supervisor_that_gave_up_unregisters_its_children(autojump_clock) -> None:
    """Intensity reached while a sibling holds a call: the sibling is asked to stop,
    killed after its 1 s shutdown timeout, its caller fails ``killed`` at that instant;
    then both names are gone (noproc)."""
    log: list = []
    inner = SupervisorSpec([child(log, "a", shutdown=1.0), child(log, "b")], intensity=0)
    outer = SupervisorSpec([ChildSpec("inner", lambda: inner, type="supervisor",
                                      restart=Restart.TEMPORARY)])
    async with open_actor_system() as system:
        await system.start_supervisor(outer, "root")
        async with trio.open_nursery() as nursery:
            outcomes: list = []

            async def caller() -> None:
                outcomes.append(await call_outcome(system, "root/inner/a", "hang"))
            nursery.start_soon(caller)
            await settle()
            system.send_nowait("root/inner/b", "boom")
        assert outcomes == [("failed", "CallFailed", "killed", 1.0)]
        await settle()
        assert log[-1] == ("stop", "b", "crash(RuntimeError: boom)")
        assert not registered(system, "root/inner/a") and not registered(system, "root/inner/b")
        assert system.whereis("root/inner/a").last_exit.kind is ExitKind.KILLED  # post-mortem
        assert system.statistics("root/inner/a").received == 1
        with pytest.raises(NoProc):
            system.send_nowait("root/inner/a", "x")
        assert await system.cast("root/inner/a", "x") is False
        assert await call_outcome(system, "root/inner/b", "x") == (
            "failed", "NoProc", "noproc", 1.0)


@pytest.mark.trio
async def test_call_waiting_when_the_name_goes_fails_noproc(autojump_clock) -> None:
    """A transient child ends normally with a call still queued behind a message that
    arrived later: the exit fails the queued call (normal); afterwards the name is gone."""
    log: list = []
    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([child(log, "a", Restart.TRANSIENT)]))
        system.send_nowait("a", ("stop",))
        outcome = await call_outcome(system, "a", "late")
        assert outcome == ("failed", "CallFailed", "normal", 0.0)
        await settle()
        assert not registered(system, "a")
        assert (await call_outcome(system, "a", "x"))[:3] == ("failed", "NoProc", "noproc")


# ---------------------------------------------------------------- self-chosen exits
@pytest.mark.trio
@pytest.mark.parametrize(("restart", "stop", "restarted", "reason"), [
    (Restart.PERMANENT, ("stop", "shutdown"), True, "shutdown"),
    (Restart.TRANSIENT, ("stop", "shutdown"), False, "shutdown"),
    (Restart.TRANSIENT, ("stop", "shutdown", {"why": 1}), False, "shutdown({'why': 1})"),
    (Restart.TRANSIENT, ("stop", "normal"), False, "normal"),
    (Restart.TEMPORARY, ("stop", "shutdown", "done"), False, "shutdown(done)"),
], ids=["permanent_shutdown", "transient_shutdown", "transient_shutdown_term",
        "transient_normal", "temporary_shutdown_term"])
async def test_self_chosen_exits_follow_restart_types(autojump_clock, restart, stop,
                                                      restarted, reason) -> None:
    """An actor ends itself with normal, shutdown or {shutdown, term}; the restart type
    decides as for any exit, and on_stop sees the chosen reason."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(SupervisorSpec([child(log, "a", restart)]))
        system.send_nowait("a", stop)
        await settle()
        expected = [("start", "a"), ("stop", "a", reason)]
        assert log == expected + ([("start", "a")] if restarted else [])
        if restart is not Restart.TEMPORARY:
            assert str(sup.which_children()[0].last_exit) == reason


def test_stop_refuses_other_kinds() -> None:
    """Only normal and shutdown are chosen exits; a crash is raised, not chosen."""
    from actors.actor import ActorContext

    ctx = ActorContext.__new__(ActorContext)
    with pytest.raises(ValueError, match="stop kind must be normal or shutdown"):
        ctx.stop("crash")
    with pytest.raises(ValueError, match="a term only with shutdown"):
        ctx.stop("normal", "term")


# ---------------------------------------------------------------- ignore and the init hook
@pytest.mark.trio
async def test_ignore_from_on_start_or_factory_is_no_failure(autojump_clock) -> None:
    """OTP's ignore: the child is not running, its siblings start, its name is not
    registered; a temporary ignored child is dropped."""
    log: list = []
    spec = SupervisorSpec([
        child(log, "a"),
        child(log, "i", ignore=True),
        ChildSpec("f", lambda: IGNORE, restart=Restart.TEMPORARY),
        child(log, "z"),
    ])
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        assert log == [("start", "a"), ("ignore", "i"), ("start", "z")]
        assert [(c.id, c.state) for c in sup.which_children()] == [
            ("a", ActorState.RUNNING), ("i", ActorState.STOPPED), ("z", ActorState.RUNNING)]
        assert not registered(system, "i") and system.whereis("f") is None  # f: dropped


@pytest.mark.trio
async def test_init_hook_runs_before_on_start_for_every_incarnation(autojump_clock) -> None:
    """ChildSpec.init sees the new actor with its ctx (name, system) before on_start,
    at every restart; an async hook is awaited; a raising hook fails the start."""
    log: list = []

    async def init(actor: Actor) -> None:
        log.append(("init", actor.ctx.name, actor.ctx.system is not None))

    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([child(log, "a", init=init)]), "s")
        system.send_nowait("s/a", "boom")
        await settle()
    assert log == [("init", "s/a", True), ("start", "a"),
                   ("stop", "a", "crash(RuntimeError: boom)"),
                   ("init", "s/a", True), ("start", "a"), ("stop", "a", "shutdown")]

    def broken(actor: Actor) -> None:
        raise KeyError("no wiring")

    async with open_actor_system() as system:
        with pytest.raises(StartFailed, match="no wiring"):
            await system.start_supervisor(SupervisorSpec([child([], "a", init=broken)]))


class Flaky(Actor):
    """Starts per a script of outcomes: "ok", "fail" (raises) or "ignore"; "boom" crashes."""

    def __init__(self, log: list, script: list) -> None:
        self.log, self.script = log, script

    async def on_start(self):
        step = self.script.pop(0)
        self.log.append((step, trio.current_time()))
        if step == "fail":
            raise RuntimeError("cannot start")
        return IGNORE if step == "ignore" else None

    async def handle(self, message):
        raise RuntimeError("boom")


@pytest.mark.trio
async def test_failed_restarts_are_retried_until_the_intensity(autojump_clock) -> None:
    """A restart whose start fails counts as another exit: retried at once while within
    the intensity, then the supervisor gives up."""
    log: list = []
    spec = SupervisorSpec([ChildSpec("a", lambda: Flaky(log, script))], intensity=3)
    script = ["ok", "fail", "fail", "ok"]
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        system.send_nowait("a", "x")
        await settle()
        assert [step for step, _ in log] == ["ok", "fail", "fail", "ok"]
        assert sup.which_children()[0].restarts == 3 and sup.exit_reason is None
        system.send_nowait("a", "x")  # a 4th restart within 5 s: gives up
        await sup.wait_stopped()
        assert sup.exit_reason == MAX_INTENSITY


@pytest.mark.trio
async def test_restart_that_ignores_leaves_the_child_stopped(autojump_clock) -> None:
    """A restart whose on_start returns IGNORE: not running, no failure, name unregistered,
    and restart_child starts it again later."""
    log: list = []
    script = ["ok", "ignore", "ok"]
    async with open_actor_system() as system:
        sup = await system.start_supervisor(
            SupervisorSpec([ChildSpec("a", lambda: Flaky(log, script))]))
        system.send_nowait("a", "x")
        await settle()
        assert [(c.state, c.restarts) for c in sup.which_children()] == [
            (ActorState.STOPPED, 1)]
        assert not registered(system, "a") and sup.exit_reason is None
        assert await sup.restart_child("a") == "a"
        assert registered(system, "a")
        assert [step for step, _ in log] == ["ok", "ignore", "ok"]


# ---------------------------------------------------------------- restarting state
@pytest.mark.trio
async def test_which_children_says_restarting_until_the_restart_started(autojump_clock):
    """From the exit until the new incarnation's on_start returned, the child is
    ``restarting`` (not ``stopped``)."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(
            SupervisorSpec([child(log, "a", slow_restart=1.0)]))
        system.send_nowait("a", "boom")
        await trio.sleep(0.5)
        assert sup.which_children()[0].state is ActorState.RESTARTING
        await trio.sleep(1.0)
        assert sup.which_children()[0].state is ActorState.RUNNING


# ---------------------------------------------------------------- significant children
def sig(log: list, tag: str, restart: Restart = Restart.TRANSIENT) -> ChildSpec:
    return child(log, tag, restart, significant=True)


@pytest.mark.trio
@pytest.mark.parametrize(("message", "ends"), [(("stop",), True), (("stop", "shutdown"), True),
                                               ("boom", False)],
                         ids=["normal", "shutdown", "crash"])
async def test_any_significant_ends_the_supervisor(autojump_clock, message, ends) -> None:
    """any_significant: a transient significant child ending normally or with shutdown
    stops the others (reverse order) and the supervisor exits ``shutdown``; a crash is
    restarted instead."""
    log: list = []
    spec = SupervisorSpec([child(log, "a"), sig(log, "s"), child(log, "z")],
                          auto_shutdown=AutoShutdown.ANY_SIGNIFICANT)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        log.clear()
        system.send_nowait("s", message)
        await settle()
        if ends:
            await sup.wait_stopped()
            assert sup.exit_reason == AUTO_SHUTDOWN
            assert sup.exit_reason.kind is ExitKind.SHUTDOWN
            assert log[1:] == [("stop", "z", "shutdown"), ("stop", "a", "shutdown")]
        else:
            assert sup.exit_reason is None and log[-1] == ("start", "s")


@pytest.mark.trio
async def test_all_significant_waits_for_the_last_one(autojump_clock) -> None:
    """all_significant: the supervisor ends when the last significant child ended by
    itself; a terminated significant child does not count as ending by itself."""
    log: list = []
    spec = SupervisorSpec([sig(log, "p", Restart.TEMPORARY), sig(log, "q"), child(log, "w")],
                          auto_shutdown="all_significant")
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec)
        system.send_nowait("p", ("stop",))
        await settle()
        assert sup.exit_reason is None
        await sup.terminate_child("q")
        await settle()
        assert sup.exit_reason is None  # by the supervisor's hand: no auto-shutdown
        await sup.restart_child("q")
        system.send_nowait("q", ("stop", "shutdown"))
        await sup.wait_stopped()
        assert sup.exit_reason == AUTO_SHUTDOWN
        assert log[-1] == ("stop", "w", "shutdown")


def test_significant_needs_auto_shutdown_and_no_permanent() -> None:
    """OTP's bad combinations are refused when the spec is built."""
    with pytest.raises(ValueError, match="a significant child must be transient or temporary"):
        ChildSpec("a", Actor, significant=True)
    with pytest.raises(ValueError, match="significant children need auto_shutdown"):
        SupervisorSpec([ChildSpec("a", Actor, restart="transient", significant=True)])
    with pytest.raises(ValueError, match="auto_shutdown must be one of"):
        SupervisorSpec([], auto_shutdown="sometimes")


@pytest.mark.trio
async def test_nested_auto_shutdown_escalates_as_shutdown(autojump_clock) -> None:
    """A significant supervisor child that auto-shuts down is, for a transient
    parent rule, a normal end: not restarted, and not a failure (no intensity)."""
    log: list = []
    inner = SupervisorSpec([sig(log, "s")], auto_shutdown="any_significant")
    outer = SupervisorSpec([ChildSpec("inner", lambda: inner, type="supervisor",
                                      restart=Restart.TRANSIENT), child(log, "w")], intensity=0)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(outer, "root")
        system.send_nowait("root/inner/s", ("stop",))
        await settle()
        rows = {c.id: c for c in sup.which_children()}
        assert rows["inner"].state is ActorState.STOPPED
        assert rows["inner"].last_exit == AUTO_SHUTDOWN and sup.exit_reason is None
        assert rows["w"].state is ActorState.RUNNING
        assert MAX_INTENSITY != AUTO_SHUTDOWN
