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
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import trio

from .game import Game, Phase, Result
from .links.memory import MemoryLink
from .links.serial import SerialLinkError, open_serial_stream
from .links.spec import is_loopback
from .protocol import (
    CATALOGUE,
    HELLO,
    MAP,
    WELCOME,
    Fault,
    Frame,
    FrameError,
    Hello,
    LineBuffer,
    LinkStats,
    MapAssembler,
    MapError,
    MapGrid,
    OutboxFull,
    Pose2,
    ReliableSession,
    decode_line,
    make_frame,
    map_chunks,
    read_data,
)
from .protocol.lines import TOO_LONG
from .store import Store

__all__ = ["ServerConfig", "ServerEvent", "RoverView", "ServerSnapshot", "Server",
           "open_server", "PROTOCOL_NAME"]

PROTOCOL_NAME = "hideseek/1"
_OUT_QUEUE = 64          # byte chunks waiting for a link's writer [chunks]
_SUBSCRIBER_QUEUE = 512  # events waiting for a slow subscriber [events]
_READ_SIZE = 4096        # bytes per read [bytes]
_ROLE_OF_COMMAND = {"start_mapping": "mapper", "stop_mapping": "mapper", "hide": "hider",
                    "seek": "seeker"}


@dataclass(frozen=True, slots=True)
class ServerConfig:
    """How the server is set up."""

    tokens: dict[str, str] = field(default_factory=dict)
    """Rover id -> token that rover's hello must carry; key ``*`` for every rover."""
    origins: dict[str, Pose2] = field(default_factory=dict)
    """Start pose in the ROOM frame [cm, deg] by rover id or by role."""
    heartbeat_s: float = 1.0
    down_after_s: float = 5.0
    serial_retry_s: tuple[float, float] = (1.0, 30.0)
    """Backoff between attempts to open a serial port: first, most [s]."""


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
    pose: Pose2 | None
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
    map: MapGrid | None
    hide_spot: Pose2 | None
    guesses: tuple[Pose2, ...]
    dropped_events: int


class _Conn:
    """One byte stream and its writer queue."""

    def __init__(self, link: str) -> None:
        self.link = link
        self.out_send, self.out_recv = trio.open_memory_channel[bytes](_OUT_QUEUE)
        self.lines = LineBuffer()
        self.rover: _Rover | None = None
        self.pre = ReliableSession()  # answers errors before hello
        self.dropped = 0


class _Rover:
    def __init__(self, rid: str, role: str, session: ReliableSession) -> None:
        self.id = rid
        self.role = role
        self.session = session
        self.conn: _Conn | None = None
        self.row: int | None = None    # rover_sessions row of the current binding
        self.up_reported = False
        self.pose: Pose2 | None = None
        self.status: dict[str, Any] = {}
        self.assembler = MapAssembler()


class Server:
    """The game server (see the module docstring). Create with `open_server`."""

    def __init__(self, store: Store, config: ServerConfig, nursery: trio.Nursery) -> None:
        self.store = store
        self.config = config
        self._nursery = nursery
        self._rovers: dict[str, _Rover] = {}
        self._role: dict[str, str] = {}         # role -> rover id (last hello wins)
        self._start_poses: dict[str, Pose2] = {}
        self.game = Game(start_poses=self._start_poses)
        self.game_id = store.new_game(trio.current_time())
        self._subscribers: list[trio.MemorySendChannel[ServerEvent]] = []
        self._frame_observers: list[Callable[[str, str, Frame], None]] = []
        self.dropped_events = 0
        self._kick = trio.Event()
        self._map_id = 0

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
            old = self.game_id
            self.store.end_game(old, "abandoned", "new game", trio.current_time())
            self.game_id = self.store.new_game(trio.current_time())
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
                                 r.session.stats(now), r.pose, dict(r.status))
                       for r in self._rovers.values())
        g = self.game
        return ServerSnapshot(now, self.game_id, str(g.phase), g.last_reason, rovers, g.map,
                              g.hide_spot, tuple(g.guesses), self.dropped_events)

    # -- links ------------------------------------------------------------------------

    def attach_memory(self, outbound: Callable[[bytes], None], *, name: str = "memory",
                      capacity: int = 65536) -> MemoryLink:
        """A link for a simulated rover in this process; the server serves it until closed."""
        link = MemoryLink(outbound, capacity=capacity, name=name)
        self._nursery.start_soon(self.serve_stream, link, name)
        return link

    async def listen_tcp(self, host: str, port: int) -> int:
        """Accept rovers over TCP; return the bound port (useful with ``port=0``).

        Raises:
            ValueError: a non-loopback address without rover tokens configured.
        """
        if not is_loopback(host) and not self.config.tokens:
            raise ValueError(f"refusing to listen on {host}: not loopback and no rover tokens "
                             "(give --token)")

        async def handler(stream: trio.SocketStream) -> None:
            try:
                peer = stream.socket.getpeername()
                name = f"tcp:{peer[0]}:{peer[1]}"
            except OSError:
                name = "tcp"
            await self.serve_stream(stream, name)

        listeners = await self._nursery.start(
            lambda task_status: trio.serve_tcp(handler, port, host=host, task_status=task_status))
        return listeners[0].socket.getsockname()[1]

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
                await self.serve_stream(stream, name)
            except SerialLinkError as exc:
                self._emit("link_error", data={"link": name, "error": str(exc),
                                               "retry_s": delay})
            await trio.sleep(delay)

    async def serve_stream(self, stream: Any, link: str) -> None:
        """Speak the protocol over one byte stream until it ends.

        Raises:
            SerialLinkError: from a serial stream that failed (the caller retries).
        """
        conn = _Conn(link)
        try:
            async with trio.open_nursery() as nursery:
                nursery.start_soon(self._writer, stream, conn)
                while True:
                    try:
                        data = await stream.receive_some(_READ_SIZE)
                    except (trio.BrokenResourceError, ConnectionError) as exc:
                        self._emit("link_error", data={"link": link, "error": str(exc)})
                        break
                    if not data:
                        break
                    self._on_bytes(conn, data)
                nursery.cancel_scope.cancel()
        finally:
            rover = conn.rover
            if rover is not None and rover.conn is conn:
                rover.conn = None
                if rover.row is not None:
                    self.store.close_rover_session(rover.row, trio.current_time())
            with trio.CancelScope(shield=True), contextlib.suppress(Exception):
                with trio.move_on_after(1):
                    await stream.aclose()

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
            session = conn.rover.session if conn.rover else conn.pre
            if line is TOO_LONG:
                self._bad(conn, session, FrameError(Fault.TOO_LONG, "line exceeds 1024 bytes"))
                continue
            try:
                frame = decode_line(line)  # type: ignore[arg-type]
            except FrameError as exc:
                self._bad(conn, session, exc)
                continue
            if frame.cmd == HELLO:
                self._on_hello(conn, frame, now)
                continue
            if conn.rover is None:
                self._bad(conn, conn.pre, FrameError(Fault.NOT_ALLOWED, "send hello first"),
                          frame)
                continue
            rover = conn.rover
            for f in rover.session.receive(frame, now):
                for observer in self._frame_observers:
                    observer(rover.id, rover.role, f)
                self._on_frame(rover, f, now)
        self._flush_conn(conn)

    def _bad(self, conn: _Conn, session: ReliableSession, exc: FrameError,
             frame: Frame | None = None) -> None:
        session.reject(exc, frame)
        self._emit("bad_frame", conn.rover.id if conn.rover else "",
                   {"link": conn.link, "fault": exc.fault, "detail": exc.detail})

    def _on_hello(self, conn: _Conn, frame: Frame, now: float) -> None:
        session = conn.rover.session if conn.rover else conn.pre
        try:
            hello: Hello = read_data(frame)
        except FrameError as exc:
            self._bad(conn, session, exc, frame)
            return
        want = self.config.tokens.get(hello.id, self.config.tokens.get("*"))
        if want is not None and hello.token != want:
            self._bad(conn, session, FrameError(Fault.AUTH, f"bad or missing token for "
                                                f"{hello.id!r}"), frame)
            return
        rover = self._rovers.get(hello.id)
        if rover is None:
            rover = _Rover(hello.id, hello.role, ReliableSession(
                now=now, heartbeat_s=self.config.heartbeat_s,
                down_after_s=self.config.down_after_s))
            self._rovers[hello.id] = rover
        if rover.conn is not None and rover.conn is not conn:
            rover.conn.rover = None  # the old stream is stale: this one speaks for the rover
        rover.role = hello.role
        rover.conn = conn
        conn.rover = rover
        self._role[hello.role] = hello.id
        origin = self.config.origins.get(hello.id, self.config.origins.get(hello.role))
        if origin is not None:
            self._start_poses[hello.role] = Pose2(*origin)
        rover.session.reset_peer(hello.seq_base)
        rover.session.receive(frame, now)
        rover.session.send(make_frame(WELCOME, {
            "server": PROTOCOL_NAME, "heartbeat_s": self.config.heartbeat_s,
            "down_after_s": self.config.down_after_s, "seq_base": rover.session.seq_base}))
        if rover.row is not None:
            self.store.close_rover_session(rover.row, now)
        rover.row = self.store.open_rover_session(hello.id, hello.role, conn.link, now)
        self._emit("hello", hello.id, {"role": hello.role, "link": conn.link})

    def _on_frame(self, rover: _Rover, frame: Frame, now: float) -> None:
        try:
            payload = read_data(frame)
            if CATALOGUE[frame.cmd].sender == "server":
                raise FrameError(Fault.NOT_ALLOWED, f"{frame.cmd!r} is sent by the server only")
        except FrameError as exc:
            rover.session.reject(exc, frame)
            self._emit("bad_frame", rover.id, {"fault": exc.fault, "detail": exc.detail})
            return
        cmd = frame.cmd
        if cmd == "pose":
            rover.pose = Pose2(payload.x, payload.y, payload.heading)
            self._emit("pose", rover.id, {"x": payload.x, "y": payload.y,
                                          "heading": payload.heading}, log=False)
        elif cmd == "status":
            rover.status = {k: v for k, v in (("state", payload.state),
                            ("detail", payload.detail), ("coverage", payload.coverage),
                            ("battery", payload.battery)) if v is not None}
            self._emit("status", rover.id, dict(rover.status), log=False)
        elif cmd == "map_request":
            self._send_map(rover)
        elif cmd == MAP:
            self._on_map_chunk(rover, frame, payload, now)
        elif cmd in ("arrived", "invalid_spot", "found", "not_found"):
            pose = (Pose2(payload.x, payload.y, payload.heading)
                    if hasattr(payload, "x") else None)
            reason = getattr(payload, "reason", "")
            result = self.game.on_rover(rover.role, cmd, pose, reason)
            data: dict[str, Any] = {"report": cmd, "ok": result.ok, "reason": result.reason}
            if pose is not None:
                data.update(x=pose.x, y=pose.y, heading=pose.heading)
            self._emit("report", rover.id, data)
            if result.ok:
                self._apply(result)
        elif cmd == "error":
            self._emit("peer_error", rover.id, {"fault": payload.fault,
                                                "detail": payload.detail})

    def _on_map_chunk(self, rover: _Rover, frame: Frame, chunk: Any, now: float) -> None:
        if rover.role != "mapper":
            rover.session.reject(FrameError(Fault.NOT_ALLOWED, "only the mapper uploads maps"),
                                 frame)
            return
        try:
            grid = rover.assembler.add(chunk)
        except MapError as exc:
            rover.session.reject(FrameError(Fault.BAD_DATA, f"map: {exc}"), frame)
            self._emit("bad_frame", rover.id, {"fault": Fault.BAD_DATA, "detail": str(exc)})
            return
        if grid is None:
            return
        result = self.game.on_map(grid)
        map_row = self.store.save_map(grid, game_id=self.game_id, t=now)
        known = int((grid.cells >= 0).sum())
        self._emit("map", rover.id, {"map": map_row, "nx": grid.shape[1], "ny": grid.shape[0],
                                     "known_cells": known, "accepted": result.ok,
                                     "reason": result.reason})
        if result.ok:
            self._apply(result)

    def _send_map(self, rover: _Rover) -> None:
        grid = self.game.map
        if grid is None:
            rover.session.reject(FrameError(Fault.NOT_ALLOWED, "no map yet"))
            return
        self._map_id += 1
        chunks = map_chunks(grid, self._map_id)
        if rover.session.outbox_room() < len(chunks):
            rover.session.reject(FrameError(Fault.BUSY, "outbox full; request the map later"))
            return
        for f in chunks:
            rover.session.send(f, reliable=True)

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
        self.store.set_phase(self.game_id, str(self.game.phase))
        self._emit("phase", data={"phase": str(self.game.phase), "reason": self.game.last_reason})
        if self.game.phase is Phase.FOUND:
            self.store.end_game(self.game_id, "finished",
                                f"found after {len(self.game.guesses)} guesses",
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
            except trio.WouldBlock:
                conn.dropped += 1  # reliable frames are resent; telemetry is lost
        self._kick.set()

    async def _timer(self) -> None:
        """Heartbeats, resends and link up/down, each at its session's deadline."""
        while True:
            now = trio.current_time()
            deadline = now + 1.0
            for rover in self._rovers.values():
                up = rover.session.is_up(now)
                if up != rover.up_reported:
                    rover.up_reported = up
                    self._emit("link_up" if up else "link_down", rover.id,
                               {"link": rover.conn.link if rover.conn else ""})
                if rover.conn is not None:
                    if rover.session.next_deadline(now) <= now:
                        self._flush_conn(rover.conn)
                    deadline = min(deadline, rover.session.next_deadline(now))
                if up:
                    deadline = min(deadline, (rover.session.last_heard or now)
                                   + rover.session.down_after_s)
            self._kick = trio.Event()
            with trio.move_on_at(max(deadline, now + 1e-3)):
                await self._kick.wait()

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
            nursery.cancel_scope.cancel()
