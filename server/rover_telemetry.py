"""What an attached rover told the server about its insides: the newest of each stream.

The server keeps, per rover, the newest ``tm_mailboxes``, ``tm_tree`` and
``tm_pose`` (frames of one ``t`` joined: a list cut over several frames) with the
time each arrived (its age is what a console marks as
stale), the working map assembled from ``tm_map`` deltas, and the last
`MAX_EVENTS` ``tm_event`` entries. A stream the welcome did not ask for is
ignored. A ``tm_map`` with another header (the rover's map grew or moved)
starts a fresh map.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from .protocol import FREE, OCCUPIED, STREAM_CMDS, UNKNOWN, GridMap

__all__ = ["MAX_EVENTS", "MAX_MAP_CELLS", "RoverTelemetry", "TelemetryView"]

MAX_EVENTS = 200
"""Events kept per rover [events]."""
MAX_MAP_CELLS = 4_000_000
"""Largest working map the server assembles [cells] (a bigger header is ignored)."""
_MAX_ROWS = 256  # rows of one stream kept when frames of one t are joined
_STREAM_OF = {cmd: s for s, cmd in STREAM_CMDS.items()}
_CODE_TO_CELL = np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8)


@dataclass(frozen=True, slots=True)
class TelemetryView:
    """One rover's telemetry as a console draws it (records only)."""

    asked: tuple[str, ...]
    """Streams the server asked for in the welcome."""
    mailboxes: tuple[tuple[str, int, int, float, int], ...]
    tree: tuple[tuple[str, str, str, int, str | None], ...]
    pose: dict[str, float] | None
    events: tuple[dict[str, Any], ...]
    ages: dict[str, float]
    """Stream -> seconds since its newest frame arrived [s]."""
    map: GridMap | None
    frames: int
    """Telemetry frames taken so far."""
    ignored: int
    """Telemetry frames of streams not asked for (ignored)."""


class RoverTelemetry:
    """The newest telemetry of one rover (see the module docstring)."""

    def __init__(self, asked: tuple[str, ...] = ()) -> None:
        self.asked = asked
        self._latest: dict[str, tuple[float, Any]] = {}
        self._events: deque[dict[str, Any]] = deque(maxlen=MAX_EVENTS)
        self._map_header: tuple | None = None
        self._codes: np.ndarray | None = None
        self._map_at: float | None = None
        self.frames = 0
        self.ignored = 0

    def take(self, cmd: str, payload: Any, now: float) -> bool:
        """Keep one telemetry payload; False when its stream was not asked for."""
        stream = _STREAM_OF.get(cmd)
        if stream is None or stream not in self.asked:
            self.ignored += 1
            return False
        self.frames += 1
        if stream == "events":
            self._events.append({"t": payload.t, "kind": payload.kind, "path": payload.path,
                                 "detail": payload.detail, "at": now})
            self._latest[stream] = (now, None)
        elif stream == "map":
            self._take_map(payload, now)
        else:  # a list cut over frames of one t: joined
            held = self._latest.get(stream)
            if held is not None and held[1].t == payload.t:
                key = "boxes" if stream == "mailboxes" else "nodes"
                rows = (getattr(held[1], key) + getattr(payload, key))[:_MAX_ROWS]
                payload = msgspec.structs.replace(payload, **{key: rows})
            self._latest[stream] = (now, payload)
        return True

    def _take_map(self, m: Any, now: float) -> None:
        header = (m.nx, m.ny, m.resolution_cm, tuple(m.origin_cm))
        if m.nx * m.ny > MAX_MAP_CELLS:
            self.ignored += 1
            return
        if header != self._map_header or self._codes is None:
            self._map_header = header
            self._codes = np.zeros(m.nx * m.ny, dtype=np.int8)
        n = self._codes.size
        for index, code in m.cells:
            if index < n:
                self._codes[index] = code
        self._map_at = now
        self._latest["map"] = (now, None)

    def working_map(self) -> GridMap | None:
        """The working map as the deltas drew it, or None before the first."""
        if self._codes is None or self._map_header is None:
            return None
        nx, ny, res, origin = self._map_header
        cells = _CODE_TO_CELL[self._codes].reshape(ny, nx)
        return GridMap(cells, res, origin)

    def view(self, now: float) -> TelemetryView:
        """A snapshot with each stream's age."""
        def payload(stream: str) -> Any:
            got = self._latest.get(stream)
            return got[1] if got else None
        boxes = payload("mailboxes")
        tree = payload("tree")
        pose = payload("pose")
        return TelemetryView(
            self.asked,
            tuple(tuple(b) for b in boxes.boxes) if boxes else (),
            tuple(tuple(n) for n in tree.nodes) if tree else (),
            ({"x": pose.x, "y": pose.y, "heading": pose.heading, "sx": pose.sx, "sy": pose.sy,
              "sheading": pose.sheading} if pose else None),
            tuple(self._events),
            {s: now - at for s, (at, _) in self._latest.items()},
            self.working_map(), self.frames, self.ignored)
