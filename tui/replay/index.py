"""A recording indexed by time: what the console shows at any simulated instant.

`ReplayIndex` turns a `supervisors.recording.reading.Recording` into sorted
time series once (bisected per snapshot afterwards) and answers "what was
true at t": the phase, the map, each rover's poses and path, the latest LIDAR
scan, queue depths and rates, the supervision tree, the message log and the
timeline. Nothing is simulated: every answer is read from the file. A
recording started mid-game begins with the game's state (``/game/state``:
phase, hide spot, guesses, faults in force); answers start from it.

Frames: the recording's Foxglove messages are in metres in the map frame;
everything here is converted back to the console's [cm].
"""

from __future__ import annotations

import base64
import bisect
import math
import re
from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np

from actors.firmware.payloads import named_text
from supervisors.recording.reading import Recording
from tui.snapshot import (
    MAX_LOG_LINES,
    MAX_TIMELINE,
    ActiveFault,
    GridView,
    LinkStats,
    LogLine,
    Pose,
    QueueStats,
    RoverView,
    TimelineEvent,
    TreeNode,
)

__all__ = ["ReplayIndex", "EVENT_KINDS"]

ROLES = ("mapper", "hider", "seeker")
#: timeline kinds a person can seek to (`ReplayIndex.next_event`)
EVENT_KINDS = ("phase", "fault", "crash", "restart", "link", "game")
_RUNTIME_KIND = {"crash": "crash", "hung": "crash", "escalate": "crash", "killed": "crash",
                 "poison": "crash", "restart": "restart", "fault": "fault"}
_FOR_S = re.compile(r" for ([0-9.]+) s$")
_KV = re.compile(r"(\w+)=(\S+)")


def _times(series: list[tuple[float, Any]]) -> list[float]:
    return [t for t, _ in series]


def _at(times: list[float], series: list, t: float) -> Any | None:
    """The last item of ``series`` at or before ``t`` (None before the first)."""
    i = bisect.bisect_right(times, t) - 1
    return series[i][1] if i >= 0 else None


def _pose(msg: dict[str, Any] | None) -> Pose | None:
    if msg is None:
        return None
    p = msg["pose"]
    q = p["orientation"]
    heading = math.degrees(2.0 * math.atan2(q.get("z", 0.0), q.get("w", 1.0)))
    return Pose(p["position"]["x"] * 100.0, p["position"]["y"] * 100.0, heading)


def grid_view(grid: dict[str, Any]) -> GridView:
    """A `GridView` from a ``foxglove.Grid`` message (int8 cells, row-major)."""
    cells = np.frombuffer(base64.b64decode(grid["data"]), np.int8).reshape(
        -1, int(grid["column_count"])).copy()
    pos = grid["pose"]["position"]
    return GridView(cells, grid["cell_size"]["x"] * 100.0, (pos["x"] * 100.0, pos["y"] * 100.0))


@dataclass(frozen=True, slots=True)
class _Row:
    t: float
    queue: str
    text: str
    depth: int


class ReplayIndex:
    """Time series of one recording (see the module docstring).

    Args:
        rec: a recording read whole (`read_recording` with every topic).
        map_from_room: a function taking a room-frame pose (x, y [cm], heading [deg])
            to the map frame, for the hide spot and guesses (the headless operator gives
            them in the room frame); None: shown as given.
    """

    def __init__(self, rec: Recording, map_from_room: Any = None) -> None:
        self.rec = rec
        self.start_s = rec.start_s
        self.end_s = rec.end_s
        self._to_map = map_from_room or (lambda x, y, h: (x, y, h))
        # at one instant the working map wins, as in the console (`tui.sim_views.map_view`)
        self._grids = rec.topic("/map/uploaded") + rec.topic("/map/working")
        self._grids.sort(key=lambda item: item[0])
        self._grid_t = _times(self._grids)
        self._grid_cache: dict[int, GridView] = {}
        self._series = {topic: rec.topic(topic) for topic in rec.messages}
        self._series_t = {topic: _times(s) for topic, s in self._series.items()}
        self._rows: list[_Row] = []
        for _, batch in rec.topic("/actors/messages"):
            for m in batch["messages"]:
                self._rows.append(_Row(m["t"], m["queue"],
                                       named_text(m["command"], m["type"], m["value"]),
                                       int(m["depth"])))
        self._row_t = [r.t for r in self._rows]
        self._by_queue: dict[str, list[tuple[float, int]]] = defaultdict(list)
        for r in self._rows:
            self._by_queue[r.queue].append((r.t, r.depth))
        self._queue_t = {q: _times(s) for q, s in self._by_queue.items()}
        self._drops: dict[str, list[float]] = defaultdict(list)
        for t, d in rec.topic("/actors/drops"):
            self._drops[d["queue"]].append(t)
        # when the recording began and the game's state then (`records.game_state`): what
        # a recording started mid-game replays from (none in older recordings)
        states = rec.topic("/game/state")
        self._state_t, self._state = states[0] if states else (-math.inf, {})
        self._timeline = self._build_timeline()
        self._timeline_t = [e.time_s for e in self._timeline]
        self._runtime = [(t, log) for t, log in rec.topic("/actors/events")]
        self._runtime_t = _times(self._runtime)

    # ---------------------------------------------------------------- timeline
    def _build_timeline(self) -> list[TimelineEvent]:
        items: list[tuple[float, str, str]] = []
        if self._state.get("phase", "idle") != "idle":
            items.append((self._state_t, "phase", f"{self._state['phase']} (when the "
                                                  "recording began)"))
        for t, log in self.rec.topic("/game/events"):
            name, text = log["name"], log["message"]
            text = text.removesuffix(" reason=")
            if name == "phase":
                items.append((t, "phase", text.replace("=", " ", 1)))
            elif name in ("link_up", "link_down"):
                items.append((t, "link", f"{text.split()[0] if text else ''} "
                                         f"{name.replace('_', ' ')}"))
            elif name in ("report", "refused", "map", "command"):
                items.append((t, "game", f"{name} {text}"))
        for t, log in self.rec.topic("/faults"):
            items.append((t, "fault", f"{log['message']} ({log['name']})"))
        for t, log in self.rec.topic("/actors/events"):
            kind = _RUNTIME_KIND.get(log["name"])
            if kind is not None:
                items.append((t, kind, f"{log['name']} {log['message']}"))
        items.sort(key=lambda item: item[0])
        return [TimelineEvent(i + 1, t, kind, text) for i, (t, kind, text) in enumerate(items)]

    def timeline(self, t: float) -> tuple[TimelineEvent, ...]:
        """The newest `MAX_TIMELINE` events at or before ``t``."""
        i = bisect.bisect_right(self._timeline_t, t)
        return tuple(self._timeline[max(0, i - MAX_TIMELINE):i])

    def next_event(self, t: float, kind: str | None = None) -> float | None:
        """Time of the first event after ``t`` (of ``kind``, when given); None when none."""
        for e in self._timeline[bisect.bisect_right(self._timeline_t, t + 1e-9):]:
            if kind is None or e.kind == kind:
                return e.time_s
        return None

    # ---------------------------------------------------------------- state at t
    def last(self, topic: str, t: float) -> Any | None:
        """The last message of ``topic`` at or before ``t``."""
        series = self._series.get(topic)
        return None if not series else _at(self._series_t[topic], series, t)

    def phase(self, t: float) -> str:
        """The game phase at ``t``."""
        phase = self._state.get("phase", "idle") if t >= self._state_t else "idle"
        for _, log in self._series.get("/game/events", [])[
                :bisect.bisect_right(self._series_t.get("/game/events", []), t)]:
            if log["name"] == "phase":
                phase = log["message"].split("=", 1)[1].split()[0]
        return phase

    def map(self, t: float) -> GridView | None:
        """The newest map at ``t`` (working or uploaded), decoded once."""
        i = bisect.bisect_right(self._grid_t, t) - 1
        if i < 0:
            return None
        if i not in self._grid_cache:
            if len(self._grid_cache) > 64:
                self._grid_cache.clear()
            self._grid_cache[i] = grid_view(self._grids[i][1])
        return self._grid_cache[i]

    def rovers(self, t: float) -> tuple[RoverView, ...]:
        """Each rover's believed and true pose and planned path at ``t``."""
        out = []
        for role in ROLES:
            path = self.last(f"/{role}/path", t)
            points = tuple((p["position"]["x"] * 100.0, p["position"]["y"] * 100.0)
                           for p in (path or {}).get("poses", []))
            out.append(RoverView(role, role, _pose(self.last(f"/{role}/pose/believed", t)),
                                 _pose(self.last(f"/{role}/pose/true", t)), points[1:],
                                 points[-1] if points else None, link="recording"))
        return tuple(out)

    def track(self, role: str, which: str = "true") -> list[tuple[float, Pose]]:
        """Every recorded pose of a rover, oldest first, as (t [s], pose) in the map frame
        [cm, deg]; ``which`` is ``true`` (the world's) or ``believed`` (the rover's)."""
        return [(t, _pose(msg)) for t, msg in self._series.get(f"/{role}/pose/{which}", [])]

    def lidar_points(self, t: float) -> np.ndarray:
        """The newest LIDAR revolution at ``t`` as map-frame points [cm] (returns only)."""
        scan = self.last("/mapper/scan", t)
        if scan is None:
            return np.zeros((0, 2))
        ranges = np.asarray(scan["ranges"], float) * 100.0
        n = len(ranges)
        pose = _pose(scan)
        assert pose is not None
        angles = math.radians(pose.heading_deg) + np.linspace(
            scan["start_angle"], scan["end_angle"], n) if n else np.zeros(0)
        hit = ranges > 0
        return np.column_stack((pose.x_cm + ranges[hit] * np.cos(angles[hit]),
                                pose.y_cm + ranges[hit] * np.sin(angles[hit])))

    def commands(self, t: float) -> tuple[Pose | None, tuple[tuple[float, float], ...]]:
        """The hide spot and the seek guesses sent by ``t`` (map frame)."""
        hide, guesses = None, []
        if t >= self._state_t:  # sent before the recording began
            spot = self._state.get("hide_spot")
            hide = None if spot is None else Pose(spot["x"], spot["y"], spot["heading"])
            guesses = [(g["x"], g["y"]) for g in self._state.get("guesses", [])]
        for _, log in self._series.get("/game/events", [])[
                :bisect.bisect_right(self._series_t.get("/game/events", []), t)]:
            if log["name"] != "command":
                continue
            kv = dict(_KV.findall(log["message"]))
            if kv.get("command") not in ("hide", "seek") or "x" not in kv:
                continue
            x, y, h = float(kv["x"]), float(kv["y"]), float(kv.get("heading", 0.0))
            if kv.get("frame") == "room":
                x, y, h = self._to_map(x, y, h)
            if kv["command"] == "hide":
                hide = Pose(x, y, h)
            else:
                guesses.append((x, y))
        return hide, tuple(guesses)

    def queues(self, t: float) -> tuple[QueueStats, ...]:
        """Every mailbox's depth, rate over the last second and drops at ``t``."""
        out = []
        names = sorted(set(self.rec.queues) | set(self._by_queue),
                       key=lambda n: (ROLES.index(n.split("/")[0])
                                      if n.split("/")[0] in ROLES else 9, n))
        for name in names:
            times = self._queue_t.get(name, [])
            i = bisect.bisect_right(times, t)
            depth = self._by_queue[name][i - 1][1] if i else 0
            rate = float(i - bisect.bisect_right(times, t - 1.0))
            drops = bisect.bisect_right(self._drops.get(name, []), t)
            out.append(QueueStats(name.split("/")[0], name, depth,
                                  self.rec.queues.get(name, 0), rate, drops))
        return tuple(out)

    def log(self, t: float) -> tuple[LogLine, ...]:
        """The newest `MAX_LOG_LINES` messages at or before ``t`` (seq: position in the run)."""
        i = bisect.bisect_right(self._row_t, t)
        return tuple(LogLine(j + 1, r.t, r.queue, r.queue, r.text)
                     for j, r in enumerate(self._rows[max(0, i - MAX_LOG_LINES):i],
                                           start=max(0, i - MAX_LOG_LINES)))

    def tree(self, t: float) -> TreeNode:
        """The supervision tree as the runtime's events tell it at ``t``: each rover's
        actors (its mailboxes), restarts counted, the last exit shown."""
        restarts: dict[str, int] = defaultdict(int)
        exits: dict[str, tuple[str, float]] = {}
        for te, log in self._runtime[:bisect.bisect_right(self._runtime_t, t)]:
            actor = log["message"].split(" ", 1)[0]
            if log["name"] == "restart":
                restarts[actor] += 1
            elif log["name"] in ("crash", "hung", "killed", "escalate"):
                exits[actor] = (f"{log['name']}: {log['message'][len(actor):].strip()}"[:60],
                                te)
        roots = []
        for role in ROLES:
            workers = tuple(
                TreeNode(name, "worker", "running", restarts[name],
                         exits.get(name, (None, None))[0], exits.get(name, (None, None))[1])
                for name, _ in ((q.name, q) for q in self.queues(t)) if name.startswith(role + "/"))
            roots.append(TreeNode(role, "supervisor", "running", restarts[role], None, None,
                                  workers))
        return TreeNode("system", "supervisor", "running", 0, None, None, tuple(roots))

    def links(self, t: float) -> tuple[LinkStats, ...]:
        """Frames each way on each rover's link by ``t``, and whether it was up."""
        out = []
        downs = {log["message"].split()[0] for _, log in self._series.get("/game/events", [])[
            :bisect.bisect_right(self._series_t.get("/game/events", []), t)]
            if log["name"] == "link_down" and log["message"]}
        for role in ROLES:
            topic = f"/{role}/link"
            i = bisect.bisect_right(self._series_t.get(topic, []), t)
            frames = self._series.get(topic, [])[:i]
            up = sum(m["direction"] == "up" for _, m in frames)
            out.append(LinkStats(role, role not in downs, None, frames_in=up,
                                 frames_out=len(frames) - up))
        return tuple(out)

    def faults(self, t: float) -> tuple[ActiveFault, ...]:
        """Faults in force at ``t`` (one with no duration: until the end)."""
        return tuple(f for f in self.all_faults() if f.started_s <= t and (
            f.until_s is None or t < f.until_s))

    def all_faults(self) -> tuple[ActiveFault, ...]:
        """Every fault the recording injects, in the order they began."""
        out = []
        for f in self._state.get("faults", []):  # in force when the recording began
            until = f["start_s"] + f["duration_s"] if f["duration_s"] > 0 else None
            out.append(ActiveFault(f["id"], f["target"], f["kind"], f["start_s"], until))
        for start, log in self._series.get("/faults", []):
            text = log["message"]
            m = _FOR_S.search(text)
            until = start + float(m.group(1)) if m else None
            kind, _, target = text.split(" for ")[0].partition(" on ")
            out.append(ActiveFault(log["name"], target, kind, start, until))
        return tuple(out)
