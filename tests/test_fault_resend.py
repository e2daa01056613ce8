"""A ``fault`` the server sends again (after a restart) is answered again, never applied twice."""

from __future__ import annotations

import pytest
import trio

from actors import BufferPool, open_actor_system
from actors.firmware.drivers.wifly import Wifly
from actors.firmware.fault_port import AnsweredFaults
from server.protocol import FaultCommand, make_frame, read_data
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors import ChildSpec, SupervisorSpec
from tests.raw_client import Outside, hello

from .test_fw_lidar import Recorder
from .test_fw_motor import FakeHardware
from .test_fw_wifly import FakeServer


class CountingPort:
    """A `FaultPort` that accepts everything and records what it applied."""

    def __init__(self) -> None:
        self.applied: list[FaultCommand] = []

    def catalogue(self) -> tuple[str, ...]:
        return ("lidar/dead",)

    def apply(self, command: FaultCommand) -> tuple[str, str]:
        self.applied.append(command)
        return "accepted", f"{command.kind} on {command.target} (#{len(self.applied)})"


def _fault(fault_id: int, kind: str = "dead") -> dict:
    return {"fault_id": fault_id, "op": "inject", "target": "lidar", "kind": kind,
            "duration": 3.0}


@pytest.mark.trio
async def test_a_resent_fault_is_answered_again_and_not_applied_twice(autojump_clock) -> None:
    """The same fault in a new frame gets the first reply again and is not applied; the
    same id with another request is a new fault (a server that numbers afresh)."""
    hw, pool, log, port = FakeHardware(), BufferPool(64), [], CountingPort()
    tree = SupervisorSpec([
        ChildSpec("nav", lambda: Recorder(log, pool)),
        ChildSpec("wifly", lambda: Wifly(hw, pool, rover_id="hider-1", role="hider",
                                         faults=port), mailbox=256)])
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        server = FakeServer(hw)
        nursery.start_soon(server.run)
        await system.start_supervisor(tree, "hider")
        await trio.sleep(1.0)
        for data in (_fault(1), _fault(1), _fault(1, "blind"), _fault(2)):
            server.session.send(make_frame("fault", data))
            await trio.sleep(1.0)
        nursery.cancel_scope.cancel()
    replies = [read_data(f) for f in server.got if f.cmd == "fault_reply"]
    assert [(r.fault_id, r.detail) for r in replies] == [
        (1, "dead on lidar (#1)"), (1, "dead on lidar (#1)"), (1, "blind on lidar (#2)"),
        (2, "dead on lidar (#3)")]
    assert [(c.fault_id, c.kind) for c in port.applied] == [(1, "dead"), (1, "blind"),
                                                            (2, "dead")]


def test_answered_faults_are_bounded_and_forget_the_oldest() -> None:
    """Past its capacity the memory forgets the oldest id: that fault, sent again, is
    applied again; a remembered one is not."""
    memory, applied = AnsweredFaults(capacity=3), []

    def apply(command: FaultCommand) -> tuple[str, str]:
        applied.append(command.fault_id)
        return "accepted", str(command.fault_id)

    for fid in range(1, 6):
        memory.answer(FaultCommand(**_fault(fid)), apply)
    assert len(memory) == 3
    assert memory.answer(FaultCommand(**_fault(5)), apply) == ("accepted", "5")
    memory.answer(FaultCommand(**_fault(1)), apply)
    assert applied == [1, 2, 3, 4, 5, 1] and memory.duplicates == 1
    with pytest.raises(ValueError, match="capacity must be at least 1, got 0"):
        AnsweredFaults(capacity=0)


def test_a_server_numbers_its_faults_past_those_its_store_has_sent(tmp_path) -> None:
    """A later server on the same store does not reuse a fault id a rover may remember."""
    path = tmp_path / "hideseek.db"
    with Store(path) as store:
        store.log_event("fault_sent", t=0.0, rover="m1", data={"fault_id": 41, "op": "inject"})
        store.log_event("fault_sent", t=1.0, rover="m1", data={"fault_id": 7, "op": "inject"})

    async def main() -> str:
        with Store(path) as store:
            assert store.last_fault_id() == 41
            async with open_server(store, ServerConfig(rovers=frozenset({"m1"}))) as s:
                x = Outside(s)
                x.send(hello("m1", "mapper"))
                await trio.sleep(0.2)
                return s.rover_fault("m1", "inject", "lidar", "dead", 3.0)

    assert trio.run(main).startswith("fault 42 sent to m1")
    assert Store(":memory:").last_fault_id() == 0
