"""Split a byte stream into frame lines, with a bounded buffer.

A serial port or TCP socket delivers bytes in arbitrary pieces; `LineBuffer`
reassembles them into lines. It never holds more than `MAX_LINE_BYTES`: a line
that grows past the limit is dropped up to its newline and reported once as
`TOO_LONG`, so a flood of garbage without newlines cannot grow memory.
Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Iterator

from .frame import MAX_LINE_BYTES

__all__ = ["TOO_LONG", "LineBuffer"]

TOO_LONG = object()
"""Yielded by `LineBuffer.feed` in place of a line that exceeded the limit."""


class LineBuffer:
    """Reassembles ``\\n``-terminated lines from byte pieces.

    Args:
        limit: longest line accepted, newline included [bytes].
    """

    def __init__(self, limit: int = MAX_LINE_BYTES) -> None:
        if limit < 2:
            raise ValueError(f"limit must be at least 2 bytes, got {limit}")
        self.limit = limit
        self._buf = bytearray()
        self._skipping = False  # inside an overlong line, dropping up to its newline

    def __len__(self) -> int:
        """Bytes held waiting for a newline."""
        return len(self._buf)

    def feed(self, data: bytes) -> Iterator[bytes | object]:
        """Add bytes; yield each complete line (without ``\\n``) or `TOO_LONG`.

        Empty lines (and a ``\\r`` before ``\\n``) are skipped, so ``\\r\\n`` senders work.
        """
        start = 0
        n = len(data)
        while start < n:
            nl = data.find(b"\n", start)
            if nl < 0:
                piece = data[start:]
                if self._skipping:
                    return
                if len(self._buf) + len(piece) >= self.limit:
                    self._buf.clear()
                    self._skipping = True
                    yield TOO_LONG
                    return
                self._buf += piece
                return
            piece = data[start:nl]
            start = nl + 1
            if self._skipping:
                self._skipping = False
                continue
            if len(self._buf) + len(piece) + 1 > self.limit:
                self._buf.clear()
                yield TOO_LONG
                continue
            if self._buf:
                self._buf += piece
                line = bytes(self._buf)
                self._buf.clear()
            else:
                line = bytes(piece)
            if line.endswith(b"\r"):
                line = line[:-1]
            if line:
                yield line
