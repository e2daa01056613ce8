"""Replies a firmware author relies on: errors name why, with cmd and seq; acks say ack;
heading null is heading absent; numbers JSON cannot hold are named."""

from __future__ import annotations

import pytest
import trio
import trio.testing

from server.protocol import (
    Frame,
    FrameError,
    ReliableSession,
    decode_line,
    encode_frame,
    make_frame,
    map_chunks,
    read_data,
)
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import room_map
from tests.raw_client import Outside, hello


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def _line(cmd: str, data=None, seq: int | None = None, type_: str | None = None) -> bytes:
    f = make_frame(cmd, data)
    return encode_frame(Frame(cmd, type_ or f.type, f.data, seq=seq))


def _errors(x: Outside) -> list[dict]:
    return [f.data for f in x.frames() if f.cmd == "error"]


async def _rover(s, rid: str, role: str) -> Outside:
    x = Outside(s, name=rid)
    x.send(hello(rid, role))
    await trio.sleep(0.2)
    x.frames()
    return x


def test_reports_and_uploads_out_of_turn_get_an_error_naming_why() -> None:
    """Wrong phase or wrong role: an error with the reason, cmd and seq; never a silent ack."""
    store = Store(":memory:")

    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"m1", "h1", "s1"}))
        async with open_server(store, config) as s:
            m, h, k = (await _rover(s, "m1", "mapper"), await _rover(s, "h1", "hider"),
                       await _rover(s, "s1", "seeker"))
            h.send(_line("arrived", {"x": 1, "y": 2, "heading": 0}, seq=1))
            k.send(_line("arrived", {"x": 1, "y": 2, "heading": 0}, seq=1))
            h.send(_line("map_request", seq=2))
            await trio.sleep(0.2)
            assert _errors(h) == [
                {"fault": "not_allowed", "detail": "arrived ignored in phase idle",
                 "cmd": "arrived", "seq": 1},
                {"fault": "not_allowed", "detail": "no map yet", "cmd": "map_request",
                 "seq": 2}]
            assert _errors(k) == [{"fault": "not_allowed", "detail": "arrived comes from the "
                                   "hider, not the seeker", "cmd": "arrived", "seq": 1}]
            (chunk,) = map_chunks(room_map(), 1)
            h.send(encode_frame(Frame("map", "chunk", chunk.data, seq=3)))
            m.send(encode_frame(Frame("map", "chunk", chunk.data, seq=1)))
            await trio.sleep(0.2)
            assert _errors(h) == [{"fault": "not_allowed", "detail": "only the mapper uploads "
                                   "maps, not the hider", "cmd": "map", "seq": 3}]
            assert _errors(m) == [{"fault": "not_allowed", "detail": "map upload ignored in "
                                   "phase idle", "cmd": "map", "seq": 1}]
        (kept,) = store.maps()
        assert (kept.accepted, kept.note) == (False, "map upload ignored in phase idle")

    run(main)


def test_hide_without_heading_sends_null() -> None:
    """``hide X Y`` with no heading: the destination's heading is null (any)."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(
                rovers=frozenset({"h1"}), origins={"h1": (0.0, 0.0, 0.0)})) as s:
            h = await _rover(s, "h1", "hider")
            s.game.phase, s.game.map = s.game.phase.MAP_READY, room_map()
            assert (await s.command("hide", x=60.0, y=10.0)).ok
            await trio.sleep(0.5)
            (dest,) = [f for f in h.frames() if f.cmd == "destination"]
            assert dest.data == {"x": 60.0, "y": 10.0, "heading": None}

    run(main)


def test_heartbeat_and_ack_frames_are_validated() -> None:
    """A heartbeat or ack with the wrong type is answered bad_type like any frame."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            h = await _rover(s, "h1", "hider")
            h.send(b'{"cmd":"heartbeat","type":"pulse","data":null}\n')
            h.send(b'{"cmd":"ack","type":"nak","data":null,"ack":0}\n')
            await trio.sleep(0.2)
            assert [(e["fault"], e["cmd"]) for e in _errors(h)] == [
                ("bad_type", "heartbeat"), ("bad_type", "ack")]

    run(main)


def test_a_bare_ack_always_carries_ack() -> None:
    """Even before anything arrived in order (a gap at seq 1) the ack frame says ack: 0."""
    session = ReliableSession()
    session.receive(Frame("pose", "pose", {"x": 0, "y": 0}, seq=3), 0.0)
    (line,) = session.transmit(0.0).splitlines()
    frame = decode_line(line)
    assert (frame.cmd, frame.ack) == ("ack", 0)


def test_heading_null_means_heading_absent() -> None:
    """``heading: null`` in a pose or found reads as the default, as when it is missing."""
    for cmd in ("pose", "arrived", "found"):
        with_null = read_data(Frame(cmd, "pose", {"x": 1, "y": 2, "heading": None}))
        without = read_data(Frame(cmd, "pose", {"x": 1, "y": 2}))
        assert with_null == without and with_null.heading == 0.0
    dest = read_data(Frame("destination", "pose", {"x": 1, "y": 2, "heading": None}))
    assert dest.heading is None


@pytest.mark.parametrize(("line", "detail"), [
    (b'{"cmd":"pose","type":"pose","data":{"x":NaN,"y":1}}',
     "$.data.x: nan is not a finite JSON number"),
    (b'{"cmd":"pose","type":"pose","data":{"x":1,"y":-Infinity}}',
     "$.data.y: -inf is not a finite JSON number"),
    (b'{"cmd":"pose","type":"pose","data":{"x":1e400,"y":1}}',
     "$.data.x: inf is not a finite JSON number"),
    (b'{"cmd":"status","type":"status","data":{"state":"\\ud800"}}',
     "$.data.state: a lone UTF-16 surrogate escape"),
])
def test_numbers_and_strings_json_cannot_hold_are_bad_data_naming_the_field(line,
                                                                            detail) -> None:
    with pytest.raises(FrameError) as info:
        decode_line(line)
    assert info.value.fault == "bad_data" and info.value.detail.startswith(detail)


def test_out_of_range_number_names_the_field() -> None:
    """A coordinate past ±1e6 is bad_data at its field."""
    with pytest.raises(FrameError, match=r"bad_data: data of 'pose': Expected `float` <= "
                                         r"1000000.0 - at `\$.x`"):
        read_data(decode_line(b'{"cmd":"pose","type":"pose","data":{"x":1e7,"y":1}}'))
