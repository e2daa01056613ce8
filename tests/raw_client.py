"""Raw protocol clients for tests that play an outside (possibly hostile) peer.

`Outside` is a memory link the server treats as a link from outside (identity
rules apply), `open_raw_tcp` a real loopback socket; both speak bytes, and
`hello` builds the line a rover opens with; `free_port` finds a loopback port.
"""

from __future__ import annotations

import socket

import trio

from server.protocol import Frame, decode_line, encode_frame, make_frame


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port of ``kind`` (TCP by default, ``socket.SOCK_DGRAM`` for UDP) that
    nothing holds at the moment of the call."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def hello(rid: str, role: str, token: str | None = None, seq_base: int = 1) -> bytes:
    """The hello line of rover ``rid``."""
    return encode_frame(make_frame("hello", {"id": rid, "role": role, "token": token,
                                             "seq_base": seq_base}))


def frames_of(chunks: list[bytes]) -> list[Frame]:
    """Every frame in received byte chunks (the list is emptied)."""
    out = [decode_line(x) for c in chunks for x in c.splitlines() if x.strip()]
    chunks.clear()
    return out


def errors_of(frames: list[Frame]) -> list[tuple[str, str]]:
    """(fault, detail) of every error frame."""
    return [(f.data["fault"], f.data["detail"]) for f in frames if f.cmd == "error"]


class Outside:
    """A memory link the server serves as an outside link (see the module docstring)."""

    def __init__(self, server, *, peer: str | None = None, timed: bool = False,
                 name: str = "outside") -> None:
        self.inbox: list[bytes] = []
        self.link = server.attach_memory(self.inbox.append, trusted=False, peer=peer,
                                         timed=timed, name=name)

    def send(self, line: bytes) -> None:
        self.link.feed(line)

    def frames(self) -> list[Frame]:
        return frames_of(self.inbox)

    @property
    def closed_by_server(self) -> bool:
        return self.link._closed


async def open_raw_tcp(port: int, source: str | None = None) -> trio.SocketStream:
    """A TCP connection to the server on loopback, from ``source`` (e.g. 127.0.0.2) if given."""
    if source is None:
        return await trio.open_tcp_stream("127.0.0.1", port)
    sock = trio.socket.socket()
    await sock.bind((source, 0))
    await sock.connect(("127.0.0.1", port))
    return trio.SocketStream(sock)


async def read_until_closed(stream: trio.SocketStream, limit_s: float) -> tuple[bytes, bool]:
    """Bytes read until the server closes (True) or ``limit_s`` passes (False)."""
    got = b""
    with trio.move_on_after(limit_s):
        while True:
            try:
                data = await stream.receive_some(65536)
            except trio.BrokenResourceError:
                return got, True
            if not data:
                return got, True
            got += data
    return got, False
