"""How a game server is set up: `ServerConfig` (identity, limits, storage)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .protocol import DEFAULT_INTERVALS, DEFAULT_SHARE, Pose

__all__ = ["ServerConfig"]


@dataclass(frozen=True, slots=True)
class ServerConfig:
    """How the server is set up."""

    tokens: dict[str, str] = field(default_factory=dict)
    """Rover id -> token that rover's hello must carry; key ``*`` for every rover."""
    origins: dict[str, Pose] = field(default_factory=dict)
    """Start pose in the ROOM frame [cm, deg] by rover id or by role; an ``(x, y, heading)``
    sequence is taken as the `Pose` it spells."""
    heartbeat_s: float = 1.0
    down_after_s: float = 5.0
    serial_retry_s: tuple[float, float] = (1.0, 30.0)
    """Backoff between attempts to open a serial port: first, most [s]."""
    rovers: frozenset[str] = frozenset()
    """Rover ids the server was given: the only ids a TCP or serial link may say hello as."""
    open_enrolment: bool = False
    """Welcome any well-formed id on TCP and serial links (tokens still apply)."""
    simulated: tuple[str, ...] = ()
    """Roles played by simulated rovers in this process: no other link may claim them."""
    max_connections: int = 64
    """Connections held at once at most: TCP connections and UDP peer addresses together."""
    max_pending_per_address: int = 16
    """Connections (TCP, UDP peers) from one address that have not said an accepted hello,
    at most."""
    max_waiting: int = 64
    """TCP connections beyond those two caps held at most while the server reads their
    first line (an accepted hello makes room for itself; `server.connections`)."""
    hello_timeout_s: float = 5.0
    """A TCP connection or UDP peer that has not authenticated by then is closed [s]."""
    auth_failures: int = 5
    """Failed hellos after which a link is closed."""
    bad_frame_budget: float = 50.0
    """Bad frames a TCP link (or UDP peer) may send in a burst before it is closed."""
    bad_frame_rate: float = 5.0
    """Bad frames per second a TCP link (or UDP peer) may send on and on [1/s]."""
    max_sessions: int = 64
    """Rover sessions kept at most."""
    reclaim_after_s: float = 60.0
    """A session whose link is gone and that plays no role is forgotten after this [s]."""
    summary_s: float = 10.0
    """Shortest time between two stored summaries of bad frames or auth failures [s]."""
    resume: bool = False
    """Play on the store's newest game when it is unfinished, instead of a new one."""
    telemetry: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_INTERVALS))
    """Interval per telemetry stream asked of a rover that offers it [s] (0 = as it
    happens); a stream left out is not asked for."""
    telemetry_share: float = DEFAULT_SHARE
    """Largest share of a link's bytes a rover's telemetry may use, said in the welcome."""
    seed: int = 1
    """Seeds the link faults' generators (one per rover id)."""

    def __post_init__(self) -> None:
        origins = {rid: p if isinstance(p, Pose) else Pose(*p) for rid, p in self.origins.items()}
        object.__setattr__(self, "origins", origins)
