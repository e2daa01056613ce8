"""What the phases of a check share: the link, the peer, the transcript, the findings.

`Checker` is made by `runner.check_rover`; each rule module's phase takes it.
Times are the rover's seconds (the check runs on a clock at the rover's
``--speed``).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any

import trio

from ..protocol import SESSION_ID_LIMIT, Frame, FrameError, read_data
from ..protocol.frame import Fault
from .link import RoverLink
from .peer import Peer, Seen, Transcript
from .rules import Findings

__all__ = ["Options", "Checker", "Expect", "SERVER_NAME", "SERVER_SESSION", "TELEMETRY_STREAMS"]

SERVER_NAME = "hideseek-check/1"
"""What the checker's welcome calls the server."""
SERVER_SESSION = zlib.crc32(SERVER_NAME.encode())
"""The ``session`` of the checker's first numbering; each restart it claims adds one."""
TELEMETRY_STREAMS = ("mailboxes", "tree", "map", "pose", "events")
"""The telemetry streams a hello may list."""


@dataclass(frozen=True, slots=True)
class Options:
    """How one check runs."""

    role: str | None = None
    """The role the rover must say in hello (None: whatever it says)."""
    timeout_s: float = 300.0
    """The whole check at most [s, rover clock]."""
    connect_s: float = 15.0
    """Longest wait for the rover's first frame, or its return after a drop [s]."""
    map_s: float = 4.0
    """How long a mapper maps before ``stop`` [s]."""
    report_s: float = 120.0
    """Longest wait for a hider's or seeker's report, or a mapper's upload [s]."""
    slack_s: float = 0.4
    """Added to every timing bound (a rover's tick, the host's scheduling) [s]."""
    tm_interval_s: float = 0.5
    """The interval the welcome asks of each telemetry stream but events [s]."""
    tm_share: float = 0.25
    """The welcome's telemetry_share."""
    line_baud: int = 57600
    """The line telemetry_share is a share of, for links without a baud rate [bit/s]."""


@dataclass(frozen=True, slots=True)
class Expect:
    """A reliable frame of the checker that the rover must acknowledge promptly."""

    seq: int
    index: int
    """Its place in the transcript."""
    t: float
    epoch: int
    """The checker's numbering it belongs to (a claimed restart starts a new one)."""


@dataclass
class Checker:
    """One check under way (see the module docstring)."""

    opts: Options
    link: RoverLink
    peer: Peer
    tx: Transcript
    found: Findings
    nursery: trio.Nursery
    hello: dict[str, Any] = field(default_factory=dict)
    """The data of the rover's first accepted hello."""
    streams: tuple[str, ...] | None = None
    """Telemetry streams hello listed (None: the field was absent)."""
    faults: tuple[str, ...] | None = None
    """Faults hello listed (None: the field was absent)."""
    asked: dict[str, float] = field(default_factory=dict)
    """The streams the welcome asked for, and their intervals [s]."""
    expects: list[Expect] = field(default_factory=list)
    epoch: int = 0
    """Restarts of the checker's numbering claimed so far (a new ``session`` each)."""
    welcomes: list[tuple[int, float]] = field(default_factory=list)
    """(transcript index, time) of every welcome sent."""
    quiet: list[tuple[float, float]] = field(default_factory=list)
    """Spans [s] in which the rover need not speak (the link was being dropped or resynced)."""
    auto_welcome: bool = False
    """Answer a hello that no phase waits for with a welcome (the server's rule)."""
    lost_link: str = ""
    pending: Seen | None = None
    """A reliable frame of the rover left unacknowledged for the resync."""
    """Why the link is gone for good (later phases are skipped), empty while it is up."""

    @property
    def role(self) -> str:
        return str(self.hello.get("role", self.opts.role or ""))

    def slack(self, bound: float) -> float:
        return bound + self.opts.slack_s

    # -- sending -----------------------------------------------------------------------

    async def send(self, cmd: str, type_: str, data: Any = None, *, reliable: bool = True,
                   expect_ack: bool = True) -> tuple[int, int]:
        """Send a frame; returns (its ``seq`` or 0, its transcript index)."""
        index = len(self.tx.lines)
        seq = await self.peer.send(Frame(cmd, type_, data), reliable=reliable)
        if seq and expect_ack:
            self.expects.append(Expect(seq, index, self.tx.now(), self.epoch))
        return seq, index

    @property
    def session(self) -> int:
        """The ``session`` the checker says in its welcomes: new with every ``epoch``."""
        return (SERVER_SESSION + self.epoch) % SESSION_ID_LIMIT

    async def welcome(self, seq_base: int) -> int:
        """Send the welcome (telemetry asked as `asked`); returns its transcript index."""
        data: dict[str, Any] = {"server": SERVER_NAME, "heartbeat_s": 1.0,
                                "down_after_s": 5.0, "seq_base": seq_base,
                                "session": self.session}
        if self.asked:
            data["telemetry"] = dict(self.asked)
            data["telemetry_share"] = self.opts.tm_share
        index = len(self.tx.lines)
        await self.peer.send(Frame("welcome", "server", data))
        self.welcomes.append((index, self.tx.now()))
        self.peer.heartbeats = True
        return index

    async def hello_first(self) -> int:
        """Send 'send hello first' (as the server does); returns its transcript index."""
        index = len(self.tx.lines)
        await self.peer.send(Frame("error", "fault", {"fault": Fault.NOT_ALLOWED,
                                                      "detail": "send hello first"}))
        return index

    async def serve(self, stream: Any) -> None:
        """Serve a new stream of the rover."""
        await self.nursery.start(self.peer.serve, stream)

    async def on_frame(self, frame: Frame) -> None:
        """A hello no phase waits for is welcomed, as the server welcomes any hello."""
        if frame.cmd == "hello" and self.auto_welcome:
            base = read_hello(frame)
            if base is not None:
                self.peer.reset_rover_seq(int(base.get("seq_base") or 1))
                unacked = self.peer.unacked()
                await self.welcome(unacked[0] if unacked else self.peer.next_seq)



def read_hello(frame: Frame) -> dict[str, Any] | None:
    """The data of a hello that passes the catalogue, None otherwise."""
    try:
        read_data(frame)
    except FrameError:
        return None
    return frame.data if isinstance(frame.data, dict) else None
