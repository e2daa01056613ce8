"""UDP links: datagram framing, rovers over UDP, and hostile UDP peers kept in bounds.

Real sockets on loopback under a virtual clock (loopback datagrams arrive at
once, so the clock only jumps when nothing is in flight).
"""

from __future__ import annotations

import trio
import trio.testing

from server.links import udp
from server.links.udp import (
    MAX_DATAGRAM,
    PEER_QUEUE,
    UdpEndpoint,
    UdpPeer,
    datagram_lines,
    open_udp_stream,
)
from server.protocol import decode_line, encode_frame, make_frame
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover
from tests.raw_client import hello


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


async def _raw(port: int, source: str = "127.0.0.1") -> trio.socket.SocketType:
    """A UDP socket on ``source`` connected to the server's port (a peer address)."""
    sock = trio.socket.socket(trio.socket.AF_INET, trio.socket.SOCK_DGRAM)
    await sock.bind((source, 0))
    await sock.connect(("127.0.0.1", port))
    return sock


async def _datagrams(sock, limit_s: float) -> list[bytes]:
    """Every datagram received within ``limit_s``."""
    got: list[bytes] = []
    with trio.move_on_after(limit_s):
        while True:
            got.append(await sock.recv(65536))
    return got


async def _udp_rover(nursery, port: int, rover: FakeRover):
    stream = await open_udp_stream("127.0.0.1", port)
    nursery.start_soon(rover.run, lambda: stream.receive_some(4096), stream.send_all)
    return stream


def test_datagram_lines_sends_one_frame_per_datagram() -> None:
    """Whole lines become one datagram each; a trailing piece ends a line too."""
    assert datagram_lines(b'{"a":1}\n{"b":2}\n') == [b'{"a":1}\n', b'{"b":2}\n']
    assert datagram_lines(b'{"a":1}\n\n{"b":2}') == [b'{"a":1}\n', b'{"b":2}\n']
    assert datagram_lines(b"") == []


def test_rover_over_udp_says_hello_and_each_reply_is_one_frame() -> None:
    """A hello datagram without its newline is welcomed; every reply datagram is one line."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            port = await s.listen_udp("127.0.0.1", 0)
            sock = await _raw(port)
            await sock.send(hello("h1", "hider").rstrip(b"\n"))
            got = await _datagrams(sock, 0.5)
            assert got and all(d.count(b"\n") == 1 and d.endswith(b"\n") for d in got)
            assert decode_line(got[0].rstrip(b"\n")).cmd == "welcome"
            (view,) = s.snapshot().rovers
            assert view.link == f"udp:127.0.0.1:{sock.getsockname()[1]}"
            assert s.snapshot().connections == 1
            sock.close()

    run(main)


def test_fake_rover_keeps_its_session_over_udp_while_garbage_peers_come_and_go() -> None:
    """A rover over UDP stays up and is served while other ports spew garbage."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), bad_frame_budget=10, bad_frame_rate=1)
        async with open_server(Store(":memory:"), config) as s, trio.open_nursery() as nursery:
            port = await s.listen_udp("127.0.0.1", 0)
            h1 = FakeRover("h1", "hider")
            await _udp_rover(nursery, port, h1)
            await trio.sleep(1)
            for _ in range(5):
                sock = await _raw(port, "127.0.0.2")
                for _ in range(50):
                    await sock.send(b"garbage")
                await trio.sleep(0.2)
                sock.close()
            await trio.sleep(3)
            assert h1.welcomed
            (view,) = s.snapshot().rovers
            assert view.stats.up and view.stats.bad_frames == 0
            nursery.cancel_scope.cancel()

    run(main)


def test_udp_garbage_spends_the_budget_then_the_peer_is_closed_and_quiet() -> None:
    """Each garbage datagram is answered until the budget is spent; the peer's connection
    is then closed and its datagrams go unanswered for the quiet period."""
    async def main() -> None:
        config = ServerConfig(bad_frame_budget=20, bad_frame_rate=1.0)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_udp("127.0.0.1", 0)
            sock = await _raw(port)
            for _ in range(100):
                await sock.send(b"garbage")
            got = await _datagrams(sock, 1.0)
            errors = [decode_line(d.rstrip(b"\n")) for d in got]
            assert 20 <= len(errors) <= 22 and all(f.cmd == "error" for f in errors)
            assert s.snapshot().connections == 0
            assert s.snapshot().refused["conn_closed"] == 1
            await sock.send(b"garbage")  # within the quiet period: dropped unanswered
            assert await _datagrams(sock, udp.QUIET_S / 2) == []
            await trio.sleep(udp.QUIET_S)
            await sock.send(b"garbage")  # after it: a new connection, answered again
            (answer,) = await _datagrams(sock, 0.5)
            assert decode_line(answer.rstrip(b"\n")).data["fault"] == "not_json"
            sock.close()

    run(main)


def test_many_source_ports_are_held_to_the_connection_caps() -> None:
    """300 source ports on one address and 100 on another: the server holds at most
    max_pending_per_address unauthenticated peers per address and max_connections in
    all; a rover from a third address is welcomed during the flood."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), max_connections=12,
                              max_pending_per_address=8)
        async with open_server(Store(":memory:"), config) as s, trio.open_nursery() as nursery:
            port = await s.listen_udp("127.0.0.1", 0)
            socks = []
            for i in range(400):
                sock = await _raw(port, "127.0.0.2" if i < 300 else "127.0.0.3")
                socks.append(sock)
                await sock.send(encode_frame(make_frame("heartbeat", None)))
                await trio.sleep(0.001)
                assert s.snapshot().connections <= 12
            stream = await open_udp_stream("127.0.0.1", port)
            h1 = FakeRover("h1", "hider")
            nursery.start_soon(h1.run, lambda: stream.receive_some(4096), stream.send_all)
            await trio.sleep(2)
            assert h1.welcomed and s.snapshot().connections <= 12
            assert s.snapshot().refused["conn_closed"] >= 400 - 12
            for sock in socks:
                sock.close()
            nursery.cancel_scope.cancel()

    run(main)


def test_a_udp_rover_with_its_token_gets_in_past_its_hosts_full_budget() -> None:
    """Source ports of one host fill its budget of unauthenticated peers; a new port on
    that host whose first datagram is a hello with the right token is welcomed (the
    host's oldest unauthenticated peer is closed), one with a wrong token is not."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "secret"},
                              max_pending_per_address=4)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_udp("127.0.0.1", 0)
            flood = []
            for _ in range(10):
                sock = await _raw(port, "127.0.0.2")
                await sock.send(encode_frame(make_frame("heartbeat", None)))
                flood.append(sock)
            await trio.sleep(0.1)
            assert s.snapshot().connections == 4
            wrong, right = await _raw(port, "127.0.0.2"), await _raw(port, "127.0.0.2")
            await wrong.send(hello("h1", "hider", "nope"))
            assert await _datagrams(wrong, 0.5) == []
            await right.send(hello("h1", "hider", "secret"))
            (answer,) = await _datagrams(right, 0.5)
            assert decode_line(answer.rstrip(b"\n")).cmd == "welcome"
            assert s.snapshot().connections == 4  # the oldest heartbeat peer made room
            for sock in [wrong, right, *flood]:
                sock.close()

    run(main)


def test_an_oversize_datagram_is_refused_whole() -> None:
    """A datagram over 1024 bytes, even one full of good lines, is one too_long answer."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"h1"}))) as s:
            port = await s.listen_udp("127.0.0.1", 0)
            sock = await _raw(port)
            await sock.send(hello("h1", "hider") * 20)  # about 1.5 KiB of hellos
            (answer,) = await _datagrams(sock, 0.5)
            error = decode_line(answer.rstrip(b"\n"))
            assert (error.cmd, error.data["fault"]) == ("error", "too_long")
            assert s.snapshot().rovers == ()
            await sock.send(hello("h1", "hider"))  # a datagram ends its line: the next is whole
            got = await _datagrams(sock, 0.5)
            assert decode_line(got[0].rstrip(b"\n")).cmd == "welcome"
            sock.close()

    run(main)


def test_a_peer_queue_and_the_quiet_table_are_bounded(monkeypatch) -> None:
    """A peer flooding faster than the server reads loses datagrams beyond its queue;
    the table of quiet peers forgets the oldest beyond its capacity."""
    async def main() -> None:
        sock = trio.socket.socket(trio.socket.AF_INET, trio.socket.SOCK_DGRAM)
        await sock.bind(("127.0.0.1", 0))
        endpoint = UdpEndpoint(sock)
        peer = UdpPeer(endpoint, ("127.0.0.9", 4000))
        for _ in range(10 * PEER_QUEUE):
            peer._deliver(b"x" * 10)
        assert peer.dropped == 9 * PEER_QUEUE
        first = await peer.receive_some(4096)
        assert first.count(b"\n") == PEER_QUEUE  # the whole queue, each datagram a line
        peer._deliver(b"y" * (MAX_DATAGRAM + 500))
        assert len(await peer.receive_some(4096)) == MAX_DATAGRAM + 2  # one too-long line
        monkeypatch.setattr(udp, "QUIET_CAPACITY", 16)
        for n in range(100):
            await UdpPeer(endpoint, ("127.0.0.9", 5000 + n)).aclose()
        assert endpoint.quiet == 16
        sock.close()

    run(main)
