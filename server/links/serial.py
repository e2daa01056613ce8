"""Serial links through pyserial: a Trio byte stream over a port or pyserial URL.

pyserial opens and configures the port. Where the port has a file descriptor
(Linux ttys, ptys) bytes move through ``trio.lowlevel.FdStream`` on a
duplicate of it: cancellable in well under a millisecond. URL transports
without one (``loop://``, ``socket://``) are read in a worker thread with a
short read timeout, so cancellation waits at most that long.

A missing or unplugged port raises `SerialLinkError` with a readable message.
An unplugged device is noticed at once: the kernel hangs the tty up, a read
then ends (or fails), and the stream raises `SerialLinkError` naming the port.

`serve_serial_port` keeps a port served across unplugs (the server's side):
a port that cannot be opened is reported and retried with doubling backoff;
a port that was open and vanished is reported once and then tried every
`REOPEN_POLL_S`, silently, while its path is missing, so a replugged adapter
is open again within that time and the rover's session resumes. A device
that comes back under another kernel name (``/dev/ttyUSB0`` then
``/dev/ttyUSB1``) is found again through a stable name, udev's
``/dev/serial/by-id/...`` symlink, given as the port. `open_serial_stream_within`
is the same wait for one side that opens the port itself (a rover).
"""

from __future__ import annotations

import errno
import math
import os
import termios
from collections.abc import Awaitable, Callable
from typing import Any

import trio

__all__ = ["SerialLinkError", "open_serial_stream", "open_serial_stream_within",
           "serve_serial_port", "ThreadSerialStream", "REOPEN_POLL_S"]

_THREAD_READ_TIMEOUT_S = 0.05
REOPEN_POLL_S = 0.25
"""How often a vanished port is tried while it is awaited back [s]."""


class SerialLinkError(OSError):
    """Raised when a serial port cannot be opened or fails (unplugged).

    ``errno`` is ``ENOENT`` when the port's path does not exist (no device there).
    """

    @property
    def missing(self) -> bool:
        """The port's path does not exist (the device is unplugged, or not yet there)."""
        return self.errno == errno.ENOENT


def _open_port(url: str, baud: int):
    import serial  # pyserial; imported here so the server starts without a port

    try:
        return serial.serial_for_url(url, baudrate=baud, timeout=_THREAD_READ_TIMEOUT_S,
                                     write_timeout=2.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        error = SerialLinkError(f"cannot open serial port {url} at {baud} baud: {msg}")
        error.errno = getattr(exc, "errno", None)
        raise error from None


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
        """Bytes from the port; an unplugged device raises at once (never b"")."""
        try:
            data = await self._fd.receive_some(max_bytes)
        except (OSError, trio.BrokenResourceError) as exc:
            raise SerialLinkError(f"serial port {self.port.port} failed: {exc}") from None
        if not data:  # VMIN=1: end of file is the tty's hang-up, the device went away
            raise SerialLinkError(f"serial port {self.port.port} hung up (device unplugged)")
        return data

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


async def open_serial_stream_within(url: str, baud: int, within_s: float,
                                    poll_s: float = REOPEN_POLL_S):
    """`open_serial_stream`, trying again every ``poll_s`` [s] while the port's path is
    missing, for up to ``within_s`` [s] (``math.inf``: until it appears).

    Raises:
        SerialLinkError: the port failed to open for another reason than a missing
            path, or was still missing after ``within_s``.
    """
    deadline = trio.current_time() + within_s
    while True:
        try:
            return open_serial_stream(url, baud)
        except SerialLinkError as exc:
            if not exc.missing or trio.current_time() + poll_s > deadline:
                raise
        await trio.sleep(poll_s)


Report = Callable[[str, dict[str, Any]], None]
"""``report(kind, data)``: ``link_open`` or ``link_error`` with ``link``, ``error``,
``retry_s``."""


async def serve_serial_port(url: str, baud: int, serve: Callable[[Any], Awaitable[None]],
                            report: Report, retry_s: tuple[float, float] = (1.0, 30.0),
                            poll_s: float = REOPEN_POLL_S) -> None:
    """Open the port and ``await serve(stream)`` until cancelled, across unplugs.

    Events through ``report``: ``link_open`` each time the port opens;
    ``link_error`` for each failed open (then a wait doubling from ``retry_s[0]``
    to ``retry_s[1]``) and once when an open port fails or vanishes. A port that
    vanished is then tried every ``poll_s`` while its path is missing, without
    an event each time, and served again as soon as it opens.
    """
    name = f"serial:{url},{baud}"
    first, most = retry_s
    delay = first
    awaited = False  # the port was open and went away: wait for it quietly
    while True:
        try:
            stream = await open_serial_stream_within(url, baud, math.inf if awaited else 0,
                                                     poll_s)
        except SerialLinkError as exc:
            report("link_error", {"link": name, "error": str(exc), "retry_s": delay})
            awaited = False
            await trio.sleep(delay)
            delay = min(delay * 2, most)
            continue
        report("link_open", {"link": name, "detail": f"serial port {url} open"})
        delay = first
        awaited = False
        try:
            await serve(stream)
        except* SerialLinkError as failed:  # raised by the reader or the writer task
            awaited = True
            report("link_error", {"link": name, "error": str(failed.exceptions[0]),
                                  "retry_s": poll_s})
        # vanished: try again soon; closed by the server: after the first retry delay
        await trio.sleep(poll_s if awaited else delay)
