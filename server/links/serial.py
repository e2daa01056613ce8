"""Serial links through pyserial: a Trio byte stream over a port or pyserial URL.

pyserial opens and configures the port. Where the port has a file descriptor
(Linux ttys, ptys) bytes move through ``trio.lowlevel.FdStream`` on a
duplicate of it: cancellable in well under a millisecond. URL transports
without one (``loop://``, ``socket://``) are read in a worker thread with a
short read timeout, so cancellation waits at most that long.

A missing or unplugged port raises `SerialLinkError` with a readable message;
`serve_serial` in the server retries with backoff.
"""

from __future__ import annotations

import os
import termios

import trio

__all__ = ["SerialLinkError", "open_serial_stream", "ThreadSerialStream"]

_THREAD_READ_TIMEOUT_S = 0.05


class SerialLinkError(OSError):
    """Raised when a serial port cannot be opened or fails (unplugged)."""


def _open_port(url: str, baud: int):
    import serial  # pyserial; imported here so the server starts without a port

    try:
        return serial.serial_for_url(url, baudrate=baud, timeout=_THREAD_READ_TIMEOUT_S,
                                     write_timeout=2.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SerialLinkError(f"cannot open serial port {url} at {baud} baud: {msg}") from None


class ThreadSerialStream:
    """A pyserial port without a file descriptor, as a Trio byte stream (worker thread)."""

    def __init__(self, port, *, eof_on_error: bool = False) -> None:
        self.port = port
        self._eof_on_error = eof_on_error  # a socket:// peer that went away ends the stream

    async def receive_some(self, max_bytes: int = 4096) -> bytes:
        """Wait for bytes (polls in a thread with a short timeout, so it is cancellable)."""
        while True:
            try:
                data = await trio.to_thread.run_sync(self._read, max_bytes)
            except Exception as exc:  # pyserial raises various types on unplug
                if self._eof_on_error:
                    return b""
                raise SerialLinkError(f"serial port {self.port.port} failed: {exc}") from None
            if data:
                return data

    def _read(self, max_bytes: int) -> bytes:
        n = self.port.in_waiting
        return self.port.read(min(max(n, 1), max_bytes))

    async def send_all(self, data: bytes) -> None:
        """Write bytes (in a thread: a slow baud rate blocks the writer, not Trio)."""
        try:
            await trio.to_thread.run_sync(self.port.write, bytes(data))
        except Exception as exc:
            raise SerialLinkError(f"serial port {self.port.port} failed: {exc}") from None

    async def aclose(self) -> None:
        """Close the port."""
        self.port.close()
        await trio.lowlevel.checkpoint()


class _FdSerialStream:
    """FdStream on a dup of the port's descriptor; keeps the pyserial object to close it."""

    def __init__(self, port) -> None:
        self.port = port
        fd = port.fileno()
        # pyserial leaves VMIN=0, VTIME=0: a non-blocking read with no data would
        # then return b"" (end of file) instead of EAGAIN. VMIN=1 makes b"" mean hang-up.
        attrs = termios.tcgetattr(fd)
        attrs[6][termios.VMIN], attrs[6][termios.VTIME] = 1, 0
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
        self._fd = trio.lowlevel.FdStream(os.dup(fd))

    async def receive_some(self, max_bytes: int = 4096) -> bytes:
        try:
            return await self._fd.receive_some(max_bytes)
        except (OSError, trio.BrokenResourceError) as exc:
            raise SerialLinkError(f"serial port {self.port.port} failed: {exc}") from None

    async def send_all(self, data: bytes) -> None:
        try:
            await self._fd.send_all(data)
        except (OSError, trio.BrokenResourceError) as exc:
            raise SerialLinkError(f"serial port {self.port.port} failed: {exc}") from None

    async def aclose(self) -> None:
        await self._fd.aclose()
        self.port.close()


def open_serial_stream(url: str, baud: int):
    """Open a pyserial port or URL as a Trio byte stream.

    Raises:
        SerialLinkError: the port is missing, busy or not a serial port.
    """
    port = _open_port(url, baud)
    try:
        fd = port.fileno()
    except Exception:  # URL transports have no descriptor
        return ThreadSerialStream(port)
    if not os.isatty(fd):  # socket://: a socket's descriptor takes no terminal settings,
        return ThreadSerialStream(port, eof_on_error=True)  # and a closed peer is an end
    try:
        return _FdSerialStream(port)
    except (OSError, termios.error) as exc:
        port.close()
        raise SerialLinkError(f"cannot set up serial port {url}: {exc}") from None
