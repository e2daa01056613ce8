"""Links: accepting TCP connections within bounds, serving serial ports, reading frames.

A link's task reads bytes, cuts them into lines and frames, and hands
``hello`` to `server.hello` and every other frame, in the order the rover's
reliable session delivers it, to `server.frames`; a writer task sends what the
session transmits. Bounds on TCP links (see the `server.server` docstring):
the connection cap, the per-address cap on links without hello, the hello and
idle timeouts, and a bad-frame budget (a token bucket) per link. Refusals are
counted in bursts (`server.guard.BurstLog`). Accepting slows, with one event
per episode, while the process is out of file descriptors.

Admission beyond the caps: a connection that finds no room (its address is
blocked after failed hellos, or has ``max_pending_per_address`` links without
an accepted hello, or the server holds ``max_connections``) is not served;
whatever it sent already is read (at most `MAX_LINE_BYTES`), and otherwise it
*waits*, unanswered, for its first line until the hello timeout. When that
line is a ``hello`` the identity rules accept (`server.hello.Hellos._admit`:
a valid token, or, from an address that is not blocked, an id that needs none
on loopback), the connection makes room for itself, closing the oldest link
without an accepted hello of its own address when that address's budget is
full, else at the cap the oldest of its address or of all, and is served at
once: a flood of idle connections, or of bad hellos that block the address,
from a rover's own address or from many, cannot keep a rover with its token
out, and its hello is answered without waiting for a timeout. Any other first
line closes it (a refused hello counts towards the address's backoff as on
any link).

At most ``max_waiting`` connections wait. When more come, a newer one takes
the place of the oldest waiting one of the address holding the most
connections without an accepted hello, if that address holds two more than
the newer one's (one more when the newer one's holds none), so a flood from
many addresses cannot push out a rover's one connection; else of the oldest
waiting one once that has waited `FAIR_WAIT_S`; else it is closed at once.
Waiting costs one small task and no session, and closing at once costs
nothing more than the accept; after each awaited accept the loop takes up to
`_BURST` more connections already queued without a scheduler round each, so a
flood of connections drains fast and a rover's connection behind it is
reached soon. A UDP peer cannot wait (it has no connection to hold): its
first datagram is its first line, decided at once.
"""

from __future__ import annotations

import contextlib
import errno
import math
from collections import Counter, OrderedDict
from collections.abc import Iterable
from typing import Any

import trio

from .config import ServerConfig
from .core import ServerCore
from .links.serial import serve_serial_port
from .links.tcp import as_stream, read_now, second_handle
from .peers import Conn
from .protocol import (
    ACK,
    HEARTBEAT,
    HELLO,
    MAX_LINE_BYTES,
    Fault,
    Frame,
    FrameError,
    Hello,
    decode_line,
    read_data,
)
from .protocol.lines import TOO_LONG
from .store import Store

__all__ = ["Connections"]

_READ_SIZE = 4096        # bytes per read [bytes]
_BURST = 16              # connections taken at once after an awaited accept, at most
_ACCEPT_STARVED = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)
FAIR_WAIT_S = 1.0
"""A waiting connection keeps its place this long against newer ones from addresses that
hold about as many connections without hello as its own [s]."""


class Connections(ServerCore):
    """The link side of a `Server`: one task per byte stream, and the TCP accept loop."""

    def __init__(self, store: Store, config: ServerConfig, nursery: trio.Nursery) -> None:
        super().__init__(store, config, nursery)
        self._waiting: OrderedDict[trio.CancelScope, tuple[float, str]] = OrderedDict()
        """Connections waiting beyond the caps, oldest first: cancel scope -> (when it came
        [s], peer address)."""
        self._waiting_held: Counter[str] = Counter()
        """Waiting connections per address (addresses with none are not kept)."""

    @property
    def waiting(self) -> int:
        """Connections held beyond the caps while the server reads their first line."""
        return len(self._waiting)

    async def _accept_loop(self, listener: trio.SocketListener) -> None:
        delay = 0.0
        burst = second_handle(listener)
        try:
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
                    self._admit_tcp(stream.socket, stream)
                    for _ in range(_BURST if burst is not None else 0):
                        try:
                            more, _ = burst.accept()  # type: ignore[union-attr]
                        except OSError:  # none waiting, or out of descriptors: the await tells
                            break
                        more.setblocking(False)
                        self._admit_tcp(more)
        finally:
            if burst is not None:
                burst.close()

    def _admit_tcp(self, sock: Any, stream: trio.SocketStream | None = None) -> None:
        """Serve a new TCP connection (``sock``: a Trio or a standard non-blocking socket;
        ``stream``: its stream, if made), let it wait beyond the caps, or close it at once
        (cheaply, in the accept loop, so a flood of connections drains the kernel's accept
        queue fast)."""
        try:
            peer = sock.getpeername()
            addr, name = str(peer[0]), f"tcp:{peer[0]}:{peer[1]}"
        except OSError:
            addr, name = "", "tcp"
        now = trio.current_time()
        refusal = self._no_room(addr, now)
        if not refusal:
            self._serve(stream or as_stream(sock), self._new_conn(name, peer=addr, timed=True))
            return
        first = read_now(sock)
        if first is not None and b"\n" not in first and self.config.max_waiting > 0:
            victim = None
            if len(self._waiting) >= self.config.max_waiting:
                victim = self._waiting_victim(addr, now)
                if victim is None:
                    self._count("conn_closed", "no room, and the waiting connections keep "
                                "theirs", name, now)
                    sock.close()
                    return
            self._wait(stream or as_stream(sock), addr, name, now, first, victim)
            return
        conn = self._admission(addr, name, first or b"", now)
        if conn is None:
            sock.close()
        else:
            self._serve(stream or as_stream(sock), conn, first or b"")

    def _admit_peer(self, stream: Any, addr: str, name: str, first: bytes = b"") -> bool:
        """Serve a new UDP peer within the caps, or beyond them when its first datagram
        ``first`` is an accepted hello (see the module docstring); False: refused."""
        if first and not first.endswith(b"\n"):
            first += b"\n"  # a datagram ends its line
        conn = self._admission(addr, name, first, trio.current_time())
        if conn is None:
            return False
        self._serve(stream, conn)
        return True

    def _no_room(self, addr: str, now: float) -> str:
        """Why a new connection from ``addr`` cannot be served now ('' when it can)."""
        cfg = self.config
        if addr and self._backoff.blocked_for(addr, now) > 0:
            return "address blocked after failed hellos"
        if self._pending(addr) >= cfg.max_pending_per_address:
            return "too many connections without hello from one address"
        if len(self._tcp) >= cfg.max_connections:
            return "connection cap"
        return ""

    def _pending(self, addr: str) -> int:
        """Connections from ``addr`` without an accepted hello."""
        return sum(1 for c in self._tcp if c.rover is None and c.peer == addr)

    def _admission(self, addr: str, name: str, first: bytes, opened: float) -> Conn | None:
        """A new connection to serve, whose first bytes are ``first``: within the caps, or
        beyond them when its first line is an accepted hello and room can be made; None
        (counted) when it is refused."""
        now = trio.current_time()
        refusal = self._no_room(addr, now)
        if refusal:
            conn = self._proven(addr, name, first, now)
            if conn is not None:
                if self._make_room(addr):
                    conn.opened = opened
                    return conn
                refusal = "connection cap"
            elif b"\n" in first:
                refusal += "; first line not an accepted hello"
        if refusal:
            self._count("conn_closed", refusal, name, now)
            return None
        conn = self._new_conn(name, peer=addr, timed=True)
        conn.opened = opened
        return conn

    def _proven(self, addr: str, name: str, first: bytes, now: float) -> Conn | None:
        """A connection for ``first``'s first line when it is a hello the identity rules
        accept (a refused one is counted, and backs the address off, as on any link)."""
        line, newline, _ = first.partition(b"\n")
        if not newline:
            return None
        try:
            frame = decode_line(line)
            if frame.cmd != HELLO:
                return None
            hello: Hello = read_data(frame)
        except FrameError:
            return None
        conn = self._new_conn(name, peer=addr, timed=True)
        refusal, _ = self._admit(conn, hello, now)
        if refusal is None:
            return conn
        self._count("auth_failed", refusal.fault, name, now, hello.id, refusal.detail)
        if addr:
            self._backoff.failed(addr, now)
        return None

    def _make_room(self, addr: str) -> bool:
        """Close the link without an accepted hello that keeps a proven connection from
        ``addr`` out: the address's oldest when its budget is full, else at the cap the
        oldest of that address or of all. False when every link at the cap is a rover's."""
        cfg = self.config
        unproven = [c for c in self._tcp if c.rover is None]
        own = [c for c in unproven if c.peer == addr]
        if own and len(own) >= cfg.max_pending_per_address:
            self._evict(own[0])
        elif len(self._tcp) >= cfg.max_connections:
            if not unproven:
                return False
            self._evict((own or unproven)[0])
        return True

    def _evict(self, conn: Conn) -> None:
        conn.close("evicted by a rover's hello beyond the caps")
        del self._tcp[conn]  # its slot is free now, whatever its task does next

    def _serve(self, stream: Any, conn: Conn, first: bytes = b"") -> None:
        """Serve ``conn`` from now on; ``first``, bytes already read from it, are handled at
        once (so a proven hello binds its rover before anything can make room in its place)."""
        self._tcp[conn] = None
        if first:
            self._on_bytes(conn, first)
        self._nursery.start_soon(self._serve_conn, stream, conn)

    def _wait(self, stream: trio.SocketStream, addr: str, name: str, now: float,
              first: bytes, victim: trio.CancelScope | None) -> None:
        """Hold a connection beyond the caps while its first line comes, in the place of
        ``victim`` when the waiting room is full (module docstring)."""
        if victim is not None:
            self._unwait(victim)
            victim.cancel()
        scope = trio.CancelScope(deadline=now + self.config.hello_timeout_s)
        self._waiting[scope] = (now, addr)
        self._waiting_held[addr] += 1
        self._nursery.start_soon(self._waiting_conn, stream, addr, name, scope, now, first)

    def _unwait(self, scope: trio.CancelScope) -> None:
        """Forget a waiting connection (once; its address's count goes when it is 0)."""
        _, addr = self._waiting.pop(scope, (0.0, None))
        if addr is None:
            return
        self._waiting_held[addr] -= 1
        if not self._waiting_held[addr]:
            del self._waiting_held[addr]

    def _waiting_victim(self, addr: str, now: float) -> trio.CancelScope | None:
        """The waiting connection a newer one from ``addr`` takes the place of, if any (see
        the module docstring): the oldest of the greediest address, when that holds more
        connections without an accepted hello than ``addr`` by two, or by one when
        ``addr`` holds none (so a flood from many addresses cannot push out a rover's one
        connection, and the flood's own addresses do not trade places for ever); else the
        oldest of all once it has waited `FAIR_WAIT_S`; else none (the newer one is
        closed: the cheap way under a flood)."""
        held = dict(self._waiting_held)
        for c in self._tcp:
            if c.rover is None:
                held[c.peer or ""] = held.get(c.peer or "", 0) + 1
        mine = held.get(addr, 0)
        greedy, most = None, mine + 1 if mine else 0
        for other in self._waiting_held:
            if held[other] > most:
                greedy, most = other, held[other]
        if greedy is not None:
            return next(scope for scope, (_, a) in self._waiting.items() if a == greedy)
        oldest, (since, _) = next(iter(self._waiting.items()))
        return oldest if now - since >= FAIR_WAIT_S else None

    async def _waiting_conn(self, stream: trio.SocketStream, addr: str, name: str,
                            scope: trio.CancelScope, opened: float, first: bytes) -> None:
        """Read a waiting connection's first line; then serve it or close it."""
        served = False
        try:
            with scope:
                while b"\n" not in first and len(first) <= MAX_LINE_BYTES:
                    data = await stream.receive_some(_READ_SIZE)
                    if not data:
                        break
                    first += data
            self._unwait(scope)
            conn = self._admission(addr, name, first, opened) if b"\n" in first else None
            if conn is not None:
                self._serve(stream, conn, first)
                served = True
            elif b"\n" not in first:
                self._count("conn_closed", "no room, and no hello while it waited", name,
                            trio.current_time())
        except (trio.BrokenResourceError, trio.ClosedResourceError, ConnectionError):
            self._count("conn_closed", "link error while it waited", name, trio.current_time())
        finally:
            self._unwait(scope)
            if not served:  # also when the server is closing
                stream.socket.close()

    async def _serve_serial(self, url: str, baud: int) -> None:
        """Serve a serial port across unplugs (`server.links.serial.serve_serial_port`)."""
        name = f"serial:{url},{baud}"

        def report(kind: str, data: dict) -> None:
            self._emit(kind, data=data)

        await serve_serial_port(
            url, baud, lambda stream: self.serve_stream(stream, name, ask_hello=True), report,
            self.config.serial_retry_s)

    def _new_conn(self, link: str, *, peer: str | None = None, trusted: bool = False,
                  timed: bool = False) -> Conn:
        conn = Conn(link, trio.current_time(), peer=peer, trusted=trusted, timed=timed)
        conn.budget = self.config.bad_frame_budget
        return conn

    async def _serve_conn(self, stream: Any, conn: Conn) -> None:
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

    def _conn_deadline(self, conn: Conn) -> float:
        if not conn.timed:
            return math.inf
        if conn.rover is None:
            return conn.opened + self.config.hello_timeout_s
        heard = conn.rover.session.last_heard
        return (heard if heard is not None else conn.opened) + self.config.down_after_s

    def _link_error(self, conn: Conn, error: str) -> None:
        if conn.rover is None and not conn.trusted:
            self._count("conn_closed", f"link error: {error}", conn.link, trio.current_time())
        else:
            self._emit("link_error", data={"link": conn.link, "error": error})

    async def _writer(self, stream: Any, conn: Conn) -> None:
        async for data in conn.out_recv:
            try:
                await stream.send_all(data)
            except (trio.BrokenResourceError, trio.ClosedResourceError, ConnectionError):
                return

    def _on_bytes(self, conn: Conn, data: bytes) -> None:
        session = conn.rover.session if conn.rover else conn.pre
        session.note_bytes_in(len(data))
        lines = conn.lines.feed(data)
        if self._link_seeds:  # an operator has broken some rover's link
            lines = self._link_in(conn, lines, self._on_lines)  # type: ignore[attr-defined]
        self._on_lines(conn, lines)

    def _on_lines(self, conn: Conn, lines: Iterable[Any]) -> None:
        now = trio.current_time()
        for line in lines:
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
            try:
                received = rover.session.receive(frame, now)
            except FrameError as exc:
                self._bad(conn, exc, frame)
                continue
            for f in received:
                for observer in self._frame_observers:
                    observer(rover.id, rover.role, f)
                self._on_frame(rover, f, now)
        if conn.rover is not None:
            self._persist(conn.rover)
        self._flush_conn(conn)

    def _bad(self, conn: Conn, exc: FrameError, frame: Frame | None = None) -> None:
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
