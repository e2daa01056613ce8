"""The message catalogue: every ``cmd``, its ``type``, payload schema and rules.

============  ============  ===========  ========  =====================================
cmd           type          direction    reliable  data
============  ============  ===========  ========  =====================================
hello         rover         rover->srv   no        `Hello` (repeat every 1 s until welcome)
welcome       server        srv->rover   no        `Welcome`
heartbeat     beat          both         no        null (about 1 Hz)
ack           ack           both         no        null (the ``ack`` field carries it)
error         fault         both         no        `ErrorInfo`
start         none          srv->rover   yes       null
stop          none          srv->rover   yes       null
origin        pose          srv->rover   yes       `PoseData`: rover's start pose, map frame
map_request   none          rover->srv   yes       null
map           chunk         both         yes       `MapChunk` (see `mapcodec`)
pose          pose          rover->srv   no        `PoseData` (map frame once origin known)
status        status        rover->srv   no        `Status`
destination   pose          srv->rover   yes       `Destination` (map frame)
arrived       pose          rover->srv   yes       `PoseData`
invalid_spot  reason        rover->srv   yes       `Reason`
found         pose          rover->srv   yes       `Found`
not_found     reason        rover->srv   yes       `Reason`
tm_*          (telemetry)   rover->srv   never     see `telemetry` (unreliable, newest wins)
fault         inject        srv->rover   yes       `FaultCommand`
fault_reply   fault_reply   rover->srv   yes       `FaultReply`
============  ============  ===========  ========  =====================================

Units: positions [cm], headings [deg] counter-clockwise from the frame's +x
axis. "reliable" means the sender gives the frame a ``seq`` and resends it
until acknowledged; any frame may carry ``seq``, a receiver acknowledges
every frame that does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

import msgspec

from .frame import Fault, Frame, FrameError
from .telemetry import (
    STREAMS,
    FaultCommand,
    FaultReply,
    TmEvent,
    TmMailboxes,
    TmMap,
    TmPose,
    TmTree,
)

__all__ = [
    "ROLES",
    "HELLO", "WELCOME", "HEARTBEAT", "ACK", "ERROR", "START", "STOP", "ORIGIN",
    "MAP_REQUEST", "MAP", "POSE", "STATUS", "DESTINATION", "ARRIVED", "INVALID_SPOT",
    "FOUND", "NOT_FOUND", "FAULT", "FAULT_REPLY",
    "Hello", "Welcome", "PoseData", "Destination", "Status", "Reason", "Found", "ErrorInfo",
    "MapChunk", "MAX_WITHIN_CM", "Spec", "CATALOGUE", "make_frame", "read_data",
    "SESSION_ID_LIMIT", "SessionId",
]

ROLES = ("mapper", "hider", "seeker")
"""The three rover roles."""

SESSION_ID_LIMIT = 2 ** 32
"""Session ids (``hello.session``, ``welcome.session``) are ints in ``[0, SESSION_ID_LIMIT)``."""
SessionId = Annotated[int, msgspec.Meta(ge=0, lt=SESSION_ID_LIMIT)]
"""A session id on the wire (`SESSION_ID_LIMIT`)."""

HELLO = "hello"
WELCOME = "welcome"
HEARTBEAT = "heartbeat"
ACK = "ack"
ERROR = "error"
START = "start"
STOP = "stop"
ORIGIN = "origin"
MAP_REQUEST = "map_request"
MAP = "map"
POSE = "pose"
STATUS = "status"
DESTINATION = "destination"
ARRIVED = "arrived"
INVALID_SPOT = "invalid_spot"
FOUND = "found"
NOT_FOUND = "not_found"
FAULT = "fault"
FAULT_REPLY = "fault_reply"

_Id = Annotated[str, msgspec.Meta(min_length=1, max_length=32, pattern=r"^[A-Za-z0-9_.-]+$")]
_Coord = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]
_Text = Annotated[str, msgspec.Meta(max_length=200)]

MAX_WITHIN_CM = 500.0
"""Largest search radius a ``destination`` may ask of a seeker [cm]: bounds its search."""


class Hello(msgspec.Struct, frozen=True):
    """Rover -> server, first frame on a link: who is speaking."""

    id: _Id
    """Rover id, e.g. ``hider-1``: letters, digits, ``_.-``, at most 32."""
    role: Literal["mapper", "hider", "seeker"]
    """The rover's role in the game."""
    token: Annotated[str, msgspec.Meta(max_length=64)] | None = None
    """Shared secret, required when the server is configured with tokens."""
    seq_base: Annotated[int, msgspec.Meta(ge=1)] = 1
    """``seq`` of the rover's oldest unacknowledged reliable frame (or its next one)."""
    session: SessionId | None = None
    """Identity of the rover's numbering of reliable frames (new after a reboot);
    absent: every hello restarts the server's reception at ``seq_base``."""
    streams: Annotated[list[Literal["mailboxes", "tree", "map", "pose", "events"]],
                       msgspec.Meta(max_length=len(STREAMS))] | None = None
    """Telemetry streams the rover can send (absent: none)."""
    faults: Annotated[list[Annotated[str, msgspec.Meta(min_length=3, max_length=48)]],
                      msgspec.Meta(max_length=64)] | None = None
    """``TARGET/KIND`` faults the rover accepts over the link (absent or empty: none)."""


class Welcome(msgspec.Struct, frozen=True):
    """Server -> rover, the answer to an accepted `Hello`."""

    server: str
    """Server name and protocol version, e.g. ``hideseek/1``."""
    heartbeat_s: float
    """Heartbeat period the server expects [s]."""
    down_after_s: float
    """Silence after which a link counts as down [s]."""
    seq_base: int
    """``seq`` of the server's oldest unacknowledged reliable frame (or its next one)."""
    session: SessionId | None = None
    """Identity of the server's numbering of reliable frames toward this rover (new
    after a server restart); absent: every welcome restarts reception at ``seq_base``."""
    telemetry: dict[Literal["mailboxes", "tree", "map", "pose", "events"],
                    Annotated[float, msgspec.Meta(ge=0, le=3600)]] | None = None
    """Stream -> interval [s] the server wants (0 = as it happens); absent: none."""
    telemetry_share: Annotated[float, msgspec.Meta(gt=0, le=1)] | None = None
    """Largest share of the link's bytes telemetry may use (absent: 0.25)."""


class PoseData(msgspec.Struct, frozen=True):
    """A pose as the wire carries it: position [cm] and heading [deg, CCW from +x].

    The payload schema of ``origin``, ``pose`` and ``arrived``; code works with
    `server.protocol.pose.Pose`, made from it."""

    x: _Coord
    y: _Coord
    heading: _Coord = 0.0


class Destination(msgspec.Struct, frozen=True):
    """Where to go, map frame; ``heading`` null means any heading."""

    x: _Coord
    y: _Coord
    heading: _Coord | None = None
    within: Annotated[float, msgspec.Meta(gt=0, le=MAX_WITHIN_CM)] | None = None
    """Seeker only: the hider is believed within this of (x, y) [cm]; absent means
    within the IR sensor's range. A seeker searches round the place that far."""


class Status(msgspec.Struct, frozen=True):
    """Free-form telemetry shown to the operator."""

    state: Annotated[str, msgspec.Meta(max_length=32)]
    """What the rover is doing: ``idle``, ``exploring``, ``driving``, ``searching`` ..."""
    detail: _Text | None = None
    coverage: Annotated[float, msgspec.Meta(ge=0, le=1)] | None = None
    """Mapper only: its own estimate of map completeness [0..1]."""
    battery: Annotated[float, msgspec.Meta(ge=0, le=1)] | None = None


class Reason(msgspec.Struct, frozen=True):
    """Why a spot is invalid or the hider was not found."""

    reason: _Text


class Found(msgspec.Struct, frozen=True):
    """The seeker's IR sensor confirmed the hider; where the seeker stands."""

    x: _Coord
    y: _Coord
    heading: _Coord = 0.0
    ir: int | None = None
    """Raw IR ADC reading that confirmed it (0..4095), when known."""


class ErrorInfo(msgspec.Struct, frozen=True):
    """Body of an ``error`` frame."""

    fault: str
    """A `Fault` code."""
    detail: str = ""
    cmd: str | None = None
    """``cmd`` of the offending frame, when it could be read."""
    seq: int | None = None
    """``seq`` of the offending frame, when it could be read."""


class MapChunk(msgspec.Struct, frozen=True):
    """One numbered piece of an encoded occupancy map (see `mapcodec`)."""

    map_id: Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
    index: Annotated[int, msgspec.Meta(ge=0)]
    count: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    nx: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    ny: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    resolution_cm: Annotated[float, msgspec.Meta(gt=0, le=1000)]
    origin_cm: tuple[_Coord, _Coord]
    crc: Annotated[int, msgspec.Meta(ge=0, le=2**32 - 1)]
    b64: Annotated[str, msgspec.Meta(max_length=1024)]


@dataclass(frozen=True, slots=True)
class Spec:
    """The catalogue entry of one ``cmd``."""

    cmd: str
    type: str
    payload: Any
    """msgspec type of ``data``; ``None`` means ``data`` is ignored (send null)."""
    sender: str
    """``rover``, ``server`` or ``both``."""
    reliable: bool


CATALOGUE: dict[str, Spec] = {s.cmd: s for s in (
    Spec(HELLO, "rover", Hello, "rover", False),
    Spec(WELCOME, "server", Welcome, "server", False),
    Spec(HEARTBEAT, "beat", None, "both", False),
    Spec(ACK, "ack", None, "both", False),
    Spec(ERROR, "fault", ErrorInfo, "both", False),
    Spec(START, "none", None, "server", True),
    Spec(STOP, "none", None, "server", True),
    Spec(ORIGIN, "pose", PoseData, "server", True),
    Spec(MAP_REQUEST, "none", None, "rover", True),
    Spec(MAP, "chunk", MapChunk, "both", True),
    Spec(POSE, "pose", PoseData, "rover", False),
    Spec(STATUS, "status", Status, "rover", False),
    Spec(DESTINATION, "pose", Destination, "server", True),
    Spec(ARRIVED, "pose", PoseData, "rover", True),
    Spec(INVALID_SPOT, "reason", Reason, "rover", True),
    Spec(FOUND, "pose", Found, "rover", True),
    Spec(NOT_FOUND, "reason", Reason, "rover", True),
    Spec("tm_mailboxes", "mailboxes", TmMailboxes, "rover", False),
    Spec("tm_tree", "tree", TmTree, "rover", False),
    Spec("tm_map", "map_delta", TmMap, "rover", False),
    Spec("tm_pose", "pose_spread", TmPose, "rover", False),
    Spec("tm_event", "event", TmEvent, "rover", False),
    Spec(FAULT, "inject", FaultCommand, "server", True),
    Spec(FAULT_REPLY, "fault_reply", FaultReply, "rover", True),
)}
"""cmd -> `Spec`, for every message of the protocol."""


def make_frame(cmd: str, data: Any = None) -> Frame:
    """A frame for ``cmd`` with the catalogue's ``type``; ``data`` may be a Struct.

    ``seq``/``ack`` are left out: the reliable session adds them.

    Raises:
        ValueError: ``cmd`` is unknown or ``data`` does not fit its schema.
    """
    spec = CATALOGUE.get(cmd)
    if spec is None:
        raise ValueError(f"cmd must be one of the catalogue, got {cmd!r}")
    if spec.payload is None:
        return Frame(cmd, spec.type, None)
    body = msgspec.to_builtins(data)
    try:
        msgspec.convert(body, spec.payload)
    except msgspec.ValidationError as exc:
        raise ValueError(f"data of {cmd!r} does not fit its schema: {exc}") from None
    return Frame(cmd, spec.type, body)


def read_data(frame: Frame) -> Any:
    """Check a received frame against the catalogue; return its typed payload.

    Returns ``None`` for messages without payload.

    Raises:
        FrameError: `UNKNOWN_CMD`, `BAD_TYPE` or `BAD_DATA`, naming the fault.
    """
    spec = CATALOGUE.get(frame.cmd)
    if spec is None:
        raise FrameError(Fault.UNKNOWN_CMD, f"unknown cmd {frame.cmd!r}")
    if frame.type != spec.type:
        raise FrameError(Fault.BAD_TYPE,
                         f"type of {frame.cmd!r} must be {spec.type!r}, got {frame.type!r}")
    if spec.payload is None:
        return None
    data = frame.data
    if spec.payload in (PoseData, Found) and isinstance(data, dict) and "heading" in data \
            and data["heading"] is None:
        data = {k: v for k, v in data.items() if k != "heading"}  # null means absent
    try:
        return msgspec.convert(data, spec.payload)
    except msgspec.ValidationError as exc:
        raise FrameError(Fault.BAD_DATA, f"data of {frame.cmd!r}: {exc}") from None
