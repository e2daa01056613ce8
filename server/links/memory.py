"""In-memory link: a simulated rover in the same process.

The rover side pushes bytes with `MemoryLink.feed` (synchronous, never blocks,
like a UART ISR) and receives the server's bytes through the ``outbound``
callable given at construction. The server side reads it as a Trio byte
stream. The buffer is bounded: bytes that find it full are dropped and
counted, as a UART overrun would.
"""

from __future__ import annotations

from collections.abc import Callable

import trio

__all__ = ["MemoryLink"]


class MemoryLink:
    """A bounded byte pipe between a simulated rover and the server.

    Args:
        outbound: called with each chunk of bytes the server sends to the rover.
        capacity: bytes buffered from the rover at most [bytes].
        name: shown in link statistics and logs.
    """

    def __init__(self, outbound: Callable[[bytes], None], *, capacity: int = 65536,
                 name: str = "memory") -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 byte, got {capacity}")
        self.outbound = outbound
        self.capacity = capacity
        self.name = name
        self.dropped_bytes = 0
        """Bytes from the rover dropped because the buffer was full."""
        self._buf = bytearray()
        self._ready = trio.Event()
        self._closed = False

    def __repr__(self) -> str:
        return f"<MemoryLink {self.name} buffered={len(self._buf)} dropped={self.dropped_bytes}>"

    # rover side ---------------------------------------------------------------

    def feed(self, data: bytes) -> None:
        """Bytes from the rover; never blocks (overflow is dropped and counted)."""
        room = self.capacity - len(self._buf)
        if len(data) > room:
            self.dropped_bytes += len(data) - max(room, 0)
            data = data[:max(room, 0)]
        if data:
            self._buf += data
            self._ready.set()

    def close(self) -> None:
        """The rover hung up: the server sees end of stream."""
        self._closed = True
        self._ready.set()

    # server side (trio byte stream) --------------------------------------------

    async def receive_some(self, max_bytes: int = 65536) -> bytes:
        """Wait for bytes from the rover; ``b""`` once closed and drained."""
        while not self._buf and not self._closed:
            await self._ready.wait()
            self._ready = trio.Event()
        data = bytes(self._buf[:max_bytes])
        del self._buf[:max_bytes]
        return data

    async def send_all(self, data: bytes) -> None:
        """Hand bytes to the rover."""
        await trio.lowlevel.checkpoint()
        self.outbound(bytes(data))

    async def aclose(self) -> None:
        """Close the server side."""
        self.close()
        await trio.lowlevel.checkpoint()
