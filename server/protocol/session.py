"""Reliable delivery over a lossy line link: a sans-IO session, one per peer.

Both ends of a link run one `ReliableSession` (the server one per rover, a
rover's WiFly actor one for the server). The session turns bytes received into
frames to deliver and decides which bytes to transmit; the owner moves the
bytes and calls `transmit` again by `next_deadline`. It reads no clock: every
call that depends on time takes ``now`` [s].

Rules (the spec in docs/protocol.md says the same):

* **seq**: a frame that must not be lost gets the next ``seq`` of its sender
  (1, 2, 3 ...). At most ``window`` such frames are in flight (sent, not yet
  acknowledged); more wait in a bounded outbox (`OutboxFull` when it is full).
* **ack**: every frame the session sends carries ``ack``, the highest peer
  ``seq`` received in order (cumulative). A received frame with ``seq``
  makes an acknowledgement due; if no other frame leaves at the next
  `transmit`, a bare ``ack`` frame does.
* **order and duplicates**: frames with ``seq`` are delivered in ``seq``
  order; a frame ahead of a gap is held (at most ``2 * window`` of them),
  one at or below the cumulative ack is a duplicate: dropped, counted, and
  acknowledged again. Frames without ``seq`` are delivered at once.
* **telemetry** (``tm_*``) is unreliable: one that carries ``seq`` is refused
  like a frame that fails the catalogue check.
* **check**: a frame with ``seq`` that fails the catalogue check (a byte
  corrupted inside an envelope that still decodes) is answered with
  ``error`` and neither acknowledged nor delivered, and its ``ack`` is not
  believed: the peer resends it.
* **lost** counts the ``seq`` numbers missing in gaps when a gap is first seen
  (a later resend may still fill it; ``lost`` then says how many were lost
  on the first try).
* **resend**: an unacknowledged frame is sent again after the retransmission
  timeout (RFC 6298: ``srtt + 4 rttvar``, clamped, doubled per try). After
  ``max_tries`` sends the session counts the link as stalled and down, stops
  resending and resumes, trying again from the first, when the peer is heard.
  A frame is never dropped from the window: that would break the order
  every later frame waits for.
* **liveness**: the link is up while the peer was heard within
  ``down_after_s``; a heartbeat leaves when nothing was sent for
  ``heartbeat_s``. No reliable frame is sent for the first time while the
  link is down.
* **session**: every session has a ``session_id`` (an int in [0, 2**32)),
  chosen by its owner when the session is made: the identity of this
  numbering of reliable frames. A rebooted rover or a restarted server makes
  a new session, so a new id; an owner that restarts and keeps its session
  (the WiFly's `LinkMemory`) keeps the id. `session_id_for` derives one from
  the owner's name and the creation instant, deterministic under a virtual
  clock.
* **reset**: a ``hello`` / ``welcome`` tells the receiver the peer's
  ``seq_base`` (its oldest unacknowledged ``seq``) and its ``session``
  (`reset_peer`). The same session as the peer last announced is the same
  numbering: in-order reception never goes back (a hello or welcome that
  crossed frames in flight names a ``seq`` delivered since, which the peer
  will never resend), it only skips forward to ``seq_base``. A new or unknown
  session, or none (a peer that does not send one), restarts in-order
  reception at ``seq_base``: that is how a rebooted peer starts over.
"""

from __future__ import annotations

import zlib
from collections import deque
from dataclasses import dataclass

from .catalogue import ACK, CATALOGUE, HEARTBEAT, SESSION_ID_LIMIT, read_data
from .frame import MAX_SEQ, Fault, Frame, FrameError, decode_line, encode_frame, error_frame
from .lines import TOO_LONG, LineBuffer
from .telemetry import TELEMETRY_CMDS

__all__ = ["LinkStats", "OutboxFull", "ReliableSession", "session_id_for"]


def session_id_for(owner: str, now: float) -> int:
    """A session id for a session ``owner`` makes at ``now`` [s]: CRC-32 of both.

    Deterministic under a virtual clock (a simulation replays it); two sessions
    of one owner made at different instants get different ids (up to CRC-32
    collisions, 1 in 2**32). Under Trio's real clock ``now`` has a random
    offset per run, so a restarted process does not repeat its ids.
    """
    return zlib.crc32(f"{owner}@{now!r}".encode())


class OutboxFull(RuntimeError):
    """Raised by `ReliableSession.send` when the bounded outbox has no room."""


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters of one link, as a ground station shows them."""

    up: bool
    frames_in: int
    """Well-formed frames received (duplicates included)."""
    frames_out: int
    bytes_in: int
    bytes_out: int
    lost: int
    """Peer ``seq`` numbers missing when a gap was first seen."""
    resent: int
    """Frames sent again after a timeout."""
    duplicates: int
    """Received frames dropped as already delivered."""
    bad_frames: int
    """Received lines that were not valid frames (each answered with ``error``)."""
    dropped: int
    """Frames not sent because a bounded queue was full."""
    stalls: int
    """Times a frame reached ``max_tries`` and the link was declared down."""
    rtt_s: float | None
    """Smoothed round-trip time [s], None before the first sample."""
    unacked: int
    """Reliable frames in flight."""
    queued: int
    """Reliable frames waiting for room in the window."""
    last_heard: float | None
    """Time the peer was last heard [s, session clock], None if never."""


@dataclass(slots=True)
class _InFlight:
    frame: Frame
    first_sent: float
    deadline: float
    tries: int


class ReliableSession:
    """One end of a reliable line link (see the module docstring for the rules).

    Args:
        now: current time [s].
        heartbeat_s: send a heartbeat after this long without sending [s].
        down_after_s: the link is down after this long without hearing the peer [s].
        rto_initial_s: retransmission timeout before the first RTT sample [s].
        rto_min_s: lower clamp of the timeout [s].
        rto_max_s: upper clamp of the timeout, backoff included [s].
        max_tries: sends of one frame before the link counts as stalled.
        window: reliable frames in flight at most.
        outbox_limit: reliable frames waiting for the window at most.
        unreliable_limit: unreliable frames waiting for `transmit` at most
            (the oldest is dropped and counted beyond it).
        session_id: this session's identity, said in hello/welcome (see
            `session_id`); None: `session_id_for` with no owner name and ``now``.

    Raises:
        ValueError: a bound below 1, timings out of order, or ``session_id``
            outside ``[0, 2**32)``.
    """

    def __init__(self, *, now: float = 0.0, heartbeat_s: float = 1.0, down_after_s: float = 5.0,
                 rto_initial_s: float = 1.0, rto_min_s: float = 0.3, rto_max_s: float = 8.0,
                 max_tries: int = 8, window: int = 8, outbox_limit: int = 256,
                 unreliable_limit: int = 64, session_id: int | None = None) -> None:
        if session_id is None:
            session_id = session_id_for("", now)
        if not 0 <= session_id < SESSION_ID_LIMIT:
            raise ValueError(f"session_id must be in [0, 2**32), got {session_id}")
        if window < 1 or outbox_limit < 1 or unreliable_limit < 1 or max_tries < 1:
            raise ValueError("window, outbox_limit, unreliable_limit and max_tries must be >= 1")
        if not 0 < heartbeat_s < down_after_s:
            raise ValueError(
                f"need 0 < heartbeat_s < down_after_s, got {heartbeat_s}, {down_after_s}")
        self.heartbeat_s = heartbeat_s
        self.down_after_s = down_after_s
        self.rto_min_s = rto_min_s
        self.rto_max_s = rto_max_s
        self.max_tries = max_tries
        self.window = window
        self.outbox_limit = outbox_limit
        self.unreliable_limit = unreliable_limit
        self.session_id = session_id
        """The identity of this numbering of reliable frames: said as ``session`` in
        hello/welcome, so the peer tells a resent announcement from a restart."""
        self._lines = LineBuffer()
        # sending side
        self._next_seq = 1
        self._outbox: deque[Frame] = deque()         # reliable, not yet given a seq
        self._unreliable: deque[Frame] = deque()      # leave at the next transmit
        self._flight: dict[int, _InFlight] = {}      # seq -> in flight, ascending
        self._last_sent: float | None = None
        self._srtt: float | None = None
        self._rttvar = 0.0
        self._rto = rto_initial_s
        # receiving side
        self._rx_next = 1                             # next peer seq expected in order
        self._held: dict[int, Frame] = {}             # peer frames ahead of a gap
        self._peer_session: int | None = None         # last announced; None: none said
        self._highest_seen = 0
        self._ack_due = False
        self._last_heard: float | None = None
        self._stalled = False
        self._created = now
        # counters
        self._c = dict(frames_in=0, frames_out=0, bytes_in=0, bytes_out=0, lost=0, resent=0,
                       duplicates=0, bad_frames=0, dropped=0, stalls=0)

    def __repr__(self) -> str:
        s = self.stats(self._last_heard or self._created)
        return (f"<ReliableSession up={s.up} in={s.frames_in} out={s.frames_out} "
                f"unacked={s.unacked} queued={s.queued} lost={s.lost} resent={s.resent}>")

    # -- public: state ------------------------------------------------------

    def is_up(self, now: float) -> bool:
        """True while the peer was heard within ``down_after_s`` and the link is not stalled."""
        return (not self._stalled and self._last_heard is not None
                and now - self._last_heard < self.down_after_s)

    @property
    def last_heard(self) -> float | None:
        """When the peer was last heard [s], or None (cheap: the server asks every tick)."""
        return self._last_heard

    @property
    def seq_base(self) -> int:
        """Our oldest unacknowledged ``seq``, or the next one: goes in hello/welcome."""
        if self._flight:
            return next(iter(self._flight))
        return self._next_seq

    @property
    def ack_value(self) -> int:
        """The cumulative ack we send: highest peer ``seq`` received in order."""
        return self._rx_next - 1

    def stats(self, now: float) -> LinkStats:
        """A snapshot of the counters."""
        return LinkStats(up=self.is_up(now), rtt_s=self._srtt, unacked=len(self._flight),
                         queued=len(self._outbox), last_heard=self._last_heard, **self._c)

    def next_deadline(self, now: float) -> float:
        """The latest time [s] by which `transmit` must be called again."""
        if self._ack_due or self._unreliable:
            return now
        up = self.is_up(now)
        if up and self._outbox and len(self._flight) < self.window:
            return now
        t = (self._last_sent if self._last_sent is not None else now) + self.heartbeat_s
        if self._last_heard is not None and up:
            t = min(t, self._last_heard + self.down_after_s)
        if up:
            for f in self._flight.values():
                t = min(t, f.deadline)
        return max(t, now)

    # -- public: sending ------------------------------------------------------

    def send(self, frame: Frame, *, reliable: bool | None = None) -> None:
        """Queue a frame; ``reliable`` defaults to the catalogue's rule for its ``cmd``.

        Raises:
            OutboxFull: a reliable frame found the outbox full (nothing queued).
        """
        if reliable is None:
            spec = CATALOGUE.get(frame.cmd)
            reliable = bool(spec and spec.reliable)
        if reliable:
            if len(self._outbox) >= self.outbox_limit:
                self._c["dropped"] += 1
                raise OutboxFull(f"outbox full ({self.outbox_limit} frames): {frame.cmd!r} "
                                 "not queued")
            self._outbox.append(frame)
        else:
            if len(self._unreliable) >= self.unreliable_limit:
                self._unreliable.popleft()
                self._c["dropped"] += 1
            self._unreliable.append(frame)

    def pending(self) -> list[Frame]:
        """Reliable frames not yet acknowledged, oldest first (in flight, then queued),
        without ``seq``/``ack``: what a restarted owner must send again."""
        return ([Frame(f.frame.cmd, f.frame.type, f.frame.data) for f in self._flight.values()]
                + list(self._outbox))

    @property
    def pending_mark(self) -> tuple[int, int]:
        """(oldest unacknowledged ``seq``, frames pending): changes exactly when `pending` does."""
        return self.seq_base, len(self._flight) + len(self._outbox)

    def outbox_room(self) -> int:
        """Reliable frames that `send` accepts now without `OutboxFull`."""
        return self.outbox_limit - len(self._outbox)

    def send_error(self, exc: FrameError, frame: Frame | None = None) -> None:
        """Answer a bad frame with an ``error`` naming the fault (unreliable)."""
        self.send(error_frame(exc.fault, exc.detail,
                              cmd=frame.cmd if frame else None,
                              seq=frame.seq if frame else None), reliable=False)

    def transmit(self, now: float) -> bytes:
        """Every byte due now: unreliable frames, new and resent reliable frames,
        a heartbeat or bare ack when needed. Empty when nothing is due."""
        out: list[Frame] = list(self._unreliable)
        self._unreliable.clear()
        up = self.is_up(now)
        if up:
            for f in self._flight.values():
                if now >= f.deadline:
                    if f.tries >= self.max_tries:
                        self._stall()
                        break
                    f.tries += 1
                    f.deadline = now + self._backoff(f.tries)
                    self._c["resent"] += 1
                    out.append(f.frame)
            up = self.is_up(now)  # a stall above takes the link down; nothing below can
            while up and self._outbox and len(self._flight) < self.window:
                if self._next_seq > MAX_SEQ:
                    raise RuntimeError("seq space exhausted: reset the session with hello")
                frame = self._outbox.popleft()
                seq = self._next_seq
                self._next_seq += 1
                stamped = Frame(frame.cmd, frame.type, frame.data, seq=seq)
                self._flight[seq] = _InFlight(stamped, now, now + self._backoff(1), 1)
                out.append(stamped)
        bare_ack = False
        if not out:
            if self._ack_due:
                out.append(Frame(ACK, "ack", None))
                bare_ack = True
            elif self._last_sent is None or now - self._last_sent >= self.heartbeat_s:
                out.append(Frame(HEARTBEAT, "beat", None))
        if not out:
            return b""
        # an ack frame always says its ack (0 before anything arrived in order)
        ack = self.ack_value if self._rx_next > 1 or bare_ack else None
        lines = []
        for f in out:
            lines.append(encode_frame(Frame(f.cmd, f.type, f.data, seq=f.seq, ack=ack)))
        self._ack_due = False
        self._last_sent = now
        data = b"".join(lines)
        self._c["frames_out"] += len(lines)
        self._c["bytes_out"] += len(data)
        return data

    def transmit_alone(self, frame: Frame, now: float) -> bytes:
        """The bytes of one unreliable ``frame``, sent now and alone: what is queued
        stays queued (a rover's ``hello`` before the welcome, when nothing else may go)."""
        ack = self.ack_value if self._rx_next > 1 else None
        data = encode_frame(Frame(frame.cmd, frame.type, frame.data, ack=ack))
        self._last_sent = now
        self._c["frames_out"] += 1
        self._c["bytes_out"] += len(data)
        return data

    # -- public: receiving ------------------------------------------------------

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """Take bytes from the link; return the frames to deliver, in order.

        Bad lines are counted and answered with an ``error`` frame (queued for
        the next `transmit`). Duplicates are dropped. Frames pass the frame
        schema only: check them against the catalogue with `read_data`.
        """
        self._c["bytes_in"] += len(data)
        delivered: list[Frame] = []
        for line in self._lines.feed(data):
            if line is TOO_LONG:
                self._bad(FrameError("too_long", "line exceeds 1024 bytes"))
                continue
            try:
                frame = decode_line(line)  # type: ignore[arg-type]
                delivered.extend(self.receive(frame, now))
            except FrameError as exc:
                self._bad(exc)
        return delivered

    def receive(self, frame: Frame, now: float) -> list[Frame]:
        """Take one decoded frame; return the frames now deliverable, in order.

        Raises:
            FrameError: a reliable frame (one with ``seq``) that fails the
                catalogue check. It is neither acknowledged nor delivered, and its
                ``ack`` is not believed, so the peer resends it: a frame whose
                envelope survived a corrupted byte is not lost for its payload.
        """
        if frame.seq is not None:
            if frame.cmd in TELEMETRY_CMDS:
                raise FrameError(Fault.BAD_FRAME, f"{frame.cmd!r} is telemetry: it never "
                                 "carries seq")
            read_data(frame)
        self._c["frames_in"] += 1
        was_down = not self.is_up(now)
        self._last_heard = now
        if was_down:
            self._stalled = False
            for f in self._flight.values():  # resend what the peer may have missed
                f.deadline = now
                f.tries = 0
        if frame.ack is not None:
            self._on_ack(frame.ack, now)
        if frame.seq is None:
            return [] if frame.cmd in (ACK, HEARTBEAT) else [frame]
        self._ack_due = True
        seq = frame.seq
        if seq > self._highest_seen:
            base = max(self._highest_seen, self._rx_next - 1)
            if seq > base + 1:
                self._c["lost"] += seq - base - 1
            self._highest_seen = seq
        if seq < self._rx_next or seq in self._held:
            self._c["duplicates"] += 1
            return []
        if seq > self._rx_next:
            if seq - self._rx_next < 2 * self.window:
                self._held[seq] = frame
            else:
                self._c["dropped"] += 1
            return []
        out = [frame]
        self._rx_next += 1
        while self._rx_next in self._held:
            out.append(self._held.pop(self._rx_next))
            self._rx_next += 1
        return [f for f in out if f.cmd not in (ACK, HEARTBEAT)]

    @property
    def peer_session(self) -> int | None:
        """The ``session`` the peer last announced, None before one (or from a peer
        that sends none)."""
        return self._peer_session

    def reset_peer(self, seq_base: int, session: int | None = None) -> None:
        """The peer announced (hello/welcome) its oldest unacknowledged ``seq_base``.

        ``session`` equal to the one last announced: the same numbering, so in-order
        reception never goes back (frames below it stay duplicates); it moves
        forward to ``seq_base`` when that is ahead. Otherwise (a new session, the
        first one heard, or None from a peer that says none) reception restarts at
        ``seq_base`` and ``session`` is remembered.

        Raises:
            ValueError: ``seq_base`` below 1.
        """
        if seq_base < 1:
            raise ValueError(f"seq_base must be >= 1, got {seq_base}")
        same = session is not None and session == self._peer_session
        self._peer_session = session
        if same:
            if seq_base <= self._rx_next:
                return  # frames below our next one were taken already
            # the peer gave up frames we never took
            highest = max(self._highest_seen, seq_base - 1)
        else:
            highest = seq_base - 1
        self._rx_next, self._highest_seen = seq_base, highest
        self._held.clear()

    def reject(self, exc: FrameError, frame: Frame | None = None) -> None:
        """Count a bad frame the owner found (catalogue check failed) and answer it."""
        self._c["bad_frames"] += 1
        self.send_error(exc, frame)

    def note_bytes_in(self, n: int) -> None:
        """Count bytes received when the owner splits lines itself instead of `feed`."""
        self._c["bytes_in"] += n

    # -- internals ----------------------------------------------------------------

    def _bad(self, exc: FrameError) -> None:
        self._c["bad_frames"] += 1
        self.send_error(exc)

    def _backoff(self, tries: int) -> float:
        return min(self._rto * (2 ** (tries - 1)), self.rto_max_s)

    def _stall(self) -> None:
        # The peer has not acknowledged after max_tries sends: stop resending
        # (bounded tries) until it is heard again, which restarts the tries.
        self._stalled = True
        self._c["stalls"] += 1

    def _on_ack(self, ack: int, now: float) -> None:
        for seq in [s for s in self._flight if s <= ack]:
            f = self._flight.pop(seq)
            if f.tries == 1:  # Karn: only frames sent once give a clean sample
                self._rtt_sample(now - f.first_sent)

    def _rtt_sample(self, r: float) -> None:
        if self._srtt is None:
            self._srtt, self._rttvar = r, r / 2
        else:
            self._rttvar = 0.75 * self._rttvar + 0.25 * abs(self._srtt - r)
            self._srtt = 0.875 * self._srtt + 0.125 * r
        self._rto = min(max(self._srtt + max(0.05, 4 * self._rttvar), self.rto_min_s),
                        self.rto_max_s)
