"""An attached rover is first-class: its telemetry and its faults over the protocol.

`supervisors.remote` runs the rover's own world and tree in the same Trio run
as the server, joined by TCP on loopback; the clock is virtual.
"""

from __future__ import annotations

import trio
import trio.testing

from server.links import parse_link
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors.remote import open_remote_rover
from tests.raw_client import free_port
from tests.test_remote import _idle_nav
from world.scenario import load_scenario


async def _until(pred, events=None, limit_s: float = 30.0):
    with trio.fail_after(limit_s):
        while not pred():
            await trio.sleep(0.1)


def _run_attached(body, *, accept_faults: bool) -> list[str]:
    port = free_port()
    lines: list[str] = []

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"mapper"}))) as server:
                await server.listen_tcp("127.0.0.1", port)
                events = server.subscribe()
                async with open_remote_rover(scenario, "mapper",
                                             parse_link(f"tcp:127.0.0.1:{port}"),
                                             report=lines.append, nav_factory=_idle_nav,
                                             accept_faults=accept_faults) as rover:
                    await body(server, rover, events)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    return lines


def _view(server, rid="mapper"):
    return next((r for r in server.snapshot().rovers if r.id == rid), None)


def test_attached_rover_streams_its_mailboxes_and_tree_to_the_server() -> None:
    """The welcome asks for what the hello offered; the server then holds the rover's
    mailboxes (wifly, motor, lidar, map, nav) and its supervision tree, with their ages."""
    async def body(server, rover, events) -> None:
        await _until(lambda: (v := _view(server)) is not None and v.telemetry is not None
                     and v.telemetry.mailboxes and v.telemetry.tree)
        tm = _view(server).telemetry
        assert set(tm.asked) == {"mailboxes", "tree", "map", "pose", "events"}
        names = [b[0] for b in tm.mailboxes]
        assert names == ["wifly", "motor", "lidar", "map", "nav"]
        assert all(b[2] > 0 for b in tm.mailboxes)  # capacities
        paths = [n[0] for n in tm.tree]
        assert paths[0] == "mapper" and "mapper/nav" in paths
        assert all(n[2] == "running" for n in tm.tree)
        assert tm.ages["mailboxes"] < 2.0
        assert rover.telemetry.stats().bytes > 0
    _run_attached(body, accept_faults=False)


def test_rover_refuses_every_fault_without_the_opt_in() -> None:
    """Without --accept-faults hello lists no faults and a known fault is refused; an
    unknown one is unsupported; the refusal is a tm_event."""
    async def body(server, rover, events) -> None:
        await _until(lambda: _view(server) is not None and _view(server).telemetry)
        assert _view(server).faults == ("link/down", "link/loss", "link/corrupt",
                                        "link/latency")
        server.rover_fault("mapper", "inject", "lidar", "dead", 5.0)
        server.rover_fault("mapper", "inject", "lidar", "melted", 5.0)
        replies = []
        with trio.fail_after(10):
            async for e in events:
                if e.kind == "fault_reply":
                    replies.append((e.data["fault_id"], e.data["result"]))
                    if len(replies) == 2:
                        break
        assert replies == [(1, "refused"), (2, "unsupported")]
        assert not rover.world.active_faults()
        await _until(lambda: any(e["kind"] == "fault_refused"
                                 for e in _view(server).telemetry.events))
    lines = _run_attached(body, accept_faults=False)
    assert any(ln.startswith("fault_refused mapper/lidar dead") for ln in lines)


def test_rover_with_the_opt_in_takes_a_device_fault_and_clears_it_when_it_ends() -> None:
    """--accept-faults: hello lists the catalogue; lidar dead for 3 s is accepted,
    injected in the rover's world, and cleared after 3 s; both are tm_events and lines
    of the rover's own log."""
    async def body(server, rover, events) -> None:
        await _until(lambda: _view(server) is not None and _view(server).telemetry)
        faults = _view(server).faults
        assert "lidar/dead" in faults and "nav/crash" in faults and "link/loss" in faults
        server.rover_fault("mapper", "inject", "lidar", "dead", 3.0)
        with trio.fail_after(10):
            async for e in events:
                if e.kind == "fault_reply":
                    assert e.data["result"] == "accepted"
                    break
        assert [f.kind for f in rover.world.active_faults()] == ["dead"]
        await _until(lambda: {e["kind"] for e in _view(server).telemetry.events}
                     >= {"fault_injected", "fault_cleared"})
        assert not rover.world.active_faults()
        server.rover_fault("mapper", "inject", "nav", "crash")
        await _until(lambda: any(e["kind"] == "restart" for e in _view(server).telemetry.events))
    lines = _run_attached(body, accept_faults=True)
    assert any(ln.startswith("fault_injected mapper/lidar dead") for ln in lines)
    assert any(ln.startswith("fault_cleared mapper/lidar dead") for ln in lines)
