"""The server's hello: the rover's session id decides whether reception goes back."""

from __future__ import annotations

import trio
import trio.testing

from server.protocol import Frame, encode_frame, make_frame
from server.server import ServerConfig, open_server
from server.store import Store
from tests.raw_client import Outside

_ARRIVED = {"x": 1, "y": 2, "heading": 0}


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


def _hello(session: int | None, seq_base: int = 1) -> bytes:
    data = {"id": "h1", "role": "hider", "seq_base": seq_base}
    if session is not None:
        data["session"] = session
    return encode_frame(make_frame("hello", data))


def _arrived(seq: int) -> bytes:
    """A reliable frame the server takes and answers (in phase idle) naming its seq."""
    f = make_frame("arrived", _ARRIVED)
    return encode_frame(Frame(f.cmd, f.type, f.data, seq=seq))


async def _answered(x: Outside, *lines: bytes) -> list[int]:
    """Send lines; the seqs of the frames the server delivered (each answered not_allowed)."""
    for line in lines:
        x.send(line)
    await trio.sleep(0.2)
    return [f.data["seq"] for f in x.frames() if f.cmd == "error"]


def test_welcome_says_the_servers_session_id_and_keeps_it_across_hellos() -> None:
    """Every welcome to one rover names the same session id: the server's numbering."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            x = Outside(s, name="h1")
            ids = []
            for session in (5, 5, 6, None):
                x.send(_hello(session))
                await trio.sleep(0.2)
                ids += [f.data["session"] for f in x.frames() if f.cmd == "welcome"]
            assert len(ids) == 4 and len(set(ids)) == 1
            assert isinstance(ids[0], int) and 0 <= ids[0] < 2 ** 32

    run(main)


def test_a_late_hello_of_the_same_rover_session_does_not_rewind_the_servers_reception() -> None:
    """A hello (same session) naming seq 1 after seq 1-2 were taken: seq 3 is delivered
    next, and a resend of seq 2 stays a duplicate."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            x = Outside(s, name="h1")
            assert await _answered(x, _hello(5)) == []
            assert await _answered(x, _arrived(1), _arrived(2)) == [1, 2]
            assert await _answered(x, _hello(5, seq_base=1), _arrived(3), _arrived(2)) == [3]

    run(main)


def test_a_hello_of_a_new_rover_session_restarts_the_servers_reception() -> None:
    """A rebooted rover (a new session id) numbers from 1 again: its seq 1 is delivered."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            x = Outside(s, name="h1")
            await _answered(x, _hello(5))
            assert await _answered(x, _arrived(1), _arrived(2)) == [1, 2]
            assert await _answered(x, _hello(6, seq_base=1), _arrived(1)) == [1]

    run(main)


def test_a_hello_without_a_session_restarts_the_servers_reception_as_before() -> None:
    """A rover that sends no session id: every hello restarts reception at its seq_base."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            x = Outside(s, name="h1")
            await _answered(x, _hello(None))
            assert await _answered(x, _arrived(1), _arrived(2)) == [1, 2]
            assert await _answered(x, _hello(None, seq_base=1), _arrived(1)) == [1]

    run(main)
