"""Telemetry and fault injection on the wire: payload schemas and the telemetry lane.

Telemetry (MAVLink's message intervals are the model): the server names in
``welcome.telemetry`` the streams it wants and an interval per stream [s];
a rover sends only those, as unreliable frames (never a ``seq``, never
resent, the newest wins), within ``welcome.telemetry_share`` of its link's
bytes, and never ahead of a game frame. A rover that sends none still plays.

==============  ============  =============================================
cmd             type          data
==============  ============  =============================================
tm_mailboxes    mailboxes     `TmMailboxes`: name, depth, capacity, msgs/s, drops
tm_tree         tree          `TmTree`: path, kind, state, restarts, last exit
tm_map          map_delta     `TmMap`: changed cells of the working map
tm_pose         pose_spread   `TmPose`: believed pose and 95 % half-widths
tm_event        event         `TmEvent`: crash, restart, fault injected ...
fault           inject        `FaultCommand` (server -> rover, reliable)
fault_reply     fault_reply   `FaultReply` (rover -> server, reliable)
==============  ============  =============================================

Fault injection (PX4's ``MAV_CMD_INJECT_FAILURE`` is the model): every
``fault`` gets exactly one ``fault_reply``: ``accepted``, ``unsupported``
(the rover does not know that target/kind) or ``refused`` (it knows it but was
not started with the opt-in).

`TelemetryLane` is the sender's side of the rules, sans-IO: frames offered per
stream (newest wins), taken only within a token-bucket byte budget.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import msgspec

from .frame import MAX_LINE_BYTES, Frame, encode_frame

__all__ = [
    "STREAMS", "STREAM_CMDS", "TELEMETRY_CMDS", "EVENT_KINDS", "FAULT_RESULTS",
    "DEFAULT_SHARE", "DEFAULT_LINK_BYTES_S", "DEFAULT_INTERVALS",
    "TmMailboxes", "TmTree", "TmMap", "TmPose", "TmEvent", "FaultCommand", "FaultReply",
    "TelemetryLane", "LaneStats", "split_cells", "split_rows",
]

STREAMS = ("mailboxes", "tree", "map", "pose", "events")
"""Telemetry streams a rover may offer in ``hello.streams``."""
STREAM_CMDS = {"mailboxes": "tm_mailboxes", "tree": "tm_tree", "map": "tm_map",
               "pose": "tm_pose", "events": "tm_event"}
"""Stream -> the ``cmd`` of its frames."""
TELEMETRY_CMDS = frozenset(STREAM_CMDS.values())
"""Every telemetry ``cmd``: unreliable, never with ``seq``."""
EVENT_KINDS = ("crash", "restart", "give_up", "fault_injected", "fault_cleared",
               "fault_refused")
FAULT_RESULTS = ("accepted", "unsupported", "refused")
DEFAULT_SHARE = 0.25
"""Largest share of the link's bytes telemetry uses unless the welcome says otherwise."""
DEFAULT_LINK_BYTES_S = 5760.0
"""Link rate assumed when a rover does not know its own [bytes/s]: 57600 baud, 8N1."""
DEFAULT_INTERVALS = {"mailboxes": 1.0, "tree": 2.0, "map": 1.0, "pose": 0.5, "events": 0.0}
"""Interval per stream the server asks for by default [s] (0 = as they happen)."""

_T = Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]
_Count = Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
_Coord = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]
_Spread = Annotated[float, msgspec.Meta(ge=0, le=1e6)]
_Name = Annotated[str, msgspec.Meta(min_length=1, max_length=32)]
_Path = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
_Text = Annotated[str, msgspec.Meta(max_length=200)]
_MAX_ROWS = 64       # mailboxes or tree nodes in one frame
_MAX_CELLS = 256     # map cells in one frame


class TmMailboxes(msgspec.Struct, frozen=True):
    """``tm_mailboxes``: each mailbox as ``[name, depth, capacity, msgs_per_s, drops]``."""

    t: _T
    boxes: Annotated[list[tuple[_Name, _Count, _Count, Annotated[float, msgspec.Meta(
        ge=0, le=1e9)], _Count]], msgspec.Meta(max_length=_MAX_ROWS)]


class TmTree(msgspec.Struct, frozen=True):
    """``tm_tree``: each node as ``[path, kind, state, restarts, last_exit]``."""

    t: _T
    nodes: Annotated[list[tuple[_Path, Literal["supervisor", "worker"],
                                Literal["running", "restarting", "stopped"], _Count,
                                Annotated[str, msgspec.Meta(max_length=80)] | None]],
                     msgspec.Meta(max_length=_MAX_ROWS)]


class TmMap(msgspec.Struct, frozen=True):
    """``tm_map``: cells of the working map as ``[row-major index, code]`` (0 unknown,
    1 free, 2 occupied), with the map's header; a delta, spread over several frames."""

    t: _T
    nx: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    ny: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    resolution_cm: Annotated[float, msgspec.Meta(gt=0, le=1000)]
    origin_cm: tuple[_Coord, _Coord]
    cells: Annotated[list[tuple[_Count, Annotated[int, msgspec.Meta(ge=0, le=2)]]],
                     msgspec.Meta(max_length=_MAX_CELLS)]


class TmPose(msgspec.Struct, frozen=True):
    """``tm_pose``: the believed pose (map frame) and its 95 % half-widths [cm, deg]."""

    t: _T
    x: _Coord
    y: _Coord
    heading: _Coord
    sx: _Spread
    sy: _Spread
    sheading: _Spread


class TmEvent(msgspec.Struct, frozen=True):
    """``tm_event``: something that happened inside the rover."""

    t: _T
    kind: Literal["crash", "restart", "give_up", "fault_injected", "fault_cleared",
                  "fault_refused"]
    path: _Path
    detail: _Text = ""


class FaultCommand(msgspec.Struct, frozen=True):
    """``fault``: inject a fault into the rover, or clear one (kind ``*``: all on target)."""

    fault_id: Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
    op: Literal["inject", "clear"]
    target: _Name
    """Rover-local device or actor: ``lidar``, ``motor``, ``nav``, ``wifly`` ..."""
    kind: _Name
    duration: Annotated[float, msgspec.Meta(ge=0, le=86400)] | None = None
    """[s]; absent or 0 = until cleared."""
    params: Annotated[dict[_Name, Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]],
                      msgspec.Meta(max_length=8)] | None = None


class FaultReply(msgspec.Struct, frozen=True):
    """``fault_reply``: the rover's answer to one ``fault``."""

    fault_id: Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
    result: Literal["accepted", "unsupported", "refused"]
    detail: _Text | None = None


def split_rows(cmd: str, type_: str, key: str, rows: list[Any], t: float,
               limit: int = MAX_LINE_BYTES) -> list[Frame]:
    """Frames of ``cmd`` carrying ``{"t": t, key: rows}``, the rows cut over as many frames
    as keep each line within ``limit`` bytes (every frame has the same ``t``: the receiver
    joins them)."""
    out: list[Frame] = []
    batch: list[Any] = []
    for row in rows:
        trial = Frame(cmd, type_, {"t": t, key: [*batch, row]})
        if batch and (len(encode_frame(trial)) > limit or len(batch) >= _MAX_ROWS):
            out.append(Frame(cmd, type_, {"t": t, key: batch}))
            batch = []
        batch.append(row)
    out.append(Frame(cmd, type_, {"t": t, key: batch}))
    return out


def split_cells(cells: list[tuple[int, int]], header: dict, t: float,
                limit: int = MAX_LINE_BYTES) -> list[Frame]:
    """``tm_map`` frames carrying ``cells``, each line within ``limit`` bytes (at most
    `MAX_LINE_BYTES`)."""
    out: list[Frame] = []
    room = max(min(limit, MAX_LINE_BYTES) - 240, 40)  # the envelope and header fit in 240
    batch: list[list[int]] = []
    used = 0
    for index, code in cells:
        size = len(str(index)) + 5  # "[index,c],"
        if batch and (used + size > room or len(batch) >= _MAX_CELLS):
            out.append(Frame("tm_map", "map_delta", {"t": t, **header, "cells": batch}))
            batch, used = [], 0
        batch.append([index, code])
        used += size
    if batch:
        out.append(Frame("tm_map", "map_delta", {"t": t, **header, "cells": batch}))
    return out


@dataclass(frozen=True, slots=True)
class LaneStats:
    """Counters of a `TelemetryLane`."""

    frames: int
    """Telemetry frames sent."""
    bytes: int
    """Telemetry bytes sent."""
    replaced: int
    """Frames dropped unsent because a newer one of the stream came (newest wins)."""
    dropped: int
    """Frames dropped because the stream's queue was full."""
    queued: int


class TelemetryLane:
    """The sender's telemetry: what the peer asked for, newest wins, within a byte budget.

    Streams ``events`` and ``map`` queue their frames (bounded: the oldest is
    dropped beyond ``queue_limit``); every other stream keeps only its newest
    frame. `take` hands out frames while the token bucket holds their bytes: it
    fills at ``share * link_bytes_s`` and holds at most one full line, so over
    any stretch of time telemetry uses at most that share of the link (plus one burst).

    The bucket holds at most ``max_frame`` bytes, so telemetry never puts more than
    that on the line at once: a game frame written next waits at most that long
    (at 57600 baud, 288 bytes: 50 ms). Producers cut their frames to ``max_frame``
    (`split_rows`, `split_cells`); a longer frame still leaves when the bucket is
    full, and the bucket goes into debt for it (the share holds on average).

    Args:
        link_bytes_s: the link's rate [bytes/s].
        queue_limit: frames kept per queued stream at most.
        max_frame: the burst [bytes]; by default 50 ms of the link, within 200..1024.
    """

    def __init__(self, link_bytes_s: float = DEFAULT_LINK_BYTES_S, *,
                 queue_limit: int = 64, max_frame: int | None = None) -> None:
        if not link_bytes_s > 0:
            raise ValueError(f"link_bytes_s must be > 0, got {link_bytes_s!r}")
        self.link_bytes_s = float(link_bytes_s)
        self.queue_limit = queue_limit
        self.max_frame = max_frame or int(min(MAX_LINE_BYTES, max(200.0, link_bytes_s * 0.05)))
        """The most bytes telemetry puts on the line at once (the bucket's size)."""
        self.intervals: dict[str, float] = {}
        """Stream -> interval [s] the peer asked for; empty = send nothing."""
        self.share = DEFAULT_SHARE
        self._queues: dict[str, deque[tuple[Frame, bytes]]] = {}
        self._last_offer: dict[str, float] = {}
        self._tokens = float(self.max_frame)
        self._filled_at: float | None = None
        self._c = dict(frames=0, bytes=0, replaced=0, dropped=0)

    def configure(self, intervals: dict[str, float] | None, share: float | None = None) -> None:
        """What the peer asked for (the welcome); ``{}`` stops everything (link down)."""
        self.intervals = {s: float(v) for s, v in (intervals or {}).items() if s in STREAMS}
        self.share = DEFAULT_SHARE if share is None else min(max(float(share), 1e-6), 1.0)
        for s in list(self._queues):
            if s not in self.intervals:
                del self._queues[s]
        self._last_offer.clear()

    @property
    def rate(self) -> float:
        """Bytes per second the budget allows [bytes/s]."""
        return self.share * self.link_bytes_s

    def wanted(self, stream: str, now: float) -> bool:
        """True when ``stream`` is asked for and its interval has passed since its last offer."""
        interval = self.intervals.get(stream)
        if interval is None:
            return False
        last = self._last_offer.get(stream)
        return last is None or now - last >= interval

    def offer(self, stream: str, frames: list[Frame], now: float) -> None:
        """Queue a stream's newest frames (ignored when the peer did not ask for it)."""
        if stream not in self.intervals:
            return
        self._last_offer[stream] = now
        q = self._queues.setdefault(stream, deque())
        if stream not in ("events", "map") and q:
            self._c["replaced"] += len(q)
            q.clear()
        for f in frames:
            if len(q) >= self.queue_limit:
                q.popleft()
                self._c["dropped"] += 1
            q.append((f, encode_frame(f)))

    def has_queued(self) -> bool:
        return any(self._queues.values())

    def _fill(self, now: float) -> None:
        if self._filled_at is not None:
            self._tokens = min(float(self.max_frame),
                               self._tokens + (now - self._filled_at) * self.rate)
        self._filled_at = now

    def next_time(self, now: float) -> float:
        """When the first queued frame fits the budget [s] (``inf`` with nothing queued)."""
        heads = [q[0][1] for q in self._queues.values() if q]
        if not heads:
            return float("inf")
        self._fill(now)
        need = min(min(len(b), self.max_frame) for b in heads) - self._tokens
        return now if need <= 0 else now + need / self.rate

    def take(self, now: float) -> bytes:
        """The bytes of the queued frames the budget allows now, streams in turn."""
        self._fill(now)
        out: list[bytes] = []
        progress = True
        while progress:
            progress = False
            for q in self._queues.values():
                if q and min(len(q[0][1]), self.max_frame) <= self._tokens:
                    _, line = q.popleft()
                    self._tokens -= len(line)
                    out.append(line)
                    self._c["frames"] += 1
                    self._c["bytes"] += len(line)
                    progress = True
        return b"".join(out)

    def stats(self) -> LaneStats:
        return LaneStats(queued=sum(len(q) for q in self._queues.values()), **self._c)
