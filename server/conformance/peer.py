"""The checker's end of a rover link: the server's side, played by hand.

A `Peer` writes frames the way the server does and records every line both
ways in a `Transcript`, stamped with Trio's clock (run it at the rover's
``--speed`` and the stamps are the rover's seconds). Unlike the server's
`ReliableSession`, each behaviour a rule needs to see is a switch:

* ``auto_ack``: acknowledge the rover's in-order reliable frames at once with
  a bare ``ack`` (the server's behaviour); off, the ``ack`` field stays where
  it was, so the rover's resends can be watched;
* ``heartbeats``: send a heartbeat after 1 s without sending (keeps the rover's
  link up while its frames go unacknowledged);
* reliable frames of the checker get the next ``seq`` and are resent after a
  timeout (1 s, doubled, at most ``MAX_TRIES`` sends), as docs/protocol.md
  asks of the server; `Peer.send_with_seq` sends one with a chosen ``seq``
  (a duplicate, or a ``seq`` after a claimed restart).

Lines the rover sends are split by `LineBuffer` and read by `decode_line`;
lines that are not frames are kept in the transcript with their fault.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import trio

from ..protocol import MAX_LINE_BYTES, TOO_LONG, Frame, FrameError, LineBuffer, decode_line
from ..protocol.frame import encode_frame

__all__ = ["Seen", "Transcript", "Peer", "HEARTBEAT_S", "RESEND_S", "MAX_TRIES", "MAX_LINES"]

HEARTBEAT_S = 1.0
"""The checker's heartbeat period, as the server's [s]."""
RESEND_S = 1.0
"""First resend timeout of the checker's reliable frames [s]."""
MAX_TRIES = 6
"""Sends of one reliable frame of the checker at most."""
MAX_LINES = 200_000
"""Lines a transcript keeps at most: a rover that floods the link past it is cut off."""
_READ_BYTES = 4096


@dataclass(frozen=True, slots=True)
class Seen:
    """One line on the link, as the checker saw it."""

    t: float
    """When [s, rover clock, from the start of the check]."""
    sender: str
    """``R`` (the rover) or ``S`` (the checker, playing the server)."""
    line: bytes
    """The line without its newline (cut to 200 bytes when longer)."""
    size: int
    """Its length on the wire, newline included [bytes]."""
    frame: Frame | None
    """The frame, None when the line is not one."""
    fault: str = ""
    """Why the line is not a frame (a `Fault` code), else empty."""
    link: int = 0
    """Which connection carried it: 0 for the first, 1 after the first reconnect ..."""

    def show(self, *, full: bool = False) -> str:
        """The line as a report quotes it: who, when, at most 160 characters (``full``: as
        kept, with the connection's number)."""
        text = self.line.decode("utf-8", "replace")
        if full:
            return f"{self.sender}@{self.t:.3f}s link{self.link} {text}"
        if len(text) > 160:
            text = text[:157] + "..."
        return f"{self.sender}@{self.t:.2f}s {text}"


class Transcript:
    """Every line of a check, in order, and a way to wait for the next ones."""

    def __init__(self) -> None:
        self.lines: list[Seen] = []
        self._changed = trio.Event()
        self.t0 = trio.current_time()

    @property
    def full(self) -> bool:
        """`MAX_LINES` are kept: no more are taken."""
        return len(self.lines) >= MAX_LINES

    def add(self, seen: Seen) -> None:
        if self.full:
            return
        self.lines.append(seen)
        self._changed.set()
        self._changed = trio.Event()

    def index(self, seen: Seen) -> int:
        """Where ``seen`` (this very line) stands in the transcript."""
        return next(i for i in range(len(self.lines) - 1, -1, -1) if self.lines[i] is seen)

    def now(self) -> float:
        """The check's clock [s]."""
        return trio.current_time() - self.t0

    def rover(self, start: int = 0) -> list[Seen]:
        """The rover's lines from index ``start`` on."""
        return [s for s in self.lines[start:] if s.sender == "R"]

    def frames(self, start: int = 0, cmd: str | None = None) -> list[Seen]:
        """The rover's frames from index ``start`` on, only ``cmd`` when given."""
        return [s for s in self.lines[start:] if s.sender == "R" and s.frame is not None
                and (cmd is None or s.frame.cmd == cmd)]

    async def wait_for(self, match: Callable[[Seen], bool], timeout_s: float,
                       start: int = 0) -> Seen | None:
        """The first rover line from index ``start`` on that ``match`` takes, waiting at
        most ``timeout_s`` [s] for it; None when none came."""
        with trio.move_on_after(timeout_s):
            while True:
                for s in self.lines[start:]:
                    if s.sender == "R" and match(s):
                        return s
                start = len(self.lines)
                await self._changed.wait()
        return None

    async def wait_cmd(self, cmd: str, timeout_s: float, start: int = 0) -> Seen | None:
        """The first rover frame ``cmd`` from index ``start`` on (see `wait_for`)."""
        return await self.wait_for(lambda s: s.frame is not None and s.frame.cmd == cmd,
                                   timeout_s, start)


@dataclass(slots=True)
class _Out:
    frame: Frame
    deadline: float
    tries: int


class Peer:
    """The server's side of one rover link (see the module docstring).

    Args:
        transcript: where every line goes.
    """

    def __init__(self, transcript: Transcript) -> None:
        self.transcript = transcript
        self.auto_ack = True
        """Acknowledge the rover's in-order reliable frames at once."""
        self.heartbeats = False
        """Send heartbeats (on after the welcome)."""
        self.rx_next = 1
        """The rover's next ``seq`` expected in order."""
        self.acked = 0
        """The ``ack`` value the checker sends (0: none yet, the field is left out)."""
        self.next_seq = 1
        """The checker's next ``seq``."""
        self.link = 0
        """Connections made so far, less one."""
        self.flooded = False
        """The rover sent more than `MAX_LINES` lines: the link was cut."""
        self._stream: Any = None
        self._lines = LineBuffer()
        self._flight: dict[int, _Out] = {}
        self._last_sent = -1e9
        self._send_lock = trio.Lock()
        self._wake = trio.Event()
        self.on_frame: Callable[[Frame], Awaitable[None]] | None = None
        """Called with each frame of the rover after the peer's own handling."""

    @property
    def connected(self) -> bool:
        """A stream is attached."""
        return self._stream is not None

    def unacked(self) -> list[int]:
        """The checker's reliable frames the rover has not acknowledged yet."""
        return sorted(self._flight)

    # -- the stream ------------------------------------------------------------------

    async def serve(self, stream: Any, *, task_status=trio.TASK_STATUS_IGNORED) -> None:
        """Read ``stream`` until it ends (or this task is cancelled); keep the timers."""
        self._stream = stream
        self._lines = LineBuffer()
        task_status.started()
        try:
            async with trio.open_nursery() as nursery:
                nursery.start_soon(self._timers)
                while True:
                    try:
                        data = await stream.receive_some(_READ_BYTES)
                    except (OSError, trio.BrokenResourceError, trio.ClosedResourceError):
                        data = b""
                    if not data or self.transcript.full:
                        self.flooded = self.transcript.full
                        nursery.cancel_scope.cancel()
                        break
                    await self._feed(data)
        finally:
            if self._stream is stream:
                self._stream = None

    async def detach(self) -> None:
        """Close the stream (the link drops); the next `serve` is the next connection."""
        stream, self._stream = self._stream, None
        self.link += 1
        if stream is not None:
            with trio.move_on_after(1) as scope:
                scope.shield = True
                try:
                    await stream.aclose()
                except (OSError, trio.BrokenResourceError, trio.ClosedResourceError):
                    pass

    async def _feed(self, data: bytes) -> None:
        t = self.transcript.now()
        for line in self._lines.feed(data):
            if line is TOO_LONG:
                self.transcript.add(Seen(t, "R", b"<a line over 1024 bytes>", MAX_LINE_BYTES + 1,
                                         None, "too_long", self.link))
                continue
            assert isinstance(line, bytes)
            try:
                frame: Frame | None = decode_line(line)
                fault = ""
            except FrameError as exc:
                frame, fault = None, exc.fault
            self.transcript.add(Seen(t, "R", line[:200], len(line) + 1, frame, fault,
                                     self.link))
            if frame is not None:
                await self._on_frame(frame)
                if self.on_frame is not None:
                    await self.on_frame(frame)

    async def _on_frame(self, frame: Frame) -> None:
        if frame.ack is not None:
            for seq in [s for s in self._flight if s <= frame.ack]:
                del self._flight[seq]
        if frame.seq is None:
            return
        if frame.seq == self.rx_next:
            self.rx_next += 1
        if self.auto_ack:
            self.acked = self.rx_next - 1
            await self.send(Frame("ack", "ack", None), bare_ack=True)

    def reset_rover_seq(self, seq_base: int) -> None:
        """The rover's hello said its next ``seq`` is ``seq_base``."""
        self.rx_next = seq_base
        if self.auto_ack:
            self.acked = seq_base - 1

    def restart_numbering(self) -> None:
        """Number the checker's reliable frames from 1 again (a restarted server); what was
        in flight is forgotten."""
        self._flight.clear()
        self.next_seq = 1

    def ack_now(self) -> None:
        """Take the rover's frames received in order as acknowledged (the next frame says so)."""
        self.acked = self.rx_next - 1

    # -- sending ---------------------------------------------------------------------

    async def send(self, frame: Frame, *, reliable: bool = False, bare_ack: bool = False) -> int:
        """Send a frame with the current ``ack``; ``reliable`` gives it the next ``seq``
        (returned; 0 for an unreliable frame) and resends it until acknowledged."""
        seq = 0
        if reliable:
            seq = self.next_seq
            self.next_seq += 1
        await self.send_with_seq(frame, seq, bare_ack=bare_ack)
        return seq

    async def send_with_seq(self, frame: Frame, seq: int, *, bare_ack: bool = False,
                            resend: bool = True) -> None:
        """Send ``frame`` with ``seq`` (0: none); a frame with ``seq`` is resent until
        acknowledged when ``resend``."""
        stamped = Frame(frame.cmd, frame.type, frame.data, seq=seq or None)
        if seq and resend:
            self._flight[seq] = _Out(stamped, trio.current_time() + RESEND_S, 1)
            self.wake()
        await self._write(stamped, bare_ack=bare_ack)

    async def send_raw(self, data: bytes) -> None:
        """Bytes as they are (a malformed line): recorded as the checker's line."""
        t = self.transcript.now()
        for line in data.split(b"\n")[:-1] or [data]:
            self.transcript.add(Seen(t, "S", line[:200], len(line) + 1, None, "raw", self.link))
        await self._put(data)

    async def _write(self, frame: Frame, *, bare_ack: bool = False) -> None:
        ack = self.acked if self.acked > 0 or bare_ack else None
        out = Frame(frame.cmd, frame.type, frame.data, seq=frame.seq, ack=ack)
        data = encode_frame(out)
        self.transcript.add(Seen(self.transcript.now(), "S", data[:-1][:200], len(data), out,
                                 "", self.link))
        await self._put(data)

    async def _put(self, data: bytes) -> None:
        stream = self._stream
        if stream is None:
            return
        async with self._send_lock:
            try:
                await stream.send_all(data)
            except (OSError, trio.BrokenResourceError, trio.ClosedResourceError):
                return
        self._last_sent = trio.current_time()

    async def _timers(self) -> None:
        """Heartbeats and resends, at their deadlines."""
        while True:
            now = trio.current_time()
            for seq, out in sorted(self._flight.items()):
                if now >= out.deadline:
                    if out.tries >= MAX_TRIES:
                        del self._flight[seq]
                        continue
                    out.tries += 1
                    out.deadline = now + RESEND_S * 2 ** (out.tries - 1)
                    await self._write(out.frame)
            if self.heartbeats and now - self._last_sent >= HEARTBEAT_S:
                await self._write(Frame("heartbeat", "beat", None))
            deadlines = [o.deadline for o in self._flight.values()]
            if self.heartbeats:
                deadlines.append(self._last_sent + HEARTBEAT_S)
            wait = min(deadlines, default=now + HEARTBEAT_S) - trio.current_time()
            with trio.move_on_after(max(wait, 0.01)):
                await self._wake.wait()
            self._wake = trio.Event()

    def wake(self) -> None:
        """Make the timers look again (a switch changed, or a frame was queued)."""
        self._wake.set()
