"""TCP connections as the server's accept loop takes them, on standard sockets.

After each awaited accept the loop takes the rest of a burst of connections
already queued through `second_handle` (no scheduler round each), reads what
each has sent already without waiting (`read_now`), and makes a Trio stream
of the ones it serves (`as_stream`). The loop and the admission rules are
`server.connections`.
"""

from __future__ import annotations

import os
import socket
from typing import Any

import trio

from ..protocol.frame import MAX_LINE_BYTES

__all__ = ["as_stream", "read_now", "second_handle"]


def second_handle(listener: Any) -> socket.socket | None:
    """A second handle on a listener's socket, to take the rest of a burst of connections
    without a scheduler round each (None where the system cannot make one)."""
    sock = getattr(listener, "socket", None)
    if sock is None:
        return None
    try:
        return socket.socket(fileno=os.dup(sock.fileno()))
    except OSError:
        return None


def as_stream(sock: socket.socket) -> trio.SocketStream:
    """A standard socket as a Trio stream."""
    return trio.SocketStream(trio.socket.from_stdlib_socket(sock))


def read_now(sock: Any) -> bytes | None:
    """What a new connection (a non-blocking socket) has sent already, up to a line's
    worth, without waiting (None when the peer has closed or reset it)."""
    try:
        return os.read(sock.fileno(), MAX_LINE_BYTES + 1) or None
    except BlockingIOError:
        return b""
    except OSError:
        return None
