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
``max_connections`` at once (the oldest unauthenticated one makes room for a
new one) and ``max_pending_per_address``
unauthenticated ones per address (closed in the accept loop, which keeps the
kernel's accept queue short under a flood), ``hello_timeout_s`` to
authenticate, closed after ``down_after_s`` of silence, and a bad-frame
budget (a token bucket) per link. Bad frames, auth failures and closes are
counted in memory and stored as one summary per ``summary_s`` (`BurstLog`).
Sessions of rovers whose link is gone are reclaimed after ``reclaim_after_s``
unless they play a role. Running out of file descriptors slows accepting,
with one event per episode.

Durability: the game's phase, map, state and each rover's unacknowledged
frames are stored as they change; with ``resume`` a server opened on a store
whose newest game is unfinished plays that game on (see `server.store`).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import trio

from .config import ServerConfig
from .game import Game, Phase, Result
from .guard import BurstLog, PeerBackoff
from .links.memory import MemoryLink
from .links.serial import SerialLinkError, open_serial_stream
from .links.spec import is_loopback
from .links.udp import open_udp_endpoint
from .protocol import (
    ACK,
    CATALOGUE,
    HEARTBEAT,
    HELLO,
    MAP,
    WELCOME,
    Fault,
    Frame,
    FrameError,
    GridMap,
    Hello,
    LineBuffer,
    LinkStats,
    MapAssembler,
    MapError,
    OutboxFull,
    Pose,
    ReliableSession,
    decode_line,
    make_frame,
    map_chunks,
    read_data,
)
from .protocol.lines import TOO_LONG
from .store import Store, StoreError
from .trust import Held, admit, beyond_loopback_refusal

__all__ = ["ServerConfig", "ServerEvent", "RoverView", "ServerSnapshot", "Server",
           "open_server", "PROTOCOL_NAME", "MAX_MAP_CHUNKS"]

PROTOCOL_NAME = "hideseek/1"
_OUT_QUEUE = 64          # byte chunks waiting for a link's writer [chunks]
_SUBSCRIBER_QUEUE = 512  # events waiting for a slow subscriber [events]
_READ_SIZE = 4096        # bytes per read [bytes]
_ROLE_OF_COMMAND = {"start_mapping": "mapper", "stop_mapping": "mapper", "hide": "hider",
                    "seek": "seeker"}
MAX_MAP_CHUNKS = 256
"""Most chunks a map may have: the download to a hider or seeker must fit a session's
outbox at once, so a bigger upload is refused at its first chunk."""
_ACCEPT_STARVED = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)


@dataclass(frozen=True, slots=True)
class ServerEvent:
    """Something that happened, for consoles, logs and headless runs."""

    t: float
    """Server time [s] (Trio clock)."""
    kind: str
    """``hello``, ``link_up``, ``link_down``, ``link_error``, ``bad_frame``, ``pose``,
    ``status``, ``map``, ``command``, ``refused``, ``phase``, ``report``, ``peer_error``."""
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


class _Conn:
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
        self.rover: _Rover | None = None
        self.pre = ReliableSession()  # answers errors before hello
        self.dropped = 0
        self.auth_failures = 0
        self.budget = 0.0
        self.budget_t = now
        self.close_reason: str | None = None
        self.scope = trio.CancelScope()
        self.pre_due = False
        """Errors queued on ``pre`` not yet transmitted."""

    def close(self, reason: str) -> None:
        """Ask the stream's task to close the link (it sends what is queued first)."""
        if self.close_reason is None:
            self.close_reason = reason
        self.scope.cancel()


class _Rover:
    def __init__(self, rid: str, role: str, session: ReliableSession) -> None:
        self.id = rid
        self.role = role
        self.session = session
        self.conn: _Conn | None = None
        self.row: int | None = None    # rover_sessions row of the current binding
        self.up_reported = False
        self.pose: Pose | None = None
        self.status: dict[str, Any] = {}
        self.assembler = MapAssembler()
        self.stored: tuple[int, tuple[int, int]] | None = None  # (game, pending mark) on disk
        self.gone_since: float | None = None


class Server:
    """The game server (see the module docstring). Create with `open_server`."""

    def __init__(self, store: Store, config: ServerConfig, nursery: trio.Nursery) -> None:
        self.store = store
        self.config = config
        self._nursery = nursery
        self._rovers: dict[str, _Rover] = {}
        self._role: dict[str, str] = {}         # role -> rover id (last hello wins)
        self._sim_roles: set[str] = set(config.simulated)
        self._start_poses: dict[str, Pose] = {}
        self._subscribers: list[trio.MemorySendChannel[ServerEvent]] = []
        self._frame_observers: list[Callable[[str, str, Frame], None]] = []
        self.dropped_events = 0
        self._kick = trio.Event()
        self._map_id = 0
        self._tcp: dict[_Conn, None] = {}       # open TCP links, oldest first
        self._backoff = PeerBackoff(threshold=config.auth_failures)
        self._bursts = BurstLog(config.summary_s)
        self._starved = False                   # accept is out of descriptors
        self.game = Game(start_poses=self._start_poses)
        self.game_id = 0
        self.resumed: int | None = None
        """Id of the game this server plays on from an earlier run, None for a new game."""
        if config.resume:
            self._resume(trio.current_time())
        if not self.game_id:
            self.game_id = store.new_game(trio.current_time())

    def _resume(self, now: float) -> None:
        row = self.store.resumable_game()
        if row is None:
            return
        try:
            grid = self.store.load_map(row.map_id) if row.map_id is not None else None
            state = self.store.game_state(row.id)
            game = Game.restored(self._start_poses, row.phase, state, grid)
        except (StoreError, ValueError, TypeError) as exc:
            self.store.end_game(row.id, "stopped", f"stopped: could not resume ({exc})", now)
            return
        self.game, self.game_id, self.resumed = game, row.id, row.id
        self._map_id = int(state.get("map_seq", 0))
        self.store.resume_game(row.id)
        for role, rid in dict(state.get("roles", {})).items():
            self._role[str(role)] = str(rid)
        for rid, role, pending in self.store.rover_states(row.id):
            rover = self._new_rover(rid, role, now)
            self._restore_pending(rover, pending)
            origin = self.config.origins.get(rid, self.config.origins.get(role))
            if origin is not None:
                self._start_poses[role] = origin
        self._emit("resumed", data={"game": row.id, "phase": str(game.phase)})

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

    def _end_game_for_new(self) -> None:
        now = trio.current_time()
        old = self.store.game(self.game_id)
        if old.status != "finished":
            self.store.end_game(self.game_id, "stopped",
                                f"stopped by the operator (new game) in phase {old.phase}", now)
        self.game_id = self.store.new_game(now)
        for rover in self._rovers.values():
            rover.stored = None
            self._persist(rover)

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
                                 r.session.stats(now), r.pose, dict(r.status))
                       for r in self._rovers.values())
        g = self.game
        return ServerSnapshot(now, self.game_id, str(g.phase), g.last_reason, rovers, g.map,
                              g.hide_spot, tuple(g.guesses), self.dropped_events,
                              len(self._tcp), dict(self._bursts.total))

    def close_game(self) -> None:
        """Record that this server stops playing its game (clean shutdown): unless
        finished or stopped, it is interrupted, to be resumed by a later server."""
        now = trio.current_time()
        with contextlib.suppress(StoreError):
            if self.store.game(self.game_id).status == "running":
                self.store.end_game(self.game_id, "interrupted",
                                    f"interrupted: the server stopped in phase {self.game.phase}",
                                    now)
        for kind in self._bursts.pending():
            self._emit(kind + "_summary", data=self._bursts.take(kind, now))

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

    async def _accept_loop(self, listener: trio.SocketListener) -> None:
        delay = 0.0
        async with listener:
            while True:
                try:
                    stream = await listener.accept()
                except OSError as exc:
                    if exc.errno not in _ACCEPT_STARVED:
                        raise
                    if not self._starved:
                        self._starved = True
                        self._emit("accept_error", data={
                            "error": f"cannot accept: {exc.strerror}; accepting slowed until "
                                     "descriptors are free (raise 'ulimit -n' or lower "
                                     "max_connections)"})
                    delay = min(max(2 * delay, 0.05), 1.0)
                    await trio.sleep(delay)
                    continue
                if self._starved:
                    self._starved = False
                    self._emit("accept_resumed", data={"detail": "descriptors free again"})
                delay = 0.0
                self._admit_tcp(stream)

    def _admit_tcp(self, stream: trio.SocketStream) -> None:
        """Serve a new TCP connection, or close it at once (cheaply, in the accept loop,
        so a flood of connections drains the kernel's accept queue fast)."""
        try:
            peer = stream.socket.getpeername()
            addr, name = str(peer[0]), f"tcp:{peer[0]}:{peer[1]}"
        except OSError:
            addr, name = "", "tcp"
        if not self._admit_peer(stream, addr, name):
            stream.socket.close()

    def _admit_peer(self, stream: Any, addr: str, name: str) -> bool:
        """Serve a new connection (TCP, or a UDP peer address) within the bounds, or refuse it."""
        now = trio.current_time()
        cfg = self.config
        refuse = ""
        if addr and self._backoff.blocked_for(addr, now) > 0:
            refuse = "address blocked after failed hellos"
        elif sum(1 for c in self._tcp if c.rover is None and c.peer == addr) \
                >= cfg.max_pending_per_address:
            refuse = "too many connections without hello from one address"
        elif len(self._tcp) >= cfg.max_connections:
            oldest = next((c for c in self._tcp if c.rover is None), None)
            if oldest is None:
                refuse = "connection cap"
            else:
                oldest.close("evicted by a newer connection at the cap")
                del self._tcp[oldest]  # its slot is free now, whatever its task does next
        if refuse:
            self._count("conn_closed", refuse, name, now)
            return False
        conn = self._new_conn(name, peer=addr, timed=True)
        self._tcp[conn] = None
        self._nursery.start_soon(self._serve_conn, stream, conn)
        return True

    def start_serial(self, url: str, baud: int) -> None:
        """Serve a serial port; a missing or unplugged port is reported and retried."""
        self._nursery.start_soon(self._serve_serial, url, baud)

    async def _serve_serial(self, url: str, baud: int) -> None:
        name = f"serial:{url},{baud}"
        first, most = self.config.serial_retry_s
        delay = first
        while True:
            try:
                stream = open_serial_stream(url, baud)
            except SerialLinkError as exc:
                self._emit("link_error", data={"link": name, "error": str(exc),
                                               "retry_s": delay})
                await trio.sleep(delay)
                delay = min(delay * 2, most)
                continue
            delay = first
            try:
                await self.serve_stream(stream, name, ask_hello=True)
            except* SerialLinkError as failed:  # raised by the reader or the writer task
                self._emit("link_error", data={"link": name, "error": str(failed.exceptions[0]),
                                               "retry_s": delay})
            await trio.sleep(delay)

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

    def _new_conn(self, link: str, *, peer: str | None = None, trusted: bool = False,
                  timed: bool = False) -> _Conn:
        conn = _Conn(link, trio.current_time(), peer=peer, trusted=trusted, timed=timed)
        conn.budget = self.config.bad_frame_budget
        return conn

    async def _serve_conn(self, stream: Any, conn: _Conn) -> None:
        link, trusted = conn.link, conn.trusted
        try:
            async with trio.open_nursery() as nursery:
                nursery.start_soon(self._writer, stream, conn)
                with conn.scope:
                    while conn.close_reason is None:
                        with trio.move_on_at(self._conn_deadline(conn)) as timer:
                            try:
                                data = await stream.receive_some(_READ_SIZE)
                            except (trio.BrokenResourceError, ConnectionError) as exc:
                                self._link_error(conn, str(exc))
                                break
                        if timer.cancelled_caught:
                            conn.close_reason = ("no hello in time" if conn.rover is None
                                                 else "silent past the link-down time")
                            break
                        if not data:
                            break
                        self._on_bytes(conn, data)
                if trusted or conn.close_reason is None:
                    nursery.cancel_scope.cancel()
                else:  # let the writer send the error that says why, then close
                    self._count("conn_closed", conn.close_reason, link, trio.current_time())
                    conn.out_send.close()
                    nursery.cancel_scope.deadline = trio.current_time() + 1.0
        finally:
            self._tcp.pop(conn, None)
            rover = conn.rover
            if rover is not None and rover.conn is conn:
                rover.conn = None
                rover.gone_since = trio.current_time()
                if rover.row is not None:
                    self.store.close_rover_session(rover.row, trio.current_time())
            with trio.CancelScope(shield=True), contextlib.suppress(Exception):
                with trio.move_on_after(1):
                    await stream.aclose()

    def _conn_deadline(self, conn: _Conn) -> float:
        if not conn.timed:
            return math.inf
        if conn.rover is None:
            return conn.opened + self.config.hello_timeout_s
        heard = conn.rover.session.last_heard
        return (heard if heard is not None else conn.opened) + self.config.down_after_s

    def _link_error(self, conn: _Conn, error: str) -> None:
        if conn.rover is None and not conn.trusted:
            self._count("conn_closed", f"link error: {error}", conn.link, trio.current_time())
        else:
            self._emit("link_error", data={"link": conn.link, "error": error})

    async def _writer(self, stream: Any, conn: _Conn) -> None:
        async for data in conn.out_recv:
            try:
                await stream.send_all(data)
            except (trio.BrokenResourceError, trio.ClosedResourceError, ConnectionError):
                return

    # -- receiving --------------------------------------------------------------------

    def _on_bytes(self, conn: _Conn, data: bytes) -> None:
        now = trio.current_time()
        session = conn.rover.session if conn.rover else conn.pre
        session.note_bytes_in(len(data))
        for line in conn.lines.feed(data):
            if conn.close_reason is not None:
                break
            if line is TOO_LONG:
                self._bad(conn, FrameError(Fault.TOO_LONG, "line exceeds 1024 bytes"))
                continue
            try:
                frame = decode_line(line)  # type: ignore[arg-type]
            except FrameError as exc:
                self._bad(conn, exc)
                continue
            if frame.cmd == HELLO:
                self._on_hello(conn, frame, now)
                continue
            if conn.rover is None:
                self._bad(conn, FrameError(Fault.NOT_ALLOWED, "send hello first"), frame)
                continue
            if frame.cmd in (HEARTBEAT, ACK):
                try:
                    read_data(frame)
                except FrameError as exc:
                    self._bad(conn, exc, frame)
                    continue
            rover = conn.rover
            for f in rover.session.receive(frame, now):
                for observer in self._frame_observers:
                    observer(rover.id, rover.role, f)
                self._on_frame(rover, f, now)
        if conn.rover is not None:
            self._persist(conn.rover)
        self._flush_conn(conn)

    def _bad(self, conn: _Conn, exc: FrameError, frame: Frame | None = None) -> None:
        """Answer and count a bad frame; a TCP link over its budget is closed."""
        session = conn.rover.session if conn.rover else conn.pre
        session.reject(exc, frame)
        conn.pre_due = conn.rover is None
        now = trio.current_time()
        rid = conn.rover.id if conn.rover else ""
        if self._bursts.add("bad_frame", exc.fault, conn.link, now):
            self._emit("bad_frame", rid, {"link": conn.link, "fault": exc.fault,
                                          "detail": exc.detail})
        if conn.timed:
            cfg = self.config
            conn.budget = min(cfg.bad_frame_budget,
                              conn.budget + (now - conn.budget_t) * cfg.bad_frame_rate)
            conn.budget_t = now
            conn.budget -= 1.0
            if conn.budget < 0:
                conn.close("bad-frame budget spent")

    def _count(self, kind: str, fault: str, link: str, now: float, rover: str = "",
               detail: str = "") -> None:
        """Count one refusal; the first of a burst is an event, the rest a later summary."""
        if self._bursts.add(kind, fault, link, now):
            self._emit(kind, rover, {"link": link, "fault": fault, "detail": detail or fault})

    def _auth_failed(self, conn: _Conn, exc: FrameError, frame: Frame, rid: str) -> None:
        session = conn.rover.session if conn.rover else conn.pre
        session.send_error(exc, frame)
        conn.pre_due = conn.rover is None
        now = trio.current_time()
        self._count("auth_failed", exc.fault, conn.link, now, rid, exc.detail)
        conn.auth_failures += 1
        if conn.peer and not conn.trusted:
            self._backoff.failed(conn.peer, now)
        if conn.auth_failures >= self.config.auth_failures and not conn.trusted:
            conn.close(f"{conn.auth_failures} failed hellos")

    def _admit(self, conn: _Conn, hello: Hello, now: float) -> tuple[FrameError | None, bool]:
        """`trust.admit` on this link and this server's sessions; then the session cap."""
        held = self._rovers.get(hello.id)
        facts = None
        if held is not None and held.conn is not None:
            facts = Held(other_link=held.conn is not conn, trusted_link=held.conn.trusted,
                         live=held.session.is_up(now))
        refusal, by_token = admit(
            hello, self.config, trusted=conn.trusted, peer=conn.peer,
            bound_id=conn.rover.id if conn.rover else None,
            blocked_s=self._backoff.blocked_for(conn.peer, now) if conn.peer else 0.0,
            held=facts, sim_roles=self._sim_roles)
        if refusal is None and held is None and len(self._rovers) >= self.config.max_sessions:
            self._reclaim(now, force=True)
            if len(self._rovers) >= self.config.max_sessions:
                refusal = FrameError(Fault.BUSY, "too many rover sessions; try again later")
        return refusal, by_token

    def _on_hello(self, conn: _Conn, frame: Frame, now: float) -> None:
        try:
            hello: Hello = read_data(frame)
        except FrameError as exc:
            self._bad(conn, exc, frame)
            return
        refusal, _ = self._admit(conn, hello, now)
        if refusal is not None:
            self._auth_failed(conn, refusal, frame, hello.id)
            return
        if conn.peer:
            self._backoff.succeeded(conn.peer)
        if conn.pre_due:  # errors answered before this hello leave before the welcome
            conn.pre_due = False
            self._flush_conn(conn)
        rover = self._rovers.get(hello.id)
        if rover is None:
            rover = self._new_rover(hello.id, hello.role, now)
        old = rover.conn
        if old is not None and old is not conn:
            old.rover = None  # the old stream is stale: this one speaks for the rover
            if not old.trusted:
                old.close("another link said hello for its rover")
        if conn.trusted:
            self._sim_roles.add(hello.role)
        roles_before = dict(self._role)
        rover.role = hello.role
        rover.conn = conn
        rover.gone_since = None
        conn.rover = rover
        self._role[hello.role] = hello.id
        origin = self.config.origins.get(hello.id, self.config.origins.get(hello.role))
        if origin is not None:
            self._start_poses[hello.role] = origin
        rover.session.reset_peer(hello.seq_base)
        rover.session.receive(frame, now)
        rover.session.send(make_frame(WELCOME, {
            "server": PROTOCOL_NAME, "heartbeat_s": self.config.heartbeat_s,
            "down_after_s": self.config.down_after_s, "seq_base": rover.session.seq_base}))
        if rover.row is not None:
            self.store.close_rover_session(rover.row, now)
        rover.row = self.store.open_rover_session(hello.id, hello.role, conn.link, now)
        rover.stored = None
        if self._role != roles_before:
            self._save_game()
        self._emit("hello", hello.id, {"role": hello.role, "link": conn.link})

    def _new_rover(self, rid: str, role: str, now: float) -> _Rover:
        rover = _Rover(rid, role, ReliableSession(
            now=now, heartbeat_s=self.config.heartbeat_s, down_after_s=self.config.down_after_s,
            outbox_limit=MAX_MAP_CHUNKS))
        rover.gone_since = now
        self._rovers[rid] = rover
        return rover

    def _on_frame(self, rover: _Rover, frame: Frame, now: float) -> None:
        try:
            payload = read_data(frame)
            if CATALOGUE[frame.cmd].sender == "server":
                raise FrameError(Fault.NOT_ALLOWED, f"{frame.cmd!r} is sent by the server only")
        except FrameError as exc:
            if rover.conn is not None:
                self._bad(rover.conn, exc, frame)
            return
        cmd = frame.cmd
        if cmd == "pose":
            rover.pose = Pose(payload.x, payload.y, payload.heading)
            self._emit("pose", rover.id, {"x": payload.x, "y": payload.y,
                                          "heading": payload.heading}, log=False)
        elif cmd == "status":
            rover.status = {k: v for k, v in (("state", payload.state),
                            ("detail", payload.detail), ("coverage", payload.coverage),
                            ("battery", payload.battery)) if v is not None}
            self._emit("status", rover.id, dict(rover.status), log=False)
        elif cmd == "map_request":
            self._send_map(rover, frame)
        elif cmd == MAP:
            self._on_map_chunk(rover, frame, payload, now)
        elif cmd in ("arrived", "invalid_spot", "found", "not_found"):
            pose = (Pose(payload.x, payload.y, payload.heading)
                    if hasattr(payload, "x") else None)
            reason = getattr(payload, "reason", "")
            result = self.game.on_rover(rover.role, cmd, pose, reason)
            data: dict[str, Any] = {"report": cmd, "ok": result.ok, "reason": result.reason}
            if pose is not None:
                data.update(x=pose.x, y=pose.y, heading=pose.heading_deg)
            self._emit("report", rover.id, data)
            if result.ok:
                self._apply(result)
            else:
                rover.session.send_error(FrameError(Fault.NOT_ALLOWED, result.reason), frame)
        elif cmd == "error":
            self._emit("peer_error", rover.id, {"fault": payload.fault,
                                                "detail": payload.detail})

    def _on_map_chunk(self, rover: _Rover, frame: Frame, chunk: Any, now: float) -> None:
        if rover.role != "mapper":
            rover.session.send_error(FrameError(
                Fault.NOT_ALLOWED, f"only the mapper uploads maps, not the {rover.role}"), frame)
            return
        if chunk.count > MAX_MAP_CHUNKS:
            exc = FrameError(Fault.BAD_DATA, f"map: {chunk.count} chunks, a map may have at "
                             f"most {MAX_MAP_CHUNKS} (send it coarser or smaller)")
            if rover.conn is not None:
                self._bad(rover.conn, exc, frame)
            return
        try:
            grid = rover.assembler.add(chunk)
        except MapError as exc:
            if rover.conn is not None:
                self._bad(rover.conn, FrameError(Fault.BAD_DATA, f"map: {exc}"), frame)
            return
        if grid is None:
            return
        result = self.game.on_map(grid)
        map_row = self.store.save_map(grid, game_id=self.game_id, t=now, accepted=result.ok,
                                      note=result.reason)
        known = int((grid.cells >= 0).sum())
        self._emit("map", rover.id, {"map": map_row, "nx": grid.shape[1], "ny": grid.shape[0],
                                     "known_cells": known, "accepted": result.ok,
                                     "reason": result.reason})
        if result.ok:
            self._apply(result)
        else:
            rover.session.send_error(FrameError(Fault.NOT_ALLOWED, result.reason), frame)

    def _send_map(self, rover: _Rover, frame: Frame | None = None) -> None:
        grid = self.game.map
        if grid is None:
            rover.session.send_error(FrameError(Fault.NOT_ALLOWED, "no map yet"), frame)
            return
        chunks = map_chunks(grid, self._map_id + 1)
        if rover.session.outbox_room() < len(chunks):
            rover.session.send_error(FrameError(Fault.BUSY, "outbox full; request the map "
                                                "later"), frame)
            return
        self._map_id += 1
        for f in chunks:
            rover.session.send(f, reliable=True)
        self._persist(rover)
        self._save_game()  # the download's map_id: a restarted server counts on from it

    # -- storage ------------------------------------------------------------------------

    def _save_game(self) -> None:
        state = {**self.game.state(), "roles": dict(self._role), "map_seq": self._map_id}
        self.store.save_game_state(self.game_id, str(self.game.phase), state)

    def _persist(self, rover: _Rover) -> None:
        """Store the rover's role and unacknowledged frames when they changed."""
        mark = (self.game_id, rover.session.pending_mark)
        if rover.stored == mark:
            return
        rover.stored = mark
        pending: list[dict[str, Any]] = []
        for f in rover.session.pending():
            if f.cmd == MAP:  # a download in flight: resent whole from the game's map
                if not any(p["cmd"] == MAP for p in pending):
                    pending.append({"cmd": MAP})
                continue
            pending.append({"cmd": f.cmd, "type": f.type, "data": f.data})
        self.store.save_rover_state(self.game_id, rover.id, rover.role, pending)

    def _restore_pending(self, rover: _Rover, pending: list[dict[str, Any]]) -> None:
        for p in pending:
            try:
                if p.get("cmd") == MAP:
                    self._send_map(rover)
                else:
                    rover.session.send(Frame(p["cmd"], p["type"], p["data"]), reliable=True)
            except (KeyError, TypeError, ValueError, OutboxFull):
                continue

    # -- sending ----------------------------------------------------------------------

    def _apply(self, result: Result) -> None:
        """Queue a result's frames to the rovers and record the phase."""
        for send in result.sends:
            rid = self._role.get(send.role)
            rover = self._rovers.get(rid) if rid else None
            if rover is None:
                self._emit("refused", data={"reason": f"no {send.role} to send "
                                            f"{send.frame.cmd} to"})
                continue
            try:
                rover.session.send(send.frame)
            except OutboxFull as exc:
                self._emit("link_error", rover.id, {"error": str(exc)})
            self._flush(rover)
            self._persist(rover)
        self._save_game()
        self._emit("phase", data={"phase": str(self.game.phase), "reason": self.game.last_reason})
        if self.game.phase is Phase.FOUND:
            self.store.end_game(self.game_id, "finished",
                                f"found after {len(self.game.guesses)} "
                                f"guess{'' if len(self.game.guesses) == 1 else 'es'}",
                                trio.current_time())

    def _flush(self, rover: _Rover) -> None:
        if rover.conn is not None:
            self._flush_conn(rover.conn)

    def _flush_conn(self, conn: _Conn) -> None:
        session = conn.rover.session if conn.rover else conn.pre
        data = session.transmit(trio.current_time())
        if data:
            try:
                conn.out_send.send_nowait(data)
            except (trio.WouldBlock, trio.ClosedResourceError):
                conn.dropped += 1  # reliable frames are resent; telemetry is lost
        self._kick.set()

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
                    if rover.session.next_deadline(now) <= now:
                        self._flush_conn(rover.conn)
                        self._persist(rover)
                    deadline = min(deadline, rover.session.next_deadline(now))
                if up:
                    deadline = min(deadline, (rover.session.last_heard or now)
                                   + rover.session.down_after_s)
            self._reclaim(now)
            for kind in self._bursts.due(now):
                self._emit(kind + "_summary", data=self._bursts.take(kind, now))
            self._kick = trio.Event()
            with trio.move_on_at(max(deadline, now + 1e-3)):
                await self._kick.wait()

    def _reclaim(self, now: float, *, force: bool = False) -> None:
        """Forget sessions whose link is gone and that play no role (all such when forced)."""
        playing = set(self._role.values())
        for rid, rover in list(self._rovers.items()):
            if rover.conn is None and rid not in playing and rover.gone_since is not None and (
                    force or now - rover.gone_since >= self.config.reclaim_after_s):
                del self._rovers[rid]

    # -- events -------------------------------------------------------------------------

    def _emit(self, kind: str, rover: str = "", data: dict[str, Any] | None = None, *,
              log: bool = True) -> None:
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
