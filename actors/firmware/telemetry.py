"""The rover's telemetry task: what it streams about its insides (``hideseek rover``).

A low-priority task of the rover's firmware, beside its tree (not an actor:
it takes no messages). It reads the rover's actor system the way a debugger
reads RAM (mailbox counters, the supervision tree, Map Management's working
grid, navigation's pose belief), changing nothing, and offers frames to the
WiFly's `TelemetryLane` for the streams the server asked for, at the
intervals it asked for. The lane keeps the newest per
stream and lets them out within its byte budget, after game frames.

* ``mailboxes``: each of the rover's mailboxes: depth, capacity, messages/s
  since the last report, drops so far;
* ``tree``: every node of the rover's supervision tree;
* ``map`` (mapper): the cells that changed since they were last offered, plus a
  slice of the known cells in turn (a lost frame heals within a few rounds);
* ``pose``: navigation's believed pose (map frame) and its 95 % half-widths;
* ``events``: crashes, restarts, a supervisor giving up, faults injected,
  cleared or refused, as they happen (`TelemetrySource.event`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import trio

from actors import ActorSystem, EventKind, Message, TraceEvent
from actors.firmware.commands import Cmd
from server.protocol import Frame, TelemetryLane, compose, split_cells, split_rows

__all__ = ["TelemetrySource", "STREAMS_OF_ROLE"]

STREAMS_OF_ROLE = {"mapper": ("mailboxes", "tree", "map", "pose", "events"),
                   "hider": ("mailboxes", "tree", "pose", "events"),
                   "seeker": ("mailboxes", "tree", "pose", "events")}
"""The streams a rover of each role offers in hello."""
_POLL_S = 0.1                 # how often the task looks at the lane [s]
_MAP_FRAMES_PER_ROUND = 3     # tm_map frames offered per map interval at most
_CELLS_PER_FRAME = 120      # map cells per tm_map frame (fits one 1024-byte line)
_TRACE_EVENTS = {EventKind.CRASH: "crash", EventKind.HUNG: "crash",
                 EventKind.RESTART: "restart", EventKind.ESCALATE: "give_up"}


class TelemetrySource:
    """Offers one rover's telemetry to its WiFly's lane (see the module docstring).

    Args:
        actors: the rover's actor system.
        tree: the rover's root supervisor.
        role: the rover's role (its actors are registered under it).
        lane: the WiFly's telemetry lane.
    """

    def __init__(self, actors: ActorSystem, tree: Any, role: str, lane: TelemetryLane) -> None:
        self.actors, self.tree, self.role, self.lane = actors, tree, role, lane
        self._prefix = f"{role}/"
        self._sent_counts: dict[str, tuple[float, int]] = {}
        self._map_sent: np.ndarray | None = None
        self._map_header: tuple | None = None
        self._refresh_at = 0
        self._wifly = f"{role}/wifly"

    # ---------------------------------------------------------------- the task
    async def run(self) -> None:
        """Offer what is due every `_POLL_S` until cancelled; trace events as they come."""
        sub = self.actors.trace.subscribe(self._on_trace, receives=False)
        try:
            while True:
                self.tick(trio.current_time())
                await trio.sleep(_POLL_S)
        finally:
            sub.close()

    def tick(self, now: float) -> None:
        """Offer each stream whose interval has passed (events go as they happen)."""
        lane = self.lane
        offered = False
        for stream, make in (("mailboxes", self._mailboxes), ("tree", self._tree),
                             ("pose", self._pose), ("map", self._map)):
            if lane.wanted(stream, now):
                frames = make(now)
                if frames:
                    lane.offer(stream, frames, now)
                    offered = True
        if offered:
            self._wake()

    def event(self, kind: str, path: str, detail: str) -> None:
        """Offer one runtime event now (``crash``, ``restart``, ``fault_injected`` ...)."""
        now = trio.current_time()
        self.lane.offer("events", [Frame("tm_event", "event", {
            "t": round(now, 3), "kind": kind, "path": path[:64], "detail": detail[:200]})], now)
        self._wake()

    def _wake(self) -> None:
        self.actors.send_nowait(self._wifly, Message.uint(Cmd.WIFLY_TIMER, 0))

    def _on_trace(self, ev: TraceEvent) -> None:
        kind = _TRACE_EVENTS.get(ev.kind)
        if kind is not None and ev.actor.startswith(self._prefix[:-1]) \
                and "events" in self.lane.intervals:
            self.event(kind, ev.actor, ev.detail)

    # ---------------------------------------------------------------- streams
    def _names(self) -> list[str]:
        return [n for n in self.actors.names() if n.startswith(self._prefix)]

    def _mailboxes(self, now: float) -> list[Frame]:
        boxes = []
        for name in self._names():
            s = self.actors.statistics(name)
            last_t, last_sent = self._sent_counts.get(name, (now, s.sent))
            rate = (s.sent - last_sent) / (now - last_t) if now > last_t else 0.0
            self._sent_counts[name] = (now, s.sent)
            boxes.append([name[len(self._prefix):][:32], s.depth, s.capacity,
                          round(max(rate, 0.0), 1), s.dropped])
        return split_rows("tm_mailboxes", "mailboxes", "boxes", boxes, round(now, 3),
                          self.lane.max_frame)

    def _tree(self, now: float) -> list[Frame]:
        nodes: list[list[Any]] = []

        def walk(node: Any) -> None:  # a node's name is its registered path
            nodes.append([node.name[:64], str(node.kind), _state(node.state), node.restarts,
                          str(node.last_exit)[:80] if node.last_exit is not None else None])
            for child in node.children:
                walk(child)
        walk(self.tree.snapshot())
        return split_rows("tm_tree", "tree", "nodes", nodes, round(now, 3), self.lane.max_frame)

    def _nav(self) -> Any:
        cell = self.actors.whereis(f"{self.role}/nav")
        return cell.actor if cell is not None else None

    def _pose(self, now: float) -> list[Frame]:
        """The mapper's pose belief is Map Management's (a Gaussian in the map frame);
        the hider's and seeker's is navigation's particle belief (own frame, moved to
        the map frame by the origin)."""
        nav = self._nav()
        if nav is None or not hasattr(nav, "map_pose"):
            return []
        pose, cov, sh = nav.map_pose, np.zeros((3, 3)), 0.0
        cell = self.actors.whereis(f"{self.role}/map")
        gaussian = getattr(cell.actor if cell is not None else None, "belief", None)
        particles = getattr(nav, "belief", None)
        if gaussian is not None:
            pose, cov, sh = gaussian.mean, np.asarray(gaussian.covariance), \
                float(gaussian.heading95_deg)
        elif particles is not None:
            spread = particles.spread()  # a fresh read: nothing of navigation's is touched
            th = math.radians(nav.origin.heading_deg) if nav.origin is not None else 0.0
            rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
            cov = np.zeros((3, 3))
            cov[:2, :2] = rot @ np.asarray(spread.covariance)[:2, :2] @ rot.T
            sh = float(spread.heading95_deg)
            pose = compose(nav.origin, spread.pose) if nav.origin is not None else spread.pose
        sx, sy = (1.96 * math.sqrt(max(float(cov[i, i]), 0.0)) for i in (0, 1))
        return [Frame("tm_pose", "pose_spread", {
            "t": round(now, 3), "x": round(pose.x, 1), "y": round(pose.y, 1),
            "heading": round(pose.heading_deg, 1), "sx": round(sx, 1), "sy": round(sy, 1),
            "sheading": round(sh, 1)})]

    def _map(self, now: float) -> list[Frame]:
        cell = self.actors.whereis(f"{self.role}/map")
        grid = getattr(cell.actor if cell is not None else None, "grid", None)
        if grid is None:
            return []
        snap = grid.snapshot()
        codes = snap.codes().ravel()
        ny, nx = snap.cells.shape
        header = {"nx": nx, "ny": ny, "resolution_cm": float(snap.resolution_cm),
                  "origin_cm": [float(v) for v in snap.origin_cm]}
        key = (nx, ny, header["resolution_cm"], tuple(header["origin_cm"]))
        if key != self._map_header or self._map_sent is None:
            self._map_header = key
            self._map_sent = np.zeros(codes.size, dtype=np.uint8)
            self._refresh_at = 0
        budget = _MAP_FRAMES_PER_ROUND * _CELLS_PER_FRAME
        changed = np.flatnonzero(codes != self._map_sent)[:budget]
        picked = list(changed)
        room = budget - len(picked)
        if room > _CELLS_PER_FRAME // 2:  # a slice of the known cells again, in turn
            known = np.flatnonzero(codes)
            if known.size:
                start = np.searchsorted(known, self._refresh_at)
                again = known[start:start + _CELLS_PER_FRAME // 2]
                self._refresh_at = int(again[-1]) + 1 if again.size and start + again.size \
                    < known.size else 0
                picked = sorted(set(picked) | set(int(i) for i in again))
        if not picked:
            return []
        idx = np.asarray(picked, dtype=np.int64)
        self._map_sent[idx] = codes[idx]
        cells = [(int(i), int(codes[i])) for i in idx]
        return split_cells(cells, header, round(now, 3), self.lane.max_frame)


def _state(state: Any) -> str:
    text = str(state)
    return text if text in ("running", "restarting", "stopped") else (
        "running" if text == "starting" else "stopped")

