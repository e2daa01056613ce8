"""The message layer between server and rovers: pure codec, no I/O, no clock.

Layering (lower modules never import higher ones)::

    frame      one JSON line <-> `Frame`, size limit, fault codes
    lines      byte stream -> lines, bounded
    catalogue  every cmd: type, payload schema, direction, reliability
    pose       THE pose type and angle algebra (room, map, rover frames)
    grid_map   THE map type (GridMap), its cell convention and its two classifications
    mapcodec   GridMap <-> numbered chunks, assembler
    telemetry  telemetry and fault-injection payloads, the telemetry lane (byte budget)
    session    reliable delivery: seq, cumulative ack, resend, liveness, stats

Imported by the server and by the rovers' firmware (the only server module the
firmware may import). The wire format is specified for firmware authors in
docs/protocol.md.
"""

from .catalogue import (
    ACK,
    ARRIVED,
    CATALOGUE,
    DESTINATION,
    ERROR,
    FAULT,
    FAULT_REPLY,
    FOUND,
    HEARTBEAT,
    HELLO,
    INVALID_SPOT,
    MAP,
    MAP_REQUEST,
    MAX_WITHIN_CM,
    NOT_FOUND,
    ORIGIN,
    POSE,
    ROLES,
    SESSION_ID_LIMIT,
    START,
    STATUS,
    STOP,
    WELCOME,
    Destination,
    ErrorInfo,
    Found,
    Hello,
    MapChunk,
    PoseData,
    Reason,
    Spec,
    Status,
    Welcome,
    make_frame,
    read_data,
)
from .frame import (
    MAX_LINE_BYTES,
    MAX_SEQ,
    Fault,
    Frame,
    FrameError,
    decode_line,
    encode_frame,
    error_frame,
)
from .grid_map import (
    FREE,
    FREE_MAX,
    OCCUPIED,
    OCCUPIED_MIN,
    OCCUPIED_SPLIT,
    UNKNOWN,
    GridMap,
    MapError,
)
from .lines import TOO_LONG, LineBuffer
from .mapcodec import CHUNK_B64_CHARS, MapAssembler, decode_runs, encode_runs, map_chunks
from .pose import ZERO_POSE, Pose, angle_diff_deg, compose, inverse, relative, wrap_deg
from .session import LinkStats, OutboxFull, ReliableSession, session_id_for
from .telemetry import (
    DEFAULT_INTERVALS,
    DEFAULT_LINK_BYTES_S,
    DEFAULT_SHARE,
    EVENT_KINDS,
    FAULT_RESULTS,
    STREAM_CMDS,
    STREAMS,
    TELEMETRY_CMDS,
    FaultCommand,
    FaultReply,
    LaneStats,
    TelemetryLane,
    TmEvent,
    TmMailboxes,
    TmMap,
    TmPose,
    TmTree,
    split_cells,
    split_rows,
)

__all__ = [
    "ACK", "ARRIVED", "CATALOGUE", "DESTINATION", "ERROR", "FOUND", "HEARTBEAT", "HELLO",
    "INVALID_SPOT", "MAP", "MAP_REQUEST", "NOT_FOUND", "ORIGIN", "POSE", "ROLES", "START",
    "STATUS", "STOP", "WELCOME", "MAX_WITHIN_CM", "Destination", "ErrorInfo", "Found", "Hello",
    "MapChunk", "PoseData", "Reason", "Spec", "Status", "Welcome", "make_frame", "read_data",
    "MAX_LINE_BYTES", "MAX_SEQ", "Fault", "Frame", "FrameError", "decode_line", "encode_frame",
    "error_frame", "TOO_LONG", "LineBuffer",
    "FREE", "FREE_MAX", "OCCUPIED", "OCCUPIED_MIN", "OCCUPIED_SPLIT", "UNKNOWN", "GridMap",
    "MapError", "CHUNK_B64_CHARS", "MapAssembler",
    "decode_runs", "encode_runs", "map_chunks",
    "Pose", "ZERO_POSE", "angle_diff_deg", "compose", "inverse", "relative", "wrap_deg",
    "LinkStats", "OutboxFull", "ReliableSession", "SESSION_ID_LIMIT", "session_id_for",
    "FAULT", "FAULT_REPLY",
    "DEFAULT_INTERVALS", "DEFAULT_LINK_BYTES_S", "DEFAULT_SHARE", "EVENT_KINDS", "FAULT_RESULTS",
    "STREAM_CMDS", "STREAMS", "TELEMETRY_CMDS", "FaultCommand", "FaultReply", "LaneStats",
    "TelemetryLane", "TmEvent", "TmMailboxes", "TmMap", "TmPose", "TmTree", "split_cells",
    "split_rows",
]
