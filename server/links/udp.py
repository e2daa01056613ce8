"""UDP links: the line protocol in datagrams, for rovers that speak UDP.

Framing: a datagram carries one frame, the JSON line of docs/protocol.md
(its newline optional), at most `MAX_DATAGRAM` bytes. A receiver also takes
several newline-separated frames in one datagram within that size; a frame
never spans datagrams (the end of a datagram ends its last line, so a cut or
garbled datagram cannot spoil the next one). Senders here send one frame per
datagram. A datagram longer than `MAX_DATAGRAM` is refused whole: the server
answers it as an over-long line (``too_long``).

Roles, as MAVProxy's ``udpin``/``udpout``: the server receives on one bound
socket (``--listen udp:HOST:PORT``, `UdpEndpoint`); a rover sends to that
address from a connected socket (``hideseek rover --link udpout:HOST:PORT``,
`open_udp_stream`) and is answered at the address it sent from.

Each peer address (host and port) the endpoint hears is one connection to
the server, served like a TCP connection (`UdpPeer` is a Trio byte stream).
The endpoint asks the server's ``admit`` callback before it makes one: the
server's bounds decide (connection cap, unauthenticated connections per
address, blocked addresses), and the hello timeout, idle close and bad-frame
budget apply to the connection. Bounds the endpoint keeps itself:

* each peer queues at most `PEER_QUEUE` datagrams for the server (more are
  dropped and counted, as a full socket buffer drops them);
* a peer whose connection the server closed is not heard for `QUIET_S`
  (its datagrams are dropped unanswered), so a peer spending its bad-frame
  budget cannot start afresh at once; that table holds at most
  `QUIET_CAPACITY` addresses (the oldest is forgotten first);
* datagrams from a peer the server refuses are dropped unanswered.

What it is not: UDP has no handshake, so a reply goes to whatever source
address a datagram claims. Before the welcome the server answers a peer only
within its bad-frame budget; beyond loopback, use tokens as for TCP.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

import trio

from ..protocol.frame import MAX_LINE_BYTES

__all__ = ["MAX_DATAGRAM", "PEER_QUEUE", "QUIET_S", "QUIET_CAPACITY", "UdpPeer", "UdpEndpoint",
           "UdpStream", "open_udp_endpoint", "open_udp_stream", "datagram_lines"]

MAX_DATAGRAM = MAX_LINE_BYTES
"""Longest datagram taken [bytes]: one frame line, newline included."""
PEER_QUEUE = 64
"""Datagrams one peer may have waiting for the server [datagrams]."""
QUIET_S = 2.0
"""A peer whose connection the server closed is not heard for this long [s]."""
QUIET_CAPACITY = 4096
"""Quiet peers remembered at most."""
_OVERSIZE = b"\xff" * (MAX_DATAGRAM + 1) + b"\n"  # what an oversize datagram reaches the server as

Admit = Callable[["UdpPeer", str, str, bytes], bool]
"""``admit(peer, host, link_name, first_datagram)``: the server serves ``peer`` (True) or
refuses it (beyond its caps it reads the first datagram: an accepted hello makes room)."""


def datagram_lines(data: bytes) -> list[bytes]:
    """Bytes of whole lines -> one datagram per line (each keeps its newline).

    A piece after the last newline is a line too: datagrams end lines.
    """
    lines = data.split(b"\n")
    out = [line + b"\n" for line in lines[:-1] if line.strip()]
    if lines[-1].strip():
        out.append(lines[-1] + b"\n")
    return out


def _received(data: bytes) -> bytes:
    """A received datagram as the line stream the receiver reads: it ends a line."""
    if len(data) > MAX_DATAGRAM:
        return _OVERSIZE
    return data if data.endswith(b"\n") else data + b"\n"


async def _socket_to(host: str, port: int, *, bind: bool) -> trio.socket.SocketType:
    """A datagram socket bound to (``bind``) or connected to ``host``:``port`` (the first
    address the resolver gives).

    Raises:
        OSError: the host does not resolve, the address is in use, or no route.
    """
    infos = await trio.socket.getaddrinfo(host, port, type=trio.socket.SOCK_DGRAM)
    if not infos:
        raise OSError(f"cannot resolve {host}")
    family, _type, _proto, _name, addr = infos[0]
    sock = trio.socket.socket(family, trio.socket.SOCK_DGRAM)
    try:
        await (sock.bind(addr) if bind else sock.connect(addr))
    except BaseException:
        sock.close()
        raise
    return sock


class UdpPeer:
    """One peer address of a `UdpEndpoint`, as a Trio byte stream the server serves.

    Made by the endpoint. ``receive_some`` gives the peer's datagrams as lines;
    ``send_all`` sends each line as one datagram to the peer; ``aclose`` ends the
    connection (the peer is then quiet for `QUIET_S`).
    """

    def __init__(self, endpoint: UdpEndpoint, addr: Any) -> None:
        self._endpoint = endpoint
        self.addr = addr
        """The peer's socket address."""
        self.host = str(addr[0])
        """The peer's host, the "address" the server's per-address bounds count."""
        self.name = f"udp:{addr[0]}:{addr[1]}"
        """The link's name in logs and snapshots."""
        self.dropped = 0
        """Datagrams dropped because the queue was full."""
        self._queue: collections.deque[bytes] = collections.deque()
        self._ready = trio.Event()
        self._closed = False

    def __repr__(self) -> str:
        return f"<UdpPeer {self.name} queued={len(self._queue)} dropped={self.dropped}>"

    def _deliver(self, data: bytes) -> None:
        """A datagram from the peer (the endpoint's receive loop; never blocks)."""
        if len(self._queue) >= PEER_QUEUE:
            self.dropped += 1
            return
        self._queue.append(_received(data))
        self._ready.set()

    async def receive_some(self, max_bytes: int = 4096) -> bytes:
        """Wait for the peer's datagrams; ``b""`` once the connection is closed."""
        while not self._queue and not self._closed:
            await self._ready.wait()
            self._ready = trio.Event()
        if self._closed:
            return b""
        out = bytearray()
        while self._queue and len(out) + len(self._queue[0]) <= max_bytes:
            out += self._queue.popleft()
        if not out:  # one datagram longer than max_bytes: hand it over in pieces
            first = self._queue[0]
            out += first[:max_bytes]
            self._queue[0] = first[max_bytes:]
        return bytes(out)

    async def send_all(self, data: bytes) -> None:
        """Send each line of ``data`` as one datagram to the peer.

        Raises:
            trio.BrokenResourceError: the socket refused a datagram, or is closed.
        """
        if self._closed:
            raise trio.ClosedResourceError("UDP peer closed")
        for datagram in datagram_lines(bytes(data)):
            await self._endpoint.send_to(datagram, self.addr)

    async def aclose(self) -> None:
        """End the connection: forget the peer, hear it no more for `QUIET_S`."""
        if not self._closed:
            self._closed = True
            self._ready.set()
            self._endpoint._forget(self)
        await trio.lowlevel.checkpoint()


class UdpEndpoint:
    """A bound UDP socket whose peers are connections (made by `open_udp_endpoint`).

    Args:
        sock: a bound datagram socket (the endpoint closes it).
        clock: the time [s] quiet periods are measured in (Trio's clock by default).
    """

    def __init__(self, sock: trio.socket.SocketType, *,
                 clock: Callable[[], float] = trio.current_time) -> None:
        self._sock = sock
        self._clock = clock
        self._peers: dict[Any, UdpPeer] = {}
        self._quiet: collections.OrderedDict[Any, float] = collections.OrderedDict()
        self.refused = 0
        """Datagrams dropped unanswered: from refused or quiet peers."""

    def __repr__(self) -> str:
        return (f"<UdpEndpoint port={self.port} peers={len(self._peers)} "
                f"quiet={len(self._quiet)} refused={self.refused}>")

    @property
    def port(self) -> int:
        """The bound port."""
        return int(self._sock.getsockname()[1])

    @property
    def peers(self) -> int:
        """Peers served now."""
        return len(self._peers)

    @property
    def quiet(self) -> int:
        """Peers in their quiet period (or not yet forgotten after it)."""
        return len(self._quiet)

    async def serve(self, admit: Admit) -> None:
        """Receive datagrams until cancelled: each goes to its peer, new peers via ``admit``.

        The socket is closed on the way out.
        """
        with self._sock:
            while True:
                try:
                    data, addr = await self._sock.recvfrom(MAX_DATAGRAM + 1)
                except ConnectionError:  # an ICMP error for an earlier reply (some systems)
                    continue
                key = addr[:2]
                peer = self._peers.get(key)
                if peer is None:
                    until = self._quiet.get(key)
                    if until is not None:
                        if self._clock() < until:
                            self.refused += 1
                            continue
                        del self._quiet[key]
                    peer = UdpPeer(self, addr)
                    if not admit(peer, peer.host, peer.name, data):
                        self.refused += 1
                        continue
                    self._peers[key] = peer
                peer._deliver(data)

    async def send_to(self, datagram: bytes, addr: Any) -> None:
        """Send one datagram.

        Raises:
            trio.BrokenResourceError: the system refused it (unreachable, closed socket).
        """
        try:
            await self._sock.sendto(datagram, addr)
        except OSError as exc:
            raise trio.BrokenResourceError(f"udp send to {addr[0]}:{addr[1]}: {exc}") from None

    def _forget(self, peer: UdpPeer) -> None:
        key = peer.addr[:2]
        if self._peers.get(key) is peer:
            del self._peers[key]
        self._quiet.pop(key, None)
        self._quiet[key] = self._clock() + QUIET_S
        while len(self._quiet) > QUIET_CAPACITY:
            self._quiet.popitem(last=False)


async def open_udp_endpoint(host: str, port: int) -> UdpEndpoint:
    """Bind a UDP socket on ``host``:``port`` (0: any free port) for `UdpEndpoint.serve`.

    Raises:
        OSError: the address does not resolve or is in use.
    """
    return UdpEndpoint(await _socket_to(host, port, bind=True))


class UdpStream:
    """A rover's UDP link to the server as a Trio byte stream (made by `open_udp_stream`).

    ``send_all`` sends each complete line as one datagram and keeps a partial
    line (bytes arrive from the rover's UART model in pieces) until its newline,
    at most `MAX_DATAGRAM` bytes (a longer one leaves as it is and is refused by
    the server). ``receive_some`` gives one datagram, as a line.
    """

    def __init__(self, sock: trio.socket.SocketType, name: str) -> None:
        self._sock = sock
        self.name = name
        self._partial = b""

    def __repr__(self) -> str:
        return f"<UdpStream {self.name}>"

    async def receive_some(self, max_bytes: int = 4096) -> bytes:
        """The next datagram from the server.

        Raises:
            ConnectionRefusedError: nothing listens at the server's address (ICMP).
        """
        data = await self._sock.recv(max(max_bytes, MAX_DATAGRAM + 1))
        return _received(data)

    async def send_all(self, data: bytes) -> None:
        """Send complete lines as datagrams; keep a partial line for the next call.

        Raises:
            OSError: the system refused a datagram (e.g. nothing listens there).
        """
        data = self._partial + bytes(data)
        cut = data.rfind(b"\n") + 1
        if len(data) - cut > MAX_DATAGRAM:
            cut = len(data)
        self._partial = data[cut:]
        for datagram in datagram_lines(data[:cut]):
            await self._sock.send(datagram)

    async def aclose(self) -> None:
        """Close the socket."""
        self._sock.close()
        await trio.lowlevel.checkpoint()


async def open_udp_stream(host: str, port: int) -> UdpStream:
    """A connected UDP socket to the server at ``host``:``port``.

    Raises:
        OSError: the host does not resolve, or no route.
    """
    return UdpStream(await _socket_to(host, port, bind=False), f"udp:{host}:{port}")

