"""Opening the link to the rover under check, with the openers of `server.links`.

=====================  ================================================
LINK                   the checker ...
=====================  ================================================
``tcp:HOST:PORT``      connects there (a rover waiting with
                       ``--link tcpin:HOST:PORT``); dropping the link
                       closes the connection and connects again
``tcpin:HOST:PORT``    listens there for a rover that connects
                       (``hideseek rover --link tcp:HOST:PORT``)
``udpin:HOST:PORT``    receives datagrams there (a rover sending with
                       ``--link udpout:HOST:PORT``), answering the first
                       source address heard; ``udp:`` is the same
``serial:PORT,BAUD``   opens the port (a device, a pty's other end, a
                       pyserial URL); dropping the link closes and
                       reopens it
=====================  ================================================
"""

from __future__ import annotations

from typing import Any

import trio

from ..links import LinkSpec, SerialLinkError, open_serial_stream, open_udp_endpoint
from ..links.spec import CHECK_ROVER, parse_link_for

__all__ = ["LinkUnreachable", "RoverLink", "parse_rover_link"]

_RETRY_S = 0.2  # between connection attempts while a rover listens again [s]


class LinkUnreachable(OSError):
    """Raised by `RoverLink.open` when the rover's address or port cannot be opened."""


def parse_rover_link(text: str) -> LinkSpec:
    """A LINK for `check_rover`.

    Raises:
        ValueError: not one of the forms of `CHECK_ROVER`, naming the string.
    """
    return parse_link_for(text, CHECK_ROVER)


class RoverLink:
    """Opens (and, for `RoverLink.reopen`, opens again) the byte stream to the rover.

    Args:
        spec: a parsed LINK (`parse_rover_link`).
    """

    def __init__(self, spec: LinkSpec) -> None:
        self.spec = spec
        self.kind = spec.kind
        """The `LinkSpec` kind."""
        self._listener: trio.SocketListener | None = None
        self._udp: Any = None
        self._peers: trio.MemorySendChannel | None = None
        self._peer_rx: trio.MemoryReceiveChannel | None = None

    @property
    def can_drop(self) -> bool:
        """Whether the link can be dropped and made again (not over UDP)."""
        return self.kind in ("tcp_out", "tcp_in", "serial")

    @property
    def speaks_first(self) -> bool:
        """Whether the checker opens with 'send hello first' (a serial port: opening it
        dropped whatever the rover said before, as the server does)."""
        return self.kind == "serial"

    async def open(self, nursery: trio.Nursery, wait_s: float) -> Any:
        """The first stream; a listening link waits at most ``wait_s`` [s] for the rover.

        Raises:
            LinkUnreachable: the address refuses, does not resolve, is in use, or the
                port is missing; or no rover came within ``wait_s``.
        """
        spec = self.spec
        try:
            if self.kind == "tcp_out":
                return await trio.open_tcp_stream(spec.host, spec.port)
            if self.kind == "serial":
                return open_serial_stream(spec.url, spec.baud)
            if self.kind == "tcp_in":
                listeners = await trio.open_tcp_listeners(spec.port, host=spec.host or None)
                self._listener = listeners[0]
                for extra in listeners[1:]:
                    await extra.aclose()
            else:
                self._udp = await open_udp_endpoint(spec.host, spec.port)
                self._peers, self._peer_rx = trio.open_memory_channel(1)
                nursery.start_soon(self._udp.serve, self._admit)
        except SerialLinkError as exc:
            raise LinkUnreachable(str(exc).splitlines()[0]) from None
        except OSError as exc:
            raise LinkUnreachable(f"cannot open {spec.text}: {_why(exc)}") from None
        stream = await self._accept(wait_s)
        if stream is None:
            raise LinkUnreachable(f"no rover came to {spec.text} within {wait_s:g} s")
        return stream

    async def reopen(self, wait_s: float) -> Any | None:
        """A new stream after a drop (the rover reconnects or listens again), or None when
        none came within ``wait_s`` [s]."""
        spec = self.spec
        with trio.move_on_after(wait_s):
            if self.kind == "serial":
                while True:
                    try:
                        return open_serial_stream(spec.url, spec.baud)
                    except SerialLinkError:
                        await trio.sleep(_RETRY_S)
            if self.kind == "tcp_out":
                while True:
                    try:
                        return await trio.open_tcp_stream(spec.host, spec.port)
                    except OSError:
                        await trio.sleep(_RETRY_S)
        if self.kind in ("tcp_in", "udp_in"):
            return await self._accept(wait_s)
        return None

    async def _accept(self, wait_s: float) -> Any | None:
        with trio.move_on_after(wait_s):
            if self._listener is not None:
                return await self._listener.accept()
            assert self._peer_rx is not None
            return await self._peer_rx.receive()
        return None

    def _admit(self, peer: Any, _host: str, _name: str) -> bool:
        """The UDP endpoint's admission: the first peer heard, one at a time."""
        assert self._peers is not None
        try:
            self._peers.send_nowait(peer)
        except trio.WouldBlock:
            return False
        return True

    async def aclose(self) -> None:
        """Stop listening."""
        if self._listener is not None:
            await self._listener.aclose()


def _why(exc: BaseException) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return text.splitlines()[0]
