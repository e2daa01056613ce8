"""Link strings: ``tcp:HOST:PORT``, ``tcp``, ``serial:PORT,BAUD``, ``sim``, ``pty``.

=============================  ================================================
string                         meaning
=============================  ================================================
``tcp:127.0.0.1:7878``         listen address for rovers connecting over TCP
``tcp``                        (``--rover ID=tcp``) this rover connects over TCP
``serial:/dev/ttyUSB0,115200`` a serial port and baud rate (MAVProxy style)
``serial:loop://,115200``      any pyserial URL: ``loop://``, ``socket://h:p``
``sim``                        a simulated rover in the same process
``pty``                        (``hideseek rover``) a new pty pair: the rover
                               holds one end, the server opens the other
=============================  ================================================

For a rover (``hideseek rover --link``), ``tcp:HOST:PORT`` is where it
connects, as a WiFly module would.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

__all__ = ["LinkSpec", "parse_link", "is_loopback"]

_KINDS = "tcp:HOST:PORT, tcp, serial:PORT,BAUD, sim or pty"


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """A parsed link string."""

    kind: str
    """``tcp_listen``, ``tcp``, ``serial``, ``sim`` or ``pty``."""
    text: str
    """The string as given."""
    host: str = ""
    port: int = 0
    url: str = ""
    """pyserial port name or URL."""
    baud: int = 0


def parse_link(text: str) -> LinkSpec:
    """Parse a link string (see the module docstring).

    Raises:
        ValueError: naming what is wrong, with the accepted forms.
    """
    t = text.strip()
    if t in ("tcp", "sim", "pty"):
        return LinkSpec(t, text)
    if t.startswith("tcp:"):
        host, sep, port_s = t[4:].rpartition(":")
        if not sep or not host:
            raise ValueError(f"tcp link must be tcp:HOST:PORT, got {text!r}")
        host = host.strip("[]")
        try:
            port = int(port_s)
        except ValueError:
            raise ValueError(f"tcp port must be a number, got {port_s!r} in {text!r}") from None
        if not 0 <= port <= 65535:
            raise ValueError(f"tcp port must be 0..65535, got {port}")
        return LinkSpec("tcp_listen", text, host=host, port=port)
    if t.startswith("serial:"):
        url, sep, baud_s = t[7:].rpartition(",")
        if not sep or not url:
            raise ValueError(f"serial link must be serial:PORT,BAUD, got {text!r}")
        try:
            baud = int(baud_s)
        except ValueError:
            raise ValueError(f"serial baud must be a number, got {baud_s!r} in {text!r}") from None
        if not 50 <= baud <= 4_000_000:
            raise ValueError(f"serial baud must be 50..4000000, got {baud}")
        return LinkSpec("serial", text, url=url, baud=baud)
    raise ValueError(f"link must be {_KINDS}, got {text!r}")


def is_loopback(host: str) -> bool:
    """True when ``host`` names only this machine (``localhost``, 127.x, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
