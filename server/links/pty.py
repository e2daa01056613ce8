"""A pseudo-terminal pair standing in for a serial cable.

``hideseek rover --link pty`` holds the master end (the rover's UART) and
prints the slave's path; the server opens that path like any serial port
(``serial:/dev/pts/5,115200``), through pyserial. The master end is read and
written through ``trio.lowlevel.FdStream``. The slave stays open in this
process too, in raw mode (no echo, no line editing), so the master does not
see end of file while no server has the port open: bytes written meanwhile
wait in the kernel's pty buffer (a few KiB) and then the writer waits.
"""

from __future__ import annotations

import os
import tty

import trio

__all__ = ["PtyCable", "open_pty_cable"]


class PtyCable:
    """The master end of a pty pair as a Trio byte stream; `path` is the other end.

    Made by `open_pty_cable`. ``aclose`` closes both ends.
    """

    def __init__(self, master: int, slave: int) -> None:
        self.path = os.ttyname(slave)
        """The slave's device path, to give the server as ``serial:PATH,BAUD``."""
        self._slave = slave
        self._stream = trio.lowlevel.FdStream(master)

    def __repr__(self) -> str:
        return f"<PtyCable {self.path}>"

    async def receive_some(self, max_bytes: int = 4096) -> bytes:
        """Bytes the server wrote to the slave end."""
        return await self._stream.receive_some(max_bytes)

    async def send_all(self, data: bytes) -> None:
        """Bytes for the server (waits while the pty buffer is full)."""
        await self._stream.send_all(data)

    async def aclose(self) -> None:
        """Close the master and the retained slave descriptor."""
        await self._stream.aclose()
        if self._slave >= 0:
            os.close(self._slave)
            self._slave = -1


def open_pty_cable() -> PtyCable:
    """A new pty pair, slave in raw mode.

    Raises:
        OSError: the system has no free pseudo-terminals.
    """
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        return PtyCable(master, slave)
    except BaseException:
        os.close(master)
        os.close(slave)
        raise
