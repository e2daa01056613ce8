"""What the server holds per link and per rover.

A `Conn` is one byte stream (TCP, serial or memory) with its writer queue and
the bounds kept on it; a `Rover` is one rover id's reliable session, which
outlives any one link (a reconnecting rover is bound to the same `Rover`).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import trio

from .link_faults import LinkFaultBook
from .protocol import LineBuffer, MapAssembler, Pose, ReliableSession
from .rover_telemetry import RoverTelemetry

__all__ = ["Conn", "Rover"]

_OUT_QUEUE = 64          # byte chunks waiting for a link's writer [chunks]


class Conn:
    """One byte stream, its writer queue, and what the server bounds about it."""

    def __init__(self, link: str, now: float, *, peer: str | None = None,
                 trusted: bool = False, timed: bool = False) -> None:
        self.link = link
        self.peer = peer
        """Peer address of a TCP link, None for other links."""
        self.trusted = trusted
        """A memory link: this process's simulated rover."""
        self.timed = timed
        """Hello and idle timeouts apply (TCP links)."""
        self.opened = now
        self.out_send, self.out_recv = trio.open_memory_channel[bytes](_OUT_QUEUE)
        self.lines = LineBuffer()
        self.rover: Rover | None = None
        self.pre = ReliableSession()  # answers errors before hello
        self.dropped = 0
        self.auth_failures = 0
        self.budget = 0.0
        self.budget_t = now
        self.close_reason: str | None = None
        self.scope = trio.CancelScope()
        self.pre_due = False
        """Errors queued on ``pre`` not yet transmitted."""
        self.delayed: deque[list[bytes]] = deque()
        """Received lines held back by a latency link fault, oldest first."""

    def close(self, reason: str) -> None:
        """Ask the stream's task to close the link (it sends what is queued first)."""
        if self.close_reason is None:
            self.close_reason = reason
        self.scope.cancel()


class Rover:
    """One rover id: its session, the link that speaks for it now, what it reported."""

    def __init__(self, rid: str, role: str, session: ReliableSession) -> None:
        self.id = rid
        self.role = role
        self.session = session
        self.conn: Conn | None = None
        self.row: int | None = None    # rover_sessions row of the current binding
        self.up_reported = False
        self.pose: Pose | None = None
        self.status: dict[str, Any] = {}
        self.assembler = MapAssembler()
        self.stored: tuple[int, tuple[int, int]] | None = None  # (game, pending mark) on disk
        self.gone_since: float | None = None
        self.telemetry: RoverTelemetry | None = None
        """What the rover streams, when its hello offered telemetry."""
        self.faults: tuple[str, ...] = ()
        """``TARGET/KIND`` faults the rover's hello says it accepts."""
        self.last_link = ""
        """Name of the link that last spoke for the rover (link faults follow it)."""
        self.link_faults: LinkFaultBook | None = None
        """Link faults the server applies to this rover's frames (made at the first)."""
