"""What the server tells its watchers: events as they happen, and snapshots to draw.

Records only (frozen, no behaviour beyond formatting): the server builds them,
consoles, logs and headless runs read them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .protocol import GridMap, LinkStats, Pose
from .rover_telemetry import TelemetryView

__all__ = ["ServerEvent", "RoverView", "ServerSnapshot"]


@dataclass(frozen=True, slots=True)
class ServerEvent:
    """Something that happened, for consoles, logs and headless runs."""

    t: float
    """Server time [s] (Trio clock)."""
    kind: str
    """``hello``, ``link_up``, ``link_down``, ``link_open`` (a serial port opened),
    ``link_error``, ``bad_frame``, ``pose``, ``status``, ``map``, ``command``, ``refused``,
    ``phase``, ``report``, ``peer_error``; for attached rovers ``rover_event`` (a
    ``tm_event``), ``fault_sent``, ``fault_reply``, ``link_fault`` and
    ``link_fault_cleared``."""
    rover: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return self.format()

    def format(self, t0: float = 0.0) -> str:
        """One log line; times relative to ``t0`` [s]."""
        body = " ".join(f"{k}={v}" for k, v in self.data.items())
        return f"{self.t - t0:9.3f} {self.kind:<10} {self.rover:<10} {body}".rstrip()


@dataclass(frozen=True, slots=True)
class RoverView:
    """One rover as the console shows it."""

    id: str
    role: str
    link: str
    stats: LinkStats
    pose: Pose | None
    """Last reported pose (map frame)."""
    status: dict[str, Any]
    telemetry: TelemetryView | None = None
    """What the rover streams about its insides (attached rovers that offer it)."""
    faults: tuple[str, ...] = ()
    """``TARGET/KIND`` faults it takes over the protocol, then its link's (attached rovers)."""


@dataclass(frozen=True, slots=True)
class ServerSnapshot:
    """Everything a console draws, at one instant."""

    t: float
    game_id: int
    phase: str
    reason: str
    rovers: tuple[RoverView, ...]
    map: GridMap | None
    hide_spot: Pose | None
    guesses: tuple[Pose, ...]
    dropped_events: int
    connections: int = 0
    """TCP connections and UDP peers served now."""
    refused: dict[str, int] = field(default_factory=dict)
    """Totals since start: ``bad_frame``, ``auth_failed``, ``conn_closed`` (by the server)."""
