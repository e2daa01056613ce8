"""The game server: rover sessions over links, the game, storage, operator API.

Plain Trio (nurseries, memory channels, cancel scopes). One `Server` per
process, opened with `open_server`::

    async with open_server(store, ServerConfig(...)) as server:
        port = await server.listen_tcp("127.0.0.1", 7878)
        link = server.attach_memory(outbound=rover_wifly.receive)   # simulated rover
        server.start_serial("/dev/ttyUSB0", 115200)                 # real rover on a cable
        events = server.subscribe()
        result = await server.command("start_mapping")

Each link carries one byte stream. Its first frame must be ``hello``; the
server then binds the stream to that rover's `ReliableSession` (kept per rover
id, so a reconnecting rover resumes where it left off) and answers
``welcome``. The server knows the room only from what rovers send.

Events (`ServerEvent`) go to every subscriber's bounded channel (a slow
subscriber loses events, counted in ``dropped_events``) and, except
telemetry, to the store's event log.

Trust (docs/protocol.md section 4 says the same to rover authors):

* A memory link is this process's own simulated rover: trusted. Every other
  link (TCP, serial) must say a ``hello`` for an id the server was given
  (``ServerConfig.rovers``), unless ``open_enrolment``; it may never claim a
  simulated rover's role, nor an id bound to a memory link.
* Tokens (per rover id, or ``*`` for all) are compared in constant time. A
  TCP or UDP peer that is not loopback must give one for every id.
* A hello for an id whose session is live on another link is accepted only
  with that id's token, or, with no token for the id, once the old link has
  been silent ``down_after_s``. One rover id per link.
* A link that fails authentication ``auth_failures`` times is closed; an
  address that keeps failing is blocked with a doubling backoff (`PeerBackoff`).

Bounds on TCP links, and on UDP peers (`server.links.udp`: each peer address
is a connection, refused by dropping its datagrams): at most
``max_connections`` at once and ``max_pending_per_address`` unauthenticated
ones per address; beyond them at most ``max_waiting`` TCP connections wait for
their first line, and one whose first line is an accepted hello makes room
for itself by closing an unauthenticated one (`server.connections`: the accept
loop does this cheaply, which keeps the kernel's accept queue short under a
flood), ``hello_timeout_s`` to authenticate, closed after ``down_after_s`` of
silence, and a bad-frame budget (a token bucket) per link. Bad frames, auth
failures and closes are counted in memory and stored as one summary per ``summary_s`` (`BurstLog`).
Sessions of rovers whose link is gone are reclaimed after ``reclaim_after_s``
unless they play a role. Running out of file descriptors slows accepting,
with one event per episode.

Durability: the game's phase, map, state and each rover's unacknowledged
frames are stored as they change; with ``resume`` a server opened on a store
whose newest game is unfinished plays that game on (see `server.store`).

The parts, one module each, share the state in `server.core`:
`server.connections` (links, accept loop, bounds), `server.hello` (identity),
`server.frames` (game frames), `server.durability` (the store), `server.rover_faults`
(faults into attached rovers and on their links). A new kind of
link registers below, beside `attach_memory`, `listen_tcp` and `start_serial`.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import AsyncIterator, Callable
from typing import Any

import trio

from .config import ServerConfig
from .connections import Connections
from .durability import Durability
from .frames import MAX_MAP_CHUNKS, GameFrames
from .game import Result
from .hello import PROTOCOL_NAME, Hellos
from .links.memory import MemoryLink
from .links.spec import is_loopback
from .links.udp import open_udp_endpoint
from .protocol import Fault, Frame, FrameError
from .rover_faults import RoverFaults
from .store import Store
from .trust import beyond_loopback_refusal
from .views import RoverView, ServerEvent, ServerSnapshot

__all__ = ["ServerConfig", "ServerEvent", "RoverView", "ServerSnapshot", "Server",
           "open_server", "PROTOCOL_NAME", "MAX_MAP_CHUNKS"]

_SUBSCRIBER_QUEUE = 512  # events waiting for a slow subscriber [events]
_ROLE_OF_COMMAND = {"start_mapping": "mapper", "stop_mapping": "mapper", "hide": "hider",
                    "seek": "seeker"}


class Server(Connections, Hellos, GameFrames, Durability, RoverFaults):
    """The game server (see the module docstring). Create with `open_server`."""

    def __init__(self, store: Store, config: ServerConfig, nursery: trio.Nursery) -> None:
        super().__init__(store, config, nursery)
        if config.resume:
            self._resume(trio.current_time())
        if not self.game_id:
            self.game_id = store.new_game(trio.current_time())

    # -- operator API -----------------------------------------------------------------

    async def command(self, name: str, **kwargs: Any) -> Result:
        """Run an operator command (``start_mapping``, ``stop_mapping``, ``hide``,
        ``seek``, ``new_game``); refused ones come back with ``ok=False`` and a reason.

        ``hide``/``seek`` take ``x``, ``y`` [cm], optional ``heading`` [deg] and
        ``frame`` (``"map"``, the default, or ``"room"``); ``seek`` also ``within``
        [cm], the radius the seeker searches round the point (see `Game.command`).
        """
        await trio.lowlevel.checkpoint()
        role = _ROLE_OF_COMMAND.get(name)
        if role is not None and role not in self._role:
            result = Result(False, f"no {role} has said hello yet")
        else:
            try:
                result = self.game.command(name, **kwargs)
            except TypeError as exc:
                result = Result(False, f"bad arguments for {name}: {exc}")
        self._emit("command" if result.ok else "refused",
                   data={"command": name, **kwargs, "reason": result.reason})
        if not result.ok:
            return result
        if name == "new_game":
            self._end_game_for_new()
        self._apply(result)
        return result

    def subscribe(self, capacity: int = _SUBSCRIBER_QUEUE) -> trio.MemoryReceiveChannel:
        """A channel receiving every `ServerEvent` from now on (bounded: overflow is dropped)."""
        send, recv = trio.open_memory_channel[ServerEvent](capacity)
        self._subscribers.append(send)
        return recv

    def observe_frames(self, observer: Callable[[str, str, Frame], None]) -> None:
        """Call ``observer(rover_id, role, frame)`` for every frame the reliable layer
        delivers to the game logic, in order, exactly as often as it is delivered.

        For test harnesses that check end-to-end delivery (each ``seq`` exactly
        once); the observer runs inline, so it must be quick and must not raise.
        """
        self._frame_observers.append(observer)

    def snapshot(self) -> ServerSnapshot:
        """The state a console draws (cheap; call it at the UI's frame rate)."""
        now = trio.current_time()
        rovers = tuple(RoverView(r.id, r.role, r.conn.link if r.conn else "",
                                 r.session.stats(now), r.pose, dict(r.status),
                                 r.telemetry.view(now) if r.telemetry else None,
                                 self.rover_fault_catalogue(r.id))
                       for r in self._rovers.values())
        g = self.game
        return ServerSnapshot(now, self.game_id, str(g.phase), g.last_reason, rovers, g.map,
                              g.hide_spot, tuple(g.guesses), self.dropped_events,
                              len(self._tcp), dict(self._bursts.total))

    # -- links ------------------------------------------------------------------------

    def attach_memory(self, outbound: Callable[[bytes], None], *, name: str = "memory",
                      capacity: int = 65536, trusted: bool = True, peer: str | None = None,
                      timed: bool = False) -> MemoryLink:
        """A link for a simulated rover in this process; the server serves it until closed.

        ``trusted=False`` treats it as a link from outside (identity rules apply;
        ``peer`` and ``timed`` as for a TCP link from that address), for tests
        that play an outside rover without a socket.
        """
        link = MemoryLink(outbound, capacity=capacity, name=name)
        self._nursery.start_soon(functools.partial(self.serve_stream, link, name,
                                                   trusted=trusted, peer=peer, timed=timed))
        return link

    async def listen_tcp(self, host: str, port: int) -> int:
        """Accept rovers over TCP; return the bound port (useful with ``port=0``).

        Raises:
            ValueError: a non-loopback address while some accepted id has no token.
        """
        self._check_listen(host)
        listeners = await trio.open_tcp_listeners(port, host=host)
        for listener in listeners:
            self._nursery.start_soon(self._accept_loop, listener)
        return listeners[0].socket.getsockname()[1]

    async def listen_udp(self, host: str, port: int) -> int:
        """Accept rovers over UDP (`server.links.udp`: each peer address is a connection,
        bounded as TCP connections are); return the bound port.

        Raises:
            ValueError: as `listen_tcp`.
            OSError: the address is in use or does not resolve.
        """
        self._check_listen(host)
        endpoint = await open_udp_endpoint(host, port)
        self._nursery.start_soon(endpoint.serve, self._admit_peer)
        return endpoint.port

    def _check_listen(self, host: str) -> None:
        if not is_loopback(host):
            refusal = beyond_loopback_refusal(host, self.config)
            if refusal:
                raise ValueError(refusal)

    def start_serial(self, url: str, baud: int) -> None:
        """Serve a serial port; a missing or unplugged port is reported and retried."""
        self._nursery.start_soon(self._serve_serial, url, baud)

    async def serve_stream(self, stream: Any, link: str, *, peer: str | None = None,
                           trusted: bool = False, timed: bool = False,
                           ask_hello: bool = False) -> None:
        """Speak the protocol over one byte stream until it ends or the server closes it.

        ``trusted``: a memory link of a simulated rover; ``peer``: the TCP peer
        address; ``timed``: hello and idle timeouts and the connection cap apply;
        ``ask_hello``: the server speaks first, with ``send hello first`` (a serial
        port: opening it flushed whatever the rover sent before, its hello too).

        Raises:
            SerialLinkError: from a serial stream that failed (the caller retries).
        """
        conn = self._new_conn(link, peer=peer, trusted=trusted, timed=timed)
        if ask_hello:
            conn.pre.send_error(FrameError(Fault.NOT_ALLOWED, "send hello first"))
            self._flush_conn(conn)
        await self._serve_conn(stream, conn)

    # -- time ---------------------------------------------------------------------------

    async def _timer(self) -> None:
        """Heartbeats, resends, link up/down and summaries, each at its deadline."""
        while True:
            now = trio.current_time()
            deadline = now + 1.0
            for rover in list(self._rovers.values()):
                up = rover.session.is_up(now)
                if up != rover.up_reported:
                    rover.up_reported = up
                    self._emit("link_up" if up else "link_down", rover.id,
                               {"link": rover.conn.link if rover.conn else ""})
                if rover.conn is not None:
                    due = rover.session.next_deadline(now)
                    if due <= now:
                        self._flush_conn(rover.conn)
                        self._persist(rover)
                        due = rover.session.next_deadline(now)  # after what was sent
                    deadline = min(deadline, due)
                if up:
                    deadline = min(deadline, (rover.session.last_heard or now)
                                   + rover.session.down_after_s)
            self._reclaim(now)
            if self._link_seeds:
                deadline = min(deadline, self._expire_link_faults(now))
            for kind in self._bursts.due(now):
                self._emit(kind + "_summary", data=self._bursts.take(kind, now))
            self._kick.clear()
            await self._kick.wait_until(max(deadline, now + 1e-3))


@contextlib.asynccontextmanager
async def open_server(store: Store, config: ServerConfig | None = None
                      ) -> AsyncIterator[Server]:
    """Run a `Server` for the duration of the ``async with`` block; links close on exit."""
    async with trio.open_nursery() as nursery:
        server = Server(store, config or ServerConfig(), nursery)
        nursery.start_soon(server._timer)
        try:
            yield server
        finally:
            server.close_game()
            nursery.cancel_scope.cancel()
