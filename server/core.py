"""The state every part of the server shares, and the two acts every part performs.

`ServerCore` holds the rovers, roles, links and game that the parts of the
server (`server.connections`, `server.hello`, `server.frames`,
`server.durability`) read and change; `server.server.Server` joins those parts
into one class, so a part calls another's methods through ``self`` (a link's task
hands a ``hello`` to `server.hello.Hellos._on_hello`, a game frame to
`server.frames.GameFrames._on_frame`).
Every part emits events (`_emit`: to each subscriber's bounded channel and,
except telemetry, to the store's event log) and transmits what a session has
queued (`_flush_conn`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import trio

from .config import ServerConfig
from .game import Game
from .guard import BurstLog, PeerBackoff
from .kick import Kick
from .peers import Conn, Rover
from .protocol import Frame, Pose
from .store import Store
from .views import ServerEvent

__all__ = ["ServerCore"]


class ServerCore:
    """The shared state of a `Server` (see `server.server`); not used alone."""

    def __init__(self, store: Store, config: ServerConfig, nursery: trio.Nursery) -> None:
        self.store = store
        self.config = config
        self._nursery = nursery
        self._rovers: dict[str, Rover] = {}
        self._role: dict[str, str] = {}         # role -> rover id (last hello wins)
        self._sim_roles: set[str] = set(config.simulated)
        self._start_poses: dict[str, Pose] = {}
        self._subscribers: list[trio.MemorySendChannel[ServerEvent]] = []
        self._frame_observers: list[Callable[[str, str, Frame], None]] = []
        self.dropped_events = 0
        self._kick = Kick()  # the timer's wake-up (`Server._timer`)
        self._map_id = 0
        self._tcp: dict[Conn, None] = {}        # open TCP links, oldest first
        self._backoff = PeerBackoff(threshold=config.auth_failures)
        self._bursts = BurstLog(config.summary_s)
        self._starved = False                   # accept is out of descriptors
        self.game = Game(start_poses=self._start_poses)
        self.game_id = 0
        self._fault_ids = store.last_fault_id()  # the last `fault` frame's id (past runs')
        self._link_seeds = 0                    # link-fault books made
        self.resumed: int | None = None
        """Id of the game this server plays on from an earlier run, None for a new game."""

    def _flush(self, rover: Rover) -> None:
        """Transmit what the rover's session has queued, if a link speaks for it."""
        if rover.conn is not None:
            self._flush_conn(rover.conn)

    def _flush_conn(self, conn: Conn) -> None:
        """Hand what the link's session has queued to its writer (a full writer queue drops it)."""
        session = conn.rover.session if conn.rover else conn.pre
        data = session.transmit(trio.current_time())
        if data and self._link_seeds:  # an operator has broken some rover's link
            data, delay = self._link_out(conn, data)  # type: ignore[attr-defined]
            if delay > 0 and data:
                self._nursery.start_soon(self._send_later, conn, data, delay)
                data = b""
        if data:
            try:
                conn.out_send.send_nowait(data)
            except (trio.WouldBlock, trio.ClosedResourceError):
                conn.dropped += 1  # reliable frames are resent; telemetry is lost
        self._kick.set()

    async def _send_later(self, conn: Conn, data: bytes, delay: float) -> None:
        """Hand ``data`` to the link's writer after ``delay`` [s] (a latency fault)."""
        await trio.sleep(delay)
        try:
            conn.out_send.send_nowait(data)
        except (trio.WouldBlock, trio.ClosedResourceError):
            conn.dropped += 1

    def _emit(self, kind: str, rover: str = "", data: dict[str, Any] | None = None, *,
              log: bool = True) -> None:
        """Send an event to every subscriber and, when ``log``, to the store's event log."""
        data = {k: v for k, v in (data or {}).items()
                if not (isinstance(v, float) and math.isnan(v))}
        event = ServerEvent(trio.current_time(), kind, rover, data)
        if log:
            self.store.log_event(kind, t=event.t, game_id=self.game_id, rover=rover, data=data)
        for ch in list(self._subscribers):
            try:
                ch.send_nowait(event)
            except trio.WouldBlock:
                self.dropped_events += 1
            except (trio.BrokenResourceError, trio.ClosedResourceError):
                self._subscribers.remove(ch)
