"""Links: accepting TCP connections within bounds, serving serial ports, reading frames.

A link's task reads bytes, cuts them into lines and frames, and hands
``hello`` to `server.hello` and every other frame, in the order the rover's
reliable session delivers it, to `server.frames`; a writer task sends what the
session transmits. Bounds on TCP links (see the `server.server` docstring):
the connection cap with eviction of the oldest unauthenticated link, the
per-address cap on links without hello, the hello and idle timeouts, and a
bad-frame budget (a token bucket) per link. Refusals are counted in bursts
(`server.guard.BurstLog`). Accepting slows, with one event per episode, while
the process is out of file descriptors.
"""

from __future__ import annotations

import contextlib
import errno
import math
from collections.abc import Iterable
from typing import Any

import trio

from .core import ServerCore
from .links.serial import serve_serial_port
from .peers import Conn
from .protocol import ACK, HEARTBEAT, HELLO, Fault, Frame, FrameError, decode_line, read_data
from .protocol.lines import TOO_LONG

__all__ = ["Connections"]

_READ_SIZE = 4096        # bytes per read [bytes]
_ACCEPT_STARVED = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)


class Connections(ServerCore):
    """The link side of a `Server`: one task per byte stream, and the TCP accept loop."""

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
