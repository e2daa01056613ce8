"""WiFly (all rovers): the rover's end of the JSON message layer to the server.

The seed's WiFly thread. Bytes from the WiFly UART ISR (Int B) arrive as
``WIFLY_RX`` (handle of the bytes); frames to send arrive from navigation as
``WIFLY_SEND`` (reliable), ``WIFLY_SEND_UNRELIABLE`` (telemetry) and
``WIFLY_SEND_MAP`` (a `GridMap` to upload in chunks, reliably), each a handle
in the rover's `BufferPool`. A self-timer (``WIFLY_TIMER``) drives heartbeats,
resends and reconnects.

Timer (why: a WiFly ticking every ``tick_s`` whatever was due made a fifth of a
seeking phase's messages): every burst of messages ends by working out the
earliest moment something falls due (`Wifly.due`: the next heartbeat or resend
by `ReliableSession.next_deadline`, the next hello of the backoff, the moment
the server counts as unheard) and arming one one-shot timer for it, rounded up
to the ``tick_s`` grid that starts when the actor starts. The grid is the
timer's resolution, so everything leaves at the tick it left at with a timer
ticking every ``tick_s``; ticks with nothing due are not made. While something
waits on a neighbour (navigation's mailbox full, the outbox with room for the
backlog, a stalled link to be declared down) the timer polls every ``tick_s``.

Protocol (server.protocol, docs/protocol.md)
    * **connect**: ``hello`` (id, role, token, ``seq_base``, ``session``) is sent until the
      server answers ``welcome``; unanswered hellos back off from ``hello_s``
      doubling up to ``hello_max_s``; ``send hello first`` from the server
      asks for one at once. With ``hold_until_welcome`` (a rover on a real
      link) nothing but hello leaves until the welcome: telemetry, heartbeats
      and reliable frames wait in the session's bounded queues. ``NAV_LINK``
      1 goes to navigation on welcome, 0 when the link goes down.
    * **reliable delivery**: a `ReliableSession` numbers reliable frames,
      resends them until acknowledged, drops duplicates and keeps order.
    * **drop and reconnect**: when the server has not been heard for
      ``down_after_s`` (or resends stalled) the link is down: hello again
      with backoff. Hello carries our oldest unacknowledged ``seq`` and our
      session id: the server's reception continues (never going back) and the
      frames that were in flight are resent: nothing reliable is lost to a
      link fault. A welcome naming the server session we know never takes our
      reception back either (it may answer a hello that crossed frames in
      flight); a new server session restarts it at its ``seq_base``.
    * **incoming**: frames checked against the catalogue (a bad one is
      answered with ``error``); ``map`` chunks are assembled here and the
      whole map goes to navigation as one ``NAV_MAP_DOWNLOAD`` (handle of a
      `GridMap` in the map frame); every other frame for the rover goes to
      navigation as ``NAV_NET`` (handle of the `Frame`).

Bounds: the session's window and outbox, a backlog of reliable frames waiting
for outbox room (``max_backlog``; beyond it frames are dropped and counted),
and a queue of deliveries waiting for room in navigation's mailbox
(``max_to_nav``). Navigation's queue being full never blocks this actor.

Restarts: the session (sequence numbers, frames in flight, the backlog) lives
in a `LinkMemory` made by the rover tree, the model of the UART driver's
buffers in retained RAM: a restarted WiFly says hello again with its
``seq_base`` and session id and resends what was not acknowledged. A rover
reset (a new tree) starts a fresh session with a new id, so the server
restarts its reception at that hello's ``seq_base``.
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from typing import Any

import trio

from actors import Actor, BufferPool, Message, PoolExhausted, Timer
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import WiflyUartIsr
from actors.firmware.fault_port import AnsweredFaults, FaultPort
from actors.firmware.hardware import Interrupt, RoverHardware
from server.protocol import (
    ERROR,
    FAULT,
    FAULT_REPLY,
    HELLO,
    MAP,
    WELCOME,
    Fault,
    Frame,
    FrameError,
    GridMap,
    MapAssembler,
    MapError,
    OutboxFull,
    ReliableSession,
    TelemetryLane,
    make_frame,
    map_chunks,
    read_data,
    session_id_for,
)

_TICK = Message.uint(Cmd.WIFLY_TIMER, 0)

_HANDLE_COMMANDS = frozenset((Cmd.WIFLY_RX, Cmd.WIFLY_SEND, Cmd.WIFLY_SEND_UNRELIABLE,
                              Cmd.WIFLY_SEND_MAP))
"""Commands whose value is a pool handle (released by `Wifly.discard` when dropped)."""

_GRID_TOLERANCE = 1e-6
"""Times within this many grid steps of a grid point count as on it (a timer's due time
is the sum of the clock and a delay, which may round a little off the grid)."""

_MAX_STEPS = 10_000
"""Grid steps walked one by one before `Wifly._arm` jumps by multiplication (bounds a
wake-up's cost after a long gap)."""

__all__ = ["LinkMemory", "Wifly"]


class LinkMemory:
    """Retained memory of the WiFly driver: the reliable session and its backlog.

    Made once per rover by the tree builder; only the WiFly actor touches it.

    Args:
        session: the session (when None, a new one with default timing and a
            ``session_id`` from ``owner`` and the instant it is made).
        owner: the rover id, named in the new session's id.
    """

    __slots__ = ("session", "backlog", "to_nav", "map_id", "dropped", "faults")

    def __init__(self, session: ReliableSession | None = None, *, owner: str = "") -> None:
        if session is None:
            now = trio.current_time()
            session = ReliableSession(now=now, session_id=session_id_for(owner, now))
        self.session = session
        """The reliable session with the server; its id lives as long as this memory."""
        self.backlog: deque[Frame] = deque()
        """Reliable frames waiting for room in the session's outbox, in order."""
        self.to_nav: deque[tuple[int, Any]] = deque()
        """Items received for navigation, waiting for room in its mailbox."""
        self.map_id = 0
        """The last map id uploaded."""
        self.dropped = 0
        """Frames dropped because a bounded queue was full."""
        self.faults = AnsweredFaults()
        """The replies to the last faults answered (a resent fault is not applied twice)."""


class Wifly(Actor):
    """The ``<rover>/wifly`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (WiFly UART, Int B).
        pool: the rover's buffer pool.
        memory: retained link memory (survives restarts); a new one when None.
        rover_id: the id said in hello (``[A-Za-z0-9_.-]``, at most 32).
        role: ``mapper``, ``hider`` or ``seeker``.
        token: the shared secret, when the server asks for one.
        isr: the WiFly UART ISR (its counters survive restarts); made here when None.
        tick_s: the timer's resolution [s]: wake-ups fall on a grid of this step.
        hello_s: first hello retry interval [s].
        hello_max_s: the longest hello retry interval (backoff cap) [s].
        max_backlog: reliable frames waiting for the outbox at most.
        max_to_nav: deliveries waiting for navigation's mailbox at most.
        hold_until_welcome: send nothing but hello until the welcome (a rover on a
            serial, TCP or UDP link, which the server may not know yet). A simulated
            rover on the server's in-memory link sends its queued frames from the
            start: its hello always arrives first there, and the server never drops
            that link.
        telemetry: the rover's telemetry lane (`TelemetryLane`): the streams the
            server asks for in the welcome are configured on it, and its frames leave
            after the game frames of each transmission, within its byte budget. None:
            the rover offers no telemetry.
        streams: the telemetry streams offered in hello (with ``telemetry``).
        faults: the rover's failure-injection hook; its `FaultPort.catalogue` goes in
            hello and every ``fault`` frame is answered from it. None: every fault is
            ``unsupported``.
    """

    def __init__(self, hardware: RoverHardware, pool: BufferPool, *, rover_id: str, role: str,
                 memory: LinkMemory | None = None, token: str | None = None,
                 isr: WiflyUartIsr | None = None, tick_s: float = 0.1, hello_s: float = 1.0,
                 hello_max_s: float = 8.0, max_backlog: int = 4096,
                 max_to_nav: int = 256, addresses: Addresses | None = None,
                 hold_until_welcome: bool = False, telemetry: TelemetryLane | None = None,
                 streams: tuple[str, ...] = (), faults: FaultPort | None = None) -> None:
        self._addresses = addresses
        # check the hello once here: a bad id is a configuration error, not a crash loop
        make_frame(HELLO, {"id": rover_id, "role": role, "token": token})
        self.hw = hardware
        self.pool = pool
        self.memory = memory
        self.rover_id, self.role, self.token = rover_id, role, token
        self._isr = isr
        self.tick_s = tick_s
        self.hello_s, self.hello_max_s = hello_s, hello_max_s
        self.max_backlog, self.max_to_nav = max_backlog, max_to_nav
        self.hold_until_welcome = hold_until_welcome
        self.telemetry = telemetry
        self.streams = streams if telemetry is not None else ()
        self.fault_port = faults
        self.welcomed = False
        """True between the server's welcome and the link going down."""
        self.hellos = 0
        """Hello frames sent by this incarnation."""
        self.maps_in = 0
        """Whole maps downloaded."""
        self._assembler = MapAssembler()
        self._next_hello = -math.inf
        self._last_hello = -math.inf  # when the last hello left [s]
        self._hello_wait = hello_s
        self._timer: Timer | Any = None  # the one-shot timer armed for `_wake_at`
        self._wake_at = -math.inf  # when the armed timer fires [s]
        self._grid = 0.0  # the latest point of the tick grid not after the last burst [s]

    # ------------------------------------------------------------------ lifetime
    async def on_start(self) -> None:
        self._nav = (self._addresses or Addresses.beside(self.ctx.name)).nav
        if self.memory is None:
            self.memory = LinkMemory(owner=self.rover_id)
        self._to_nav = self.memory.to_nav
        if self._isr is None:
            self._isr = WiflyUartIsr(self._post, self.pool)
        self.hw.attach(Interrupt.INT_B, self._isr)
        self._grid = self._wake_at = trio.current_time()
        self._timer = self.ctx.start_timer(0.0, _TICK)

    def _post(self, message: Message) -> bool:
        return self.ctx.system.send_nowait(self.ctx.name, message)

    @property
    def session(self) -> ReliableSession:
        """The reliable session with the server."""
        assert self.memory is not None
        return self.memory.session

    def statistics(self) -> dict[str, Any]:
        """Link counters: the session's plus this actor's."""
        mem = self.memory
        assert mem is not None
        stats = self.session.stats(trio.current_time())
        return {"up": stats.up, "welcomed": self.welcomed, "resent": stats.resent,
                "duplicates": stats.duplicates, "lost": stats.lost,
                "dropped": stats.dropped + mem.dropped, "frames_in": stats.frames_in,
                "frames_out": stats.frames_out, "hellos": self.hellos, "stalls": stats.stalls,
                "backlog": len(mem.backlog), "unacked": stats.unacked}

    # ------------------------------------------------------------------ messages
    async def handle(self, message: Message) -> None:
        await self.handle_burst([message])

    async def handle_burst(self, messages: list[Message]) -> None:
        now = trio.current_time()
        for m in messages:
            cmd = m.command
            if cmd == Cmd.WIFLY_RX:
                self._receive(self.pool.take(int(m.value)), now)
            elif cmd == Cmd.WIFLY_SEND:
                self._queue_reliable([self.pool.take(int(m.value))])
            elif cmd == Cmd.WIFLY_SEND_UNRELIABLE:
                self.session.send(self.pool.take(int(m.value)), reliable=False)
            elif cmd == Cmd.WIFLY_SEND_MAP:
                self._upload(self.pool.take(int(m.value)))
            elif cmd == Cmd.WIFLY_LINK_OPEN and not self.welcomed:
                # a new connection: hello now, not at the end of the backoff (a server
                # closes a connection without hello after 5 s), unless one just left (it
                # may be on its way yet); a welcomed rover's next frame is answered
                # "send hello first" if the server does not know it
                self._next_hello = min(self._next_hello,
                                       max(now, self._last_hello + self.hello_s / 2))
                self._hello_wait = self.hello_s
            elif cmd == Cmd.WIFLY_LINK_OPEN:
                pass
            elif cmd == Cmd.WIFLY_TIMER or cmd == Cmd.NOOP:
                pass  # the work below runs after every burst; NOOP is a flood fault's filler
            else:
                raise ValueError(f"wifly got an unknown command 0x{cmd:04x}")
        self._service(now)
        self._arm(now)

    def discard(self, message: Message) -> None:
        """A dropped poison message gives its pool buffer back (the handler may have taken it)."""
        if message.command in _HANDLE_COMMANDS:
            with contextlib.suppress(KeyError):
                self.pool.take(int(message.value))

    # ------------------------------------------------------------------ sending
    def _queue_reliable(self, frames: list[Frame]) -> None:
        mem = self.memory
        assert mem is not None
        for f in frames:
            if not isinstance(f, Frame):
                raise TypeError(f"wifly can send only a Frame, got {type(f).__name__}")
            if len(mem.backlog) >= self.max_backlog:
                mem.dropped += 1
                continue
            mem.backlog.append(f)

    def _upload(self, grid: GridMap) -> None:
        mem = self.memory
        assert mem is not None
        mem.map_id = (mem.map_id + 1) % (2**31)
        self._queue_reliable(map_chunks(grid, mem.map_id))

    def _service(self, now: float) -> None:
        """Liveness, hello, deliveries to navigation, and transmitting what is due."""
        session = self.session
        mem = self.memory
        assert mem is not None
        if self.welcomed and not session.is_up(now):
            self._link(False)
            self._next_hello = now
        while mem.backlog and session.outbox_room() > 0:
            try:
                session.send(mem.backlog[0], reliable=True)
            except OutboxFull:
                break
            mem.backlog.popleft()
        self._deliver()
        hello_due = not self.welcomed and now >= self._next_hello
        if hello_due:
            self.hellos += 1
            self._last_hello = now
            self._next_hello = now + self._hello_wait
            self._hello_wait = min(self._hello_wait * 2, self.hello_max_s)
        if not self.welcomed and self.hold_until_welcome:
            # only hello leaves: a server that does not know this link refuses anything
            # else ("send hello first"); the rest waits in the session's bounded queues
            if hello_due:
                self.hw.wifly_write(session.transmit_alone(self._hello(), now))
            return
        if hello_due:
            session.send(self._hello(), reliable=False)
        data = session.transmit(now)
        lane = self.telemetry
        if lane is not None and self.welcomed and lane.has_queued():
            data += lane.take(now)  # after the game frames, within the budget
        if data:
            self.hw.wifly_write(data)

    # ------------------------------------------------------------------ timer
    def due(self, now: float) -> float:
        """The earliest time [s] at which the link needs servicing though no message
        comes: ``now`` when something waits on a neighbour (poll at the next tick)."""
        session = self.session
        mem = self.memory
        assert mem is not None
        if self._to_nav or (mem.backlog and session.outbox_room() > 0):
            return now  # navigation's mailbox was full, or the outbox has room again
        if not self.welcomed:
            if self.hold_until_welcome:
                return self._next_hello  # only hello may leave
            return min(self._next_hello, session.next_deadline(now))
        if not session.is_up(now):
            return now  # stalled: the link is down at the next tick
        heard = session.last_heard
        down = heard + session.down_after_s if heard is not None else math.inf
        due = min(down, session.next_deadline(now))
        if self.telemetry is not None and self.telemetry.has_queued():
            due = min(due, self.telemetry.next_time(now))
        return due

    def _arm(self, now: float) -> None:
        """Arm the timer for the first tick of the grid after ``now`` at or after `due`
        (a pending timer for that tick stays; one for another is replaced)."""
        due = self.due(now)
        if not math.isfinite(due):
            return
        step = self.tick_s
        # a timer armed for a grid point may fire a rounding error before it
        at = now + step * _GRID_TOLERANCE
        grid = self._grid
        if now - grid > _MAX_STEPS * step:  # a long gap (no burst for a while): jump
            grid += math.floor((now - grid) / step) * step
        while grid + step <= at:
            grid += step
        self._grid = grid
        wake = grid + step
        if due - wake > _MAX_STEPS * step:
            wake += math.floor((due - wake) / step) * step
        while wake < due - step * _GRID_TOLERANCE:
            wake += step
        if wake == self._wake_at and self._wake_at > at and self._timer is not None:
            return  # the timer armed for that tick is still pending
        if self._timer is not None:
            self._timer.cancel()
        self._timer = self.ctx.start_timer(wake - now, _TICK)
        self._wake_at = wake

    def _hello(self) -> Frame:
        body: dict[str, Any] = {"id": self.rover_id, "role": self.role, "token": self.token,
                                "seq_base": self.session.seq_base,
                                "session": self.session.session_id}
        if self.streams:
            body["streams"] = list(self.streams)
        if self.fault_port is not None:
            body["faults"] = list(self.fault_port.catalogue())
        return make_frame(HELLO, body)

    # ------------------------------------------------------------------ receiving
    def _receive(self, data: bytes, now: float) -> None:
        # line by line: a welcome of a new server session restarts in-order reception,
        # so it must act before the session takes the frames after it (a chunk may hold
        # the welcome and the frames that follow it; taken together, they were counted
        # and then rewound)
        start = 0
        while start < len(data):
            end = data.find(b"\n", start)
            end = len(data) if end < 0 else end + 1
            self._frames(self.session.feed(data[start:end], now), now)
            start = end

    def _frames(self, frames: list[Frame], now: float) -> None:
        session = self.session
        for frame in frames:
            try:
                body = read_data(frame)
            except FrameError as exc:
                session.reject(exc, frame)
                continue
            if frame.cmd == WELCOME:
                # a welcome of the server session we know (one answering a hello that
                # crossed frames in flight) never takes reception back; a new one restarts it
                session.reset_peer(body.seq_base, body.session)
                self._hello_wait = self.hello_s
                if self.telemetry is not None:
                    self.telemetry.configure(body.telemetry, body.telemetry_share)
                if not self.welcomed:
                    self._link(True)
            elif frame.cmd == ERROR:
                if body.detail == "send hello first":  # the server forgot us: reconnect
                    if self.welcomed:
                        self._link(False)
                    self._next_hello = now
            elif frame.cmd == FAULT:
                self._fault(body)
            elif frame.cmd == MAP:
                try:
                    grid = self._assembler.add(body)
                except MapError as exc:
                    session.reject(FrameError(Fault.BAD_DATA, str(exc)), frame)
                    continue
                if grid is not None:
                    self.maps_in += 1
                    self._to_nav_put(Cmd.NAV_MAP_DOWNLOAD, grid)
            else:
                self._to_nav_put(Cmd.NAV_NET, frame)

    def _fault(self, command: Any) -> None:
        """Answer one ``fault`` (exactly one ``fault_reply``, reliable); one answered
        already (`AnsweredFaults`) gets the same reply and is not applied again."""
        if self.fault_port is None:
            result, detail = "unsupported", "this rover takes no faults over the link"
        else:
            assert self.memory is not None
            result, detail = self.memory.faults.answer(command, self.fault_port.apply)
        self._queue_reliable([make_frame(FAULT_REPLY, {"fault_id": command.fault_id,
                                                       "result": result,
                                                       "detail": detail[:200]})])

    def _link(self, up: bool) -> None:
        self.welcomed = up
        if not up and self.telemetry is not None:
            self.telemetry.configure({})
        self._to_nav_put(Cmd.NAV_LINK, int(up))

    def _to_nav_put(self, cmd: int, obj: Any) -> None:
        if len(self._to_nav) >= self.max_to_nav:
            assert self.memory is not None
            self.memory.dropped += 1
            return
        self._to_nav.append((cmd, obj))

    def _deliver(self) -> None:
        """Hand waiting items to navigation while its mailbox has room (never blocks)."""
        system = self.ctx.system
        cell = system.whereis(self._nav)
        while self._to_nav:
            if cell is None:
                return
            stats = cell.mailbox.statistics()
            if stats.depth >= stats.capacity:
                return
            cmd, obj = self._to_nav[0]
            if cmd == Cmd.NAV_LINK:
                message = Message.int(cmd, obj)
            else:
                try:
                    message = Message.handle(cmd, self.pool.put(obj))
                except PoolExhausted:
                    return  # try again at the next tick
            self._to_nav.popleft()
            system.send_nowait(self._nav, message)
