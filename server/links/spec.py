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
        port = _int_in(port_s, "tcp port", 0, 65535, text)
        return LinkSpec("tcp_listen", text, host=host, port=port)
    if t.startswith("serial:"):
        url, sep, baud_s = t[7:].rpartition(",")
        if not sep or not url:
            raise ValueError(f"serial link must be serial:PORT,BAUD, got {text!r}")
        baud = _int_in(baud_s, "serial baud", 50, 4_000_000, text)
        return LinkSpec("serial", text, url=url, baud=baud)
    raise ValueError(f"link must be {_KINDS}, got {text!r}")


def _int_in(value: str, what: str, lo: int, hi: int, text: str) -> int:
    """``value`` as an int in lo..hi; a ValueError naming ``what`` and the link otherwise."""
    try:
        n = int(value)
    except ValueError:
        raise ValueError(f"{what} must be a number, got {value!r} in {text!r}") from None
    if not lo <= n <= hi:
        raise ValueError(f"{what} must be {lo}..{hi}, got {n}")
    return n


def is_loopback(host: str) -> bool:
    """True when ``host`` names only this machine (``localhost``, 127.x, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
