"""Byte links between the server and rovers: memory, TCP, UDP, serial.

Every link gives the server a Trio byte stream (``receive_some``,
``send_all``, ``aclose``); `server.Server.serve_stream` speaks the protocol
over it. Link strings are parsed by `parse_link`.
"""

from .memory import MemoryLink
from .pty import PtyCable, open_pty_cable
from .serial import (
    SerialLinkError,
    ThreadSerialStream,
    open_serial_stream,
    open_serial_stream_within,
    serve_serial_port,
)
from .spec import LinkSpec, is_loopback, parse_link
from .udp import UdpEndpoint, UdpPeer, UdpStream, open_udp_endpoint, open_udp_stream

__all__ = ["MemoryLink", "SerialLinkError", "ThreadSerialStream", "open_serial_stream",
           "open_serial_stream_within", "serve_serial_port",
           "LinkSpec", "is_loopback", "parse_link", "PtyCable", "open_pty_cable",
           "UdpEndpoint", "UdpPeer", "UdpStream", "open_udp_endpoint", "open_udp_stream"]
