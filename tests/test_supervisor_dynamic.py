"""Dynamic children (start_child, terminate_child, restart_child, delete_child,
count_children) and the dynamic supervisor with max_children, in the style of OTP's
supervisor_SUITE: exact event sequences on the autojump clock."""

from __future__ import annotations

import pytest
import trio
import trio.testing

import supervisors
from actors import IGNORE, Actor, ActorState, ExitKind, NoProc, open_actor_system
from supervisors import (
    ChildCounts,
    ChildError,
    ChildSpec,
    DynamicSupervisorSpec,
    Restart,
    Strategy,
    SupervisorSpec,
)


class Worker(Actor):
    """Logs start/stop; "boom" crashes it, "quit" ends it normally; echoes the rest."""

    def __init__(self, log: list, tag: str, fail: bool = False) -> None:
        self.log, self.tag, self.fail = log, tag, fail

    async def on_start(self) -> None:
        if self.fail:
            raise RuntimeError(f"{self.tag} cannot start")
        self.log.append(("start", self.tag))

    async def on_stop(self, reason) -> None:
        self.log.append(("stop", self.tag, str(reason)))

    async def handle(self, message):
        if message == "boom":
            raise RuntimeError("boom")
        if message == "quit":
            self.ctx.stop()
        return (self.tag, message)


def worker(log: list, tag: str, restart: Restart = Restart.PERMANENT, **kw) -> ChildSpec:
    return ChildSpec(tag, lambda: Worker(log, tag, **kw), restart=restart)


async def settle() -> None:
    await trio.testing.wait_all_tasks_blocked()


# ---------------------------------------------------------------- a static supervisor
@pytest.mark.trio
async def test_start_terminate_restart_delete_child(autojump_clock) -> None:
    """The OTP child API in sequence, with count_children after each step."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(SupervisorSpec([worker(log, "a")]), "s")
        assert await sup.start_child(worker(log, "b")) == "s/b"
        assert await system.call("s/b", 1, timeout=1) == ("b", 1)
        assert sup.count_children() == ChildCounts(specs=2, active=2, supervisors=0, workers=2)

        await sup.terminate_child("b")
        assert sup.count_children() == ChildCounts(2, 1, 0, 2)
        assert [(c.id, c.state) for c in sup.which_children()] == [
            ("a", ActorState.RUNNING), ("b", ActorState.STOPPED)]
        with pytest.raises(NoProc):  # terminated: its name is gone until restarted
            system.send_nowait("s/b", 1)

        assert await sup.restart_child("b") == "s/b"
        assert await system.call("s/b", 2, timeout=1) == ("b", 2)
        with pytest.raises(ChildError) as info:
            await sup.delete_child("b")
        assert info.value.reason == "running"

        await sup.terminate_child("b")
        await sup.delete_child("b")
        assert [c.id for c in sup.which_children()] == ["a"]
        assert sup.count_children() == ChildCounts(1, 1, 0, 1)
        assert trio.current_time() == 0.0
    assert log == [("start", "a"), ("start", "b"), ("stop", "b", "shutdown"),
                   ("start", "b"), ("stop", "b", "shutdown"), ("stop", "a", "shutdown")]


@pytest.mark.trio
async def test_child_api_errors_have_otp_reasons(autojump_clock) -> None:
    """already_started, already_present, not_found, a start failure adds nothing,
    and a stopped supervisor refuses."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(SupervisorSpec([worker(log, "a")]))

        async def reason(coro) -> object:
            with pytest.raises(ChildError) as info:
                await coro
            return info.value.reason

        assert await reason(sup.start_child(worker(log, "a"))) == "already_started"
        await sup.terminate_child("a")
        assert await reason(sup.start_child(worker(log, "a"))) == "already_present"
        assert await reason(sup.terminate_child("x")) == "not_found"
        assert await reason(sup.restart_child("x")) == "not_found"
        failure = await reason(sup.start_child(worker(log, "f", fail=True)))
        assert failure.kind is ExitKind.START_FAILED and "f cannot start" in failure.detail
        assert [c.id for c in sup.which_children()] == ["a"] and system.whereis("f") is None
        assert await sup.start_child(ChildSpec("i", lambda: IGNORE)) is None
        assert [(c.id, c.state) for c in sup.which_children()] == [
            ("a", ActorState.STOPPED), ("i", ActorState.STOPPED)]
        sup.stop()
        await sup.wait_stopped()
        assert await reason(sup.start_child(worker(log, "late"))) == "stopped"


@pytest.mark.trio
async def test_dynamic_child_joins_the_strategy(autojump_clock) -> None:
    """A child added by start_child is last in start order: rest_for_one restarts it
    after an earlier sibling's crash, and the supervisor stops it first."""
    log: list = []
    async with open_actor_system() as system:
        sup = await system.start_supervisor(
            SupervisorSpec([worker(log, "a"), worker(log, "b")], strategy=Strategy.REST_FOR_ONE))
        await sup.start_child(worker(log, "c"))
        log.clear()
        system.send_nowait("b", "boom")
        await settle()
        assert log == [("stop", "b", "crash(RuntimeError: boom)"), ("stop", "c", "shutdown"),
                       ("start", "b"), ("start", "c")]
        log.clear()
    assert log == [("stop", "c", "shutdown"), ("stop", "b", "shutdown"),
                   ("stop", "a", "shutdown")]


# ---------------------------------------------------------------- the dynamic supervisor
class Session(Actor):
    """A child made with start_child's arguments."""

    def __init__(self, log: list, rover: str) -> None:
        self.log, self.rover = log, rover

    async def on_start(self) -> None:
        self.log.append(("start", self.rover))

    async def on_stop(self, reason) -> None:
        self.log.append(("stop", self.rover, str(reason)))

    async def handle(self, message):
        if message == "boom":
            raise RuntimeError("boom")
        if message == "bye":
            self.ctx.stop("shutdown", "rover left")
        return (self.rover, message)


@pytest.mark.trio
async def test_dynamic_supervisor_starts_children_on_demand_up_to_max(autojump_clock):
    """Children from one template with their own arguments and ids; max_children bounds
    them; ended children are dropped, freeing room; stop in reverse start order."""
    log: list = []
    spec = DynamicSupervisorSpec(ChildSpec("session", Session, restart=Restart.TRANSIENT),
                                 max_children=2)
    async with open_actor_system() as system:
        sessions = await system.start_supervisor(spec, "sessions")
        assert sessions.which_children() == []
        assert await sessions.start_child(log, "mapper", id="mapper") == "sessions/mapper"
        assert await sessions.start_child(log, rover="hider") == "sessions/session-1"
        with pytest.raises(ChildError) as info:
            await sessions.start_child(log, "seeker")
        assert info.value.reason == "max_children"
        assert await system.call("sessions/session-1", "hi", timeout=1) == ("hider", "hi")

        system.send_nowait("sessions/mapper", "boom")  # transient: restarted
        await settle()
        system.send_nowait("sessions/mapper", "bye")  # {shutdown, term}: dropped
        await settle()
        assert [c.id for c in sessions.which_children()] == ["session-1"]
        assert system.whereis("sessions/mapper") is None
        assert await sessions.start_child(log, "seeker") == "sessions/session-2"
        assert sessions.count_children().active == 2
        for call in (sessions.restart_child("session-1"), sessions.delete_child("session-1")):
            with pytest.raises(ChildError, match="not_supported"):
                await call
        await sessions.terminate_child("session-1")  # dropped, as in simple_one_for_one
        assert [c.id for c in sessions.which_children()] == ["session-2"]
        log_before_stop = list(log)
    assert log_before_stop == [
        ("start", "mapper"), ("start", "hider"),
        ("stop", "mapper", "crash(RuntimeError: boom)"), ("start", "mapper"),
        ("stop", "mapper", "shutdown(rover left)"), ("start", "seeker"),
        ("stop", "hider", "shutdown")]
    assert log[-1] == ("stop", "seeker", "shutdown")


@pytest.mark.trio
async def test_dynamic_supervisor_gives_up_like_any_other(autojump_clock) -> None:
    """Intensity applies across all its children; giving up stops them in reverse order."""
    log: list = []
    spec = DynamicSupervisorSpec(ChildSpec("w", Session), intensity=1, period=10.0)
    async with open_actor_system() as system:
        sup = await system.start_supervisor(spec, "d")
        for rover in ("r1", "r2", "r3"):
            await sup.start_child(log, rover)
        log.clear()
        system.send_nowait("d/w-1", "boom")
        await settle()
        system.send_nowait("d/w-2", "boom")
        await sup.wait_stopped()
        assert sup.exit_reason.detail == "reached max restart intensity"
        assert system.whereis("d/w-3") is None
    assert log == [("stop", "r1", "crash(RuntimeError: boom)"), ("start", "r1"),
                   ("stop", "r2", "crash(RuntimeError: boom)"), ("stop", "r3", "shutdown"),
                   ("stop", "r1", "shutdown")]


def test_dynamic_spec_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match="max_children must be an int >= 1 or None, got 0"):
        DynamicSupervisorSpec(ChildSpec("w", Session), max_children=0)
    with pytest.raises(TypeError, match="child must be a ChildSpec"):
        DynamicSupervisorSpec("w")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="intensity must be an int >= 0"):
        DynamicSupervisorSpec(ChildSpec("w", Session), intensity=-1)


@pytest.mark.trio
async def test_dynamic_supervisor_nests_under_a_static_one(autojump_clock) -> None:
    """A DynamicSupervisorSpec is a valid supervisor child."""
    log: list = []
    dyn = DynamicSupervisorSpec(ChildSpec("w", Session))
    spec = SupervisorSpec([ChildSpec("pool", lambda: dyn, type="supervisor")])
    async with open_actor_system() as system:
        root = await system.start_supervisor(spec, "root")
        pool = root._children["pool"].sup
        assert await pool.start_child(log, "x") == "root/pool/w-1"
        assert await system.call("root/pool/w-1", 1, timeout=1) == ("x", 1)


def test_supervisors_public_names_exist() -> None:
    """The package re-exports the dynamic-children names."""
    for name in ("AutoShutdown", "ChildCounts", "ChildError", "DynamicSupervisor",
                 "DynamicSupervisorSpec", "Supervisor", "SupervisorSpec", "ChildSpec"):
        assert name in supervisors.__all__ and hasattr(supervisors, name)
