"""Telemetry and fault frames on the wire: schemas, bounds, unreliability, the byte budget."""

from __future__ import annotations

import pytest
import trio
import trio.testing

from server.protocol import (
    MAX_LINE_BYTES,
    Fault,
    Frame,
    FrameError,
    ReliableSession,
    TelemetryLane,
    encode_frame,
    make_frame,
    read_data,
    split_cells,
)
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover, memory_pipe


def _mailboxes(t: float, n: int = 5) -> Frame:
    return make_frame("tm_mailboxes", {"t": t, "boxes": [[f"box{i}", 1, 16, 2.5, 0]
                                                         for i in range(n)]})


@pytest.mark.parametrize(("cmd", "data", "field"), [
    ("tm_mailboxes", {"t": 1.0, "boxes": [["a", 0, 1, 0.0, 0]] * 65}, "boxes"),
    ("tm_mailboxes", {"t": 1.0, "boxes": [["a", -1, 1, 0.0, 0]]}, "boxes"),
    ("tm_tree", {"t": 1.0, "nodes": [["m", "worker", "dancing", 0, None]]}, "nodes"),
    ("tm_tree", {"t": 1.0, "nodes": [["m", "worker", "running", 0, "x" * 81]]}, "nodes"),
    ("tm_map", {"t": 1.0, "nx": 2, "ny": 2, "resolution_cm": 5.0, "origin_cm": [0, 0],
                "cells": [[0, 3]]}, "cells"),
    ("tm_pose", {"t": 1.0, "x": 0, "y": 0, "heading": 0, "sx": -1, "sy": 0, "sheading": 0},
     "sx"),
    ("tm_event", {"t": 1.0, "kind": "explode", "path": "m/nav"}, "kind"),
    ("fault", {"fault_id": 1, "op": "break", "target": "lidar", "kind": "dead"}, "op"),
    ("fault", {"fault_id": 1, "op": "inject", "target": "lidar", "kind": "dead",
               "params": {f"p{i}": 1 for i in range(9)}}, "params"),
    ("fault_reply", {"fault_id": 1, "result": "maybe"}, "result"),
])
def test_telemetry_and_fault_frames_out_of_bounds_are_bad_data(cmd, data, field) -> None:
    """Every list, string and number of the new frames is bounded: beyond it, bad_data
    naming the field."""
    spec_type = {"tm_mailboxes": "mailboxes", "tm_tree": "tree", "tm_map": "map_delta",
                 "tm_pose": "pose_spread", "tm_event": "event", "fault": "inject",
                 "fault_reply": "fault_reply"}[cmd]
    with pytest.raises(FrameError) as err:
        read_data(Frame(cmd, spec_type, data))
    assert err.value.fault == Fault.BAD_DATA and field in err.value.detail


def test_hello_and_welcome_carry_streams_faults_and_the_share() -> None:
    """The new hello and welcome fields are optional and bounded."""
    hello = read_data(make_frame("hello", {"id": "m", "role": "mapper",
                                           "streams": ["tree", "map"],
                                           "faults": ["lidar/dead", "nav/crash"]}))
    assert hello.streams == ["tree", "map"] and hello.faults == ["lidar/dead", "nav/crash"]
    assert read_data(make_frame("hello", {"id": "m", "role": "mapper"})).streams is None
    with pytest.raises(ValueError):
        make_frame("hello", {"id": "m", "role": "mapper", "streams": ["video"]})
    with pytest.raises(ValueError):
        make_frame("welcome", {"server": "s", "heartbeat_s": 1.0, "down_after_s": 5.0,
                               "seq_base": 1, "telemetry_share": 1.5})


def test_telemetry_is_unreliable_and_a_telemetry_frame_with_seq_is_refused() -> None:
    """tm_* frames are queued without seq; one that arrives with a seq is neither
    acknowledged nor delivered."""
    a = ReliableSession()
    a.send(_mailboxes(1.0))
    line = a.transmit(0.0)
    assert b'"seq"' not in line and a.stats(0.0).unacked == 0
    b = ReliableSession()
    with pytest.raises(FrameError) as err:
        b.receive(Frame("tm_mailboxes", "mailboxes", {"t": 1.0, "boxes": []}, seq=1), 0.0)
    assert err.value.fault == Fault.BAD_FRAME and b.ack_value == 0


def test_lane_sends_only_what_was_asked_and_the_newest_of_a_stream() -> None:
    """Before a welcome asks for a stream, offers are ignored; a newer frame of a
    stream replaces one not sent yet; link down (configure {}) stops everything."""
    lane = TelemetryLane(5760.0)
    lane.offer("mailboxes", [_mailboxes(1.0)], 0.0)
    assert not lane.has_queued()
    lane.configure({"mailboxes": 1.0}, 0.25)
    assert lane.wanted("mailboxes", 0.0) and not lane.wanted("tree", 0.0)
    lane.offer("mailboxes", [_mailboxes(1.0)], 0.0)
    assert not lane.wanted("mailboxes", 0.5)
    lane.offer("mailboxes", [_mailboxes(2.0)], 0.5)
    out = lane.take(0.5)
    assert out.count(b"\n") == 1 and b'"t":2.0' in out and lane.stats().replaced == 1
    lane.configure({})
    lane.offer("mailboxes", [_mailboxes(3.0)], 1.0)
    assert not lane.has_queued()


def test_lane_keeps_telemetry_within_its_share_of_the_link() -> None:
    """Offered far more than the budget for 100 s, the lane sends at most the share of
    the link's bytes (plus one line), and drops the rest unsent."""
    lane = TelemetryLane(5760.0)
    lane.configure({"mailboxes": 0.0, "events": 0.0}, 0.25)
    sent = 0
    for step in range(10_000):  # every 10 ms
        now = step * 0.01
        lane.offer("mailboxes", [_mailboxes(now, 20)], now)
        lane.offer("events", [make_frame("tm_event", {"t": now, "kind": "restart",
                                                      "path": "m/nav"})], now)
        sent += len(lane.take(now))
    assert sent <= 0.25 * 5760.0 * 100 + MAX_LINE_BYTES
    assert sent >= 0.9 * 0.25 * 5760.0 * 100
    assert lane.stats().replaced > 0 and lane.stats().dropped > 0


def test_split_cells_fits_every_line() -> None:
    """A big map delta is cut into frames that each fit 1024 bytes."""
    cells = [(9_000_000 + i, 2) for i in range(1000)]
    frames = split_cells(cells, {"nx": 4096, "ny": 4096, "resolution_cm": 5.0,
                                 "origin_cm": [-100000.0, -100000.0]}, 123456.789)
    assert sum(len(f.data["cells"]) for f in frames) == 1000
    assert all(len(encode_frame(f)) <= MAX_LINE_BYTES for f in frames)
    assert all(read_data(f).cells for f in frames)


def test_server_asks_only_for_offered_streams_and_ignores_the_rest() -> None:
    """A hello without streams gets the welcome it always got; one offering streams is
    asked for them; telemetry it did not ask for is ignored without an error."""
    welcomes = {}

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"a", "b"}))) as server:
                plain, offering = FakeRover("a", "hider"), FakeRover("b", "seeker")
                offering._hello = lambda: offering.session.send(make_frame("hello", {
                    "id": "b", "role": "seeker", "streams": ["tree"],
                    "seq_base": offering.session.seq_base}))
                async with trio.open_nursery() as nursery:
                    for r in (plain, offering):
                        receive, send, _ = memory_pipe(lambda out, r=r: server.attach_memory(
                            out, trusted=False, name=f"mem:{r.id}"))
                        nursery.start_soon(r.run, receive, send)
                    with trio.fail_after(5):
                        while not (plain.welcomed and offering.welcomed):
                            await trio.sleep(0.1)
                    for r in (plain, offering):
                        welcomes[r.id] = next(f.data for f in r.received if f.cmd == "welcome")
                    offering.session.send(_mailboxes(1.0))  # not asked for
                    offering.session.send(make_frame("tm_tree", {"t": 1.0, "nodes": [
                        ["seeker", "supervisor", "running", 0, None]]}))
                    await trio.sleep(1.0)
                    view = {v.id: v for v in server.snapshot().rovers}["b"]
                    welcomes["view"] = view
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert set(welcomes["a"]) == {"server", "heartbeat_s", "down_after_s", "seq_base", "session"}
    assert welcomes["b"]["telemetry"] == {"tree": 2.0}
    assert welcomes["b"]["telemetry_share"] == 0.25
    view = welcomes["view"]
    assert view.telemetry.tree == (("seeker", "supervisor", "running", 0, None),)
    assert view.telemetry.mailboxes == () and view.telemetry.ignored == 1
    assert view.stats.bad_frames == 0
