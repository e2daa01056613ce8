"""Link strings, as MAVProxy users type them.

=================================  ============================================
string                             meaning
=================================  ============================================
``tcp:127.0.0.1:7878``             a TCP address: where the connecting side
                                   connects (a rover, or with ``--rover
                                   ID=tcp:HOST:PORT`` the server, to a rover
                                   listening there), or ``--listen``'s address
``tcpin:0.0.0.0:7878``             listen there for the other side to connect
                                   (``hideseek rover --link tcpin:...``: the
                                   rover waits for the server)
``tcp``                            (``--rover ID=tcp``) this rover connects in,
                                   to ``--listen``
``udp:127.0.0.1:7878``             a UDP address: where a rover sends its
                                   datagrams, or ``--listen``'s address (the
                                   server receives there; MAVProxy's ``udpin``)
``udpin:0.0.0.0:7878``             ``--listen`` only: the same as ``udp:``
``udp``                            (``--rover ID=udp``) this rover sends to the
                                   server's UDP ``--listen`` address
``serial:/dev/ttyUSB0,115200``     a serial port and baud rate
``serial:/dev/ttyUSB0``            ... at 115200 baud
``/dev/ttyUSB0,57600``, ``COM3``   a bare device path, with or without a baud
``serial:loop://,115200``          any pyserial URL: ``loop://``, ``socket://h:p``
``sim``                            a simulated rover in the same process
``pty``                            (``hideseek rover``) a new pty pair: the rover
                                   holds one end, the server opens the other
=================================  ============================================
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

__all__ = ["LinkSpec", "parse_link", "is_loopback", "DEFAULT_BAUD"]

_KINDS = ("tcp:HOST:PORT, tcpin:HOST:PORT, tcp, udp:HOST:PORT, udpin:HOST:PORT, udp, "
          "serial:PORT[,BAUD], a device path[,BAUD], sim or pty")
#: Baud rate of a serial link given without one (the WiFly module's default) [bit/s].
DEFAULT_BAUD = 115200


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """A parsed link string."""

    kind: str
    """``tcp_listen`` (a TCP address, ``tcp:``), ``tcp_in`` (listen, ``tcpin:``), ``tcp``,
    ``udp_listen`` (a UDP address, ``udp:``), ``udp_in`` (listen, ``udpin:``), ``udp``,
    ``serial``, ``sim`` or ``pty``."""
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
    if t in ("tcp", "udp", "sim", "pty"):
        return LinkSpec(t, text)
    for prefix, kind in (("tcp:", "tcp_listen"), ("tcpin:", "tcp_in"), ("udp:", "udp_listen"),
                         ("udpin:", "udp_in")):
        if t.startswith(prefix):
            host, sep, port_s = t[len(prefix):].rpartition(":")
            if not sep or not host.strip("[]"):
                raise ValueError(f"{prefix[:-1]} link must be {prefix}HOST:PORT, got {text!r}")
            host = host.strip("[]")
            port = _int_in(port_s, f"{prefix[:-1]} port", 0, 65535, text)
            return LinkSpec(kind, text, host=host, port=port)
    if t.startswith("serial:"):
        return _serial(t[7:], text)
    if _is_device(t):
        return _serial(t, text)
    raise ValueError(f"link must be {_KINDS}, got {text!r}")


def _serial(port_baud: str, text: str) -> LinkSpec:
    """``PORT`` or ``PORT,BAUD`` (default `DEFAULT_BAUD`)."""
    url, sep, baud_s = port_baud.rpartition(",")
    if not sep:
        url, baud = port_baud, DEFAULT_BAUD
    else:
        baud = _int_in(baud_s, "serial baud", 50, 4_000_000, text)
    if not url.strip():
        raise ValueError(f"serial link must be serial:PORT[,BAUD], got {text!r}")
    return LinkSpec("serial", text, url=url.strip(), baud=baud)


def _is_device(text: str) -> bool:
    """A bare serial device: a path (``/dev/ttyUSB0``) or a Windows ``COMn``."""
    port = text.partition(",")[0]
    return port.startswith("/") or (port.upper().startswith("COM") and port[3:].isdigit())


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
