"""Link faults the server applies to an attached rover's frames (`server.link_faults`)."""

from __future__ import annotations

import re

import pytest
import trio
import trio.testing

from server.link_faults import LINK_FAULTS, LinkFaultBook, check_link_fault
from server.protocol import make_frame
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover, attach_outside, memory_pipe
from tui.serve_console import parse_command_line, run_fault
from world.faults import DEVICE_FAULTS


def test_link_faults_are_the_simulated_wiflys_kinds_and_parameters() -> None:
    """The server's link faults and the world's WiFly device faults are one catalogue."""
    assert LINK_FAULTS == DEVICE_FAULTS["wifly"]


def test_check_link_fault_names_what_is_wrong() -> None:
    """A bad kind, parameter or duration is one clear error."""
    assert check_link_fault("loss", 10, {"percent": 30}) == {"percent": 30.0}
    with pytest.raises(ValueError, match="link fault kind must be one of down, loss, corrupt, "
                                         "latency, got 'melt'"):
        check_link_fault("melt", 0, {})
    with pytest.raises(ValueError, match="has no parameter 'ratio'"):
        check_link_fault("loss", 0, {"ratio": 1})
    with pytest.raises(ValueError, match="duration"):
        check_link_fault("down", -1, {})


def test_book_drops_corrupts_and_cuts_lines_from_its_seeded_generator() -> None:
    """Loss drops about its share of lines, the same ones for the same seed; corruption
    keeps every newline; down drops all; an empty book passes lines untouched."""
    lines = [b'{"cmd":"heartbeat","type":"beat","data":null}\n'] * 2000
    empty = LinkFaultBook(1)
    assert empty.apply(lines) is lines
    a, b = LinkFaultBook(7), LinkFaultBook(7)
    a.add("loss", 0.0, 0.0, {"percent": 30})
    b.add("loss", 0.0, 0.0, {"percent": 30})
    kept = a.apply(lines)
    assert len(kept) == len(b.apply(lines))
    assert 0.25 < 1 - len(kept) / len(lines) < 0.35
    c = LinkFaultBook(3)
    c.add("corrupt", 0.0, 0.0, {"per_byte": 0.2})
    out = c.apply(lines[:50])
    assert c.corrupted > 0 and all(x.count(b"\n") == 1 and x.endswith(b"\n") for x in out)
    d = LinkFaultBook(1)
    d.add("down", 0.0, 2.0, {})
    assert d.apply(lines) == [] and d.dropped == len(lines)
    assert [f.kind for f in d.expire(2.0)] == ["down"] and not d


def test_thirty_percent_loss_for_60_s_loses_no_frame_both_ways() -> None:
    """30 % of the frames lost both ways for 60 s on an attached rover's link: every
    reliable frame still arrives exactly once and in order, by resending."""
    delivered: list[int] = []
    seen: dict = {}

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"m1"}))) as server:
                server.observe_frames(lambda rid, role, f: delivered.append(f.seq or 0)
                                      if f.cmd == "map_request" else None)
                rover = FakeRover("m1", "hider")
                async with trio.open_nursery() as nursery:
                    await attach_outside(server, nursery, rover)
                    text = server.rover_fault("m1", "inject", "link", "loss", 60.0,
                                              {"percent": 30})
                    assert text == "link fault loss on m1 for 60 s"
                    for _ in range(40):
                        rover.session.send(make_frame("map_request"))
                        server.rover_fault("m1", "inject", "lidar", "dead", 1.0)
                        await trio.sleep(1.0)
                    await trio.sleep(60)
                    view = server.snapshot().rovers[0]
                    seen["server_resent"] = view.stats.resent
                    seen["rover_resent"] = rover.session.stats(trio.current_time()).resent
                    seen["faults"] = [f.data["fault_id"] for f in rover.received
                                      if f.cmd == "fault"]
                    seen["dropped"] = server._rovers["m1"].link_faults.dropped
                    seen["cleared"] = not server._rovers["m1"].link_faults
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert delivered == list(range(1, 41))
    assert seen["faults"] == list(range(1, 41))
    assert seen["server_resent"] > 0 and seen["rover_resent"] > 0 and seen["dropped"] > 20
    assert seen["cleared"]


def test_link_faults_refused_for_a_simulated_rover_and_unknown_ids() -> None:
    """A rover simulated in the server's process is broken through the world, not here."""
    async def main() -> None:
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig()) as server:
                rover = FakeRover("mapper", "mapper")
                receive, send, _ = memory_pipe(server.attach_memory)
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(rover.run, receive, send)
                    with trio.fail_after(5):
                        while not rover.welcomed:
                            await trio.sleep(0.1)
                    with pytest.raises(ValueError, match="simulated here"):
                        server.rover_fault("mapper", "inject", "link", "down")
                    with pytest.raises(ValueError, match="no attached rover 'x'"):
                        server.rover_fault("x", "inject", "link", "down")
                    assert server.rover_fault_catalogue("mapper") == ()
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))


def test_serve_prompt_parses_fault_and_clear_lines() -> None:
    """``fault ROVER/TARGET KIND [DURATION] [NAME=VALUE ...]`` and ``clear ROVER/TARGET``."""
    assert parse_command_line("fault mapper/link loss 60 percent=30") == ("fault", {
        "rover": "mapper", "target": "link", "kind": "loss", "duration_s": 60.0,
        "params": {"percent": 30.0}})
    assert parse_command_line("fault m1/lidar dead")[1]["duration_s"] == 0.0
    assert parse_command_line("clear mapper/link") == ("clear", {
        "rover": "mapper", "target": "link", "kind": "*"})
    for bad, message in (("fault mapper", "usage: fault ROVER/TARGET KIND"),
                         ("fault mapper/link loss soon", "DURATION must be a number"),
                         ("fault mapper/link loss 5 percent", "is not NAME=NUMBER"),
                         ("clear mapper/link a b", "usage: clear ROVER/TARGET [KIND]")):
        with pytest.raises(ValueError, match=re.escape(message)):
            parse_command_line(bad)


def test_serve_prompt_fault_reaches_an_attached_rovers_link_and_clear_ends_it() -> None:
    """From the prompt, by role: a link fault on the attached rover, then cleared."""
    out: list[str] = []

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"m1"}))) as server:
                async with trio.open_nursery() as nursery:
                    await attach_outside(server, nursery, FakeRover("m1", "mapper"))
                    for line in ("fault mapper/link latency 0 added_s=0.5",
                                 "clear mapper/link"):
                        name, kw = parse_command_line(line)
                        out.append(run_fault(server, None, name, kw))
                        out.append(str([f.kind for f in server.link_faults_of("m1")]))
                    with pytest.raises(ValueError, match="link fault kind must be"):
                        run_fault(server, None, *parse_command_line("fault m1/link melt"))
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert out == ["link fault latency on m1 until cleared", "['latency']",
                   "1 link fault(s) cleared on m1", "[]"]
