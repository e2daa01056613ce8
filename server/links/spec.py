"""Link strings, as MAVProxy users type them: one parser for every command.

The forms mean what they mean in MAVProxy (``--master``, ``--out``): ``tcp:``
connects, ``tcpin:`` listens, ``udp:`` and ``udpin:`` receive (listen),
``udpout:`` sends, a device path with an optional ``,BAUD`` is a serial port.

=================================  ============================================
string                             meaning
=================================  ============================================
``tcp:10.0.0.2:7878``              connect to a TCP address (a rover to the
                                   server; ``--rover ID=tcp:HOST:PORT``: the
                                   server to a rover listening there)
``tcpin:0.0.0.0:7878``             listen there for the other side to connect
``udp:0.0.0.0:7878``               receive UDP datagrams there (listen; the
``udpin:0.0.0.0:7878``             same as ``udpin:``)
``udpout:10.0.0.2:7878``           send UDP datagrams there (a rover to the
                                   server's ``udpin:`` address)
``serial:/dev/ttyUSB0,115200``     a serial port and baud rate
``serial:/dev/ttyUSB0``            ... at 115200 baud
``/dev/ttyUSB0,57600``, ``COM3``   a bare device path, with or without a baud
``/dev/serial/by-id/usb-...``      udev's stable name of a USB adapter: it
                                   stays when the kernel renumbers the adapter
                                   (``ttyUSB0`` coming back as ``ttyUSB1``)
``serial:loop://,115200``          any pyserial URL: ``loop://``, ``socket://h:p``
``tcp``, ``udp``                   (``--rover ID=...``) this rover connects in
                                   to, or sends to, the ``--listen`` address
``sim``                            a simulated rover in the same process
``pty``                            (``hideseek rover``) a new pty pair: the rover
                                   holds one end, the server opens the other
=================================  ============================================

Each command takes some of these (a `LinkUse`: `ROVER_LINK`, `LISTEN`,
`SERVE_ROVER`, `PLAY_ROVER`, `CHECK_ROVER`); `parse_link_for` refuses any other with one
line listing the forms that command takes. `parse_link` parses any form.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

__all__ = ["LinkSpec", "LinkUse", "parse_link", "parse_link_for", "is_loopback",
           "DEFAULT_BAUD", "ROVER_LINK", "LISTEN", "SERVE_ROVER", "PLAY_ROVER",
           "CHECK_ROVER"]

_KINDS = ("tcp:HOST:PORT, tcpin:HOST:PORT, udp:HOST:PORT, udpin:HOST:PORT, "
          "udpout:HOST:PORT, serial:PORT[,BAUD], a device path[,BAUD], tcp, udp, sim or pty")
#: Baud rate of a serial link given without one (the WiFly module's default) [bit/s].
DEFAULT_BAUD = 115200


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """A parsed link string."""

    kind: str
    """``tcp_out`` (connect, ``tcp:``), ``tcp_in`` (listen, ``tcpin:``), ``udp_in``
    (receive, ``udp:`` and ``udpin:``), ``udp_out`` (send, ``udpout:``), ``serial``,
    ``tcp``, ``udp``, ``sim`` or ``pty``."""
    text: str
    """The string as given."""
    host: str = ""
    port: int = 0
    url: str = ""
    """pyserial port name or URL; for ``tcp_out``, ``socket://HOST:PORT`` (how the
    server's serial loop connects out to a rover listening there)."""
    baud: int = 0


def parse_link(text: str) -> LinkSpec:
    """Parse a link string (see the module docstring).

    Raises:
        ValueError: naming what is wrong, with the accepted forms.
    """
    t = text.strip()
    if t in ("tcp", "udp", "sim", "pty"):
        return LinkSpec(t, text)
    for prefix, kind in (("tcp:", "tcp_out"), ("tcpin:", "tcp_in"), ("udp:", "udp_in"),
                         ("udpin:", "udp_in"), ("udpout:", "udp_out")):
        if t.startswith(prefix):
            host, sep, port_s = t[len(prefix):].rpartition(":")
            if not sep or not host.strip("[]"):
                raise ValueError(f"{prefix[:-1]} link must be {prefix}HOST:PORT, got {text!r}")
            host = host.strip("[]")
            port = _int_in(port_s, f"{prefix[:-1]} port", 0, 65535, text)
            url = f"socket://{host}:{port}" if kind == "tcp_out" else ""
            return LinkSpec(kind, text, host=host, port=port, url=url,
                            baud=DEFAULT_BAUD if url else 0)
    if t.startswith("serial:"):
        return _serial(t[7:], text)
    if _is_device(t):
        return _serial(t, text)
    raise ValueError(f"link must be {_KINDS}, got {text!r}")


@dataclass(frozen=True, slots=True)
class LinkUse:
    """The link strings one option of one command takes."""

    option: str
    """The option, as refusals name it (``--link``)."""
    kinds: tuple[str, ...]
    """`LinkSpec` kinds taken."""
    forms: str
    """The forms taken, as people type them: every refusal lists them."""
    hints: tuple[tuple[str, str], ...] = ()
    """(kind, why it is not taken here), said after the forms for a kind not taken."""


ROVER_LINK = LinkUse(
    "--link", ("tcp_out", "tcp_in", "udp_out", "serial", "pty"),
    "tcp:HOST:PORT (connect to the server), tcpin:HOST:PORT (wait there for the server "
    "to connect), udpout:HOST:PORT (send datagrams to the server), serial:PORT[,BAUD] or "
    "PORT[,BAUD] (a serial port; 115200 baud by default) or pty (a new pty pair)",
    (("udp_in", "udp: and udpin: receive (listen), as in MAVProxy; a rover sends with "
                "udpout:HOST:PORT"),))
"""``hideseek rover --link``: where the server is, or how it reaches the rover."""
LISTEN = LinkUse(
    "--listen", ("tcp_in", "tcp_out", "udp_in"),
    "tcpin:HOST:PORT or tcp:HOST:PORT (accept TCP there), udpin:HOST:PORT or "
    "udp:HOST:PORT (receive UDP there) or none")
"""``serve``/``play --listen``: where rovers on ``tcp`` connect and rovers on ``udp`` send."""
_ATTACH = ("tcp (it connects to --listen), udp (it sends to --listen), tcp:HOST:PORT (the "
           "server connects to it there)")
_SERIAL = ("serial:PORT[,BAUD] or PORT[,BAUD] (a serial port; a /dev/serial/by-id/ name "
           "survives a renumbered adapter)")
SERVE_ROVER = LinkUse("--rover ID=LINK", ("tcp", "udp", "tcp_out", "serial", "sim"),
                      f"{_ATTACH}, {_SERIAL} or sim (simulated in this process)")
"""``serve --rover ID=LINK``: how each rover reaches the server."""
PLAY_ROVER = LinkUse("--rover ROLE=LINK", ("tcp", "udp", "tcp_out", "serial"),
                     f"{_ATTACH} or {_SERIAL}")
"""``play --rover ROLE=LINK``: a rover attached instead of simulated."""
CHECK_ROVER = LinkUse(
    "LINK", ("tcp_out", "tcp_in", "udp_in", "serial"),
    "tcp:HOST:PORT (connect to a rover waiting with --link tcpin:), tcpin:HOST:PORT (wait "
    "for a rover to connect), udpin:HOST:PORT or udp:HOST:PORT (receive its datagrams "
    f"there) or {_SERIAL}")
"""``check-rover LINK``: how the checker reaches the rover under check."""


def parse_link_for(text: str, use: LinkUse) -> LinkSpec:
    """Parse a link string for one option (``use``): only the forms it takes.

    Raises:
        ValueError: ``"{option} must be {forms}, got {text!r}"``, then why, when known.
    """
    try:
        spec = parse_link(text)
    except ValueError as exc:
        why = str(exc).removesuffix(f", got {text!r}")
        spec = None
    else:
        why = dict(use.hints).get(spec.kind, "")
    if spec is not None and spec.kind in use.kinds:
        return spec
    got = f"{use.option} must be {use.forms}, got {text!r}"
    raise ValueError(f"{got} ({why})" if why and not why.startswith("link must be") else got)


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
