"""Record a running simulated game as an MCAP file, without changing the game.

A `Recorder` watches a `SimSystem` the way a debugger would and writes what it
sees to the channels of `supervisors.recording.schemas`, with the run's
metadata (`RunInfo`, the scenario's TOML text) and the game's state
(`game_state`: phase, hide spot, guesses, faults in force; the map and poses
are sampled at once) at the start, and the game's summary at the end, so a
recording started at any moment of a game replays from what the game was then.
Timestamps are Trio's clock: simulated time [s], as nanoseconds in the file.

Why the game cannot tell it is recorded: everything is read in synchronous
callbacks the system already offers, and no task is added, so Trio's
scheduling (part of a game's trace hash) is untouched:

* every message sent to a mailbox comes from a message tap
  (`actors.Trace.tap_messages`, which never changes the trace hash), and
  drops and lifecycle events from a trace subscriber;
* time-sampled channels (poses and paths every `POSE_PERIOD_S`, the working
  map and a checkpoint every whole second, the server's events, faults) are
  sampled from the message tap when simulated time has passed their next
  sampling instant: messages flow every few
  milliseconds (timers, encoder interrupts), so samples land within a few ms
  of their period, at the same instants on every run of one seed;
* the link frames come from wrapping the two byte callbacks of each rover's
  link (``WiflyLink.on_server_receive`` and ``MemoryLink.outbound``), and the
  LIDAR revolutions from wrapping the world's ``Lidar.measure``; the wrappers
  pass everything through unchanged and are removed by `Recorder.stop`.

The server's event channel is drained in the same callbacks (``receive_nowait``:
no task waits on it).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import IO, Any

import msgspec
import numpy as np
import trio
from mcap.writer import CompressionType, Writer

from actors import EventKind, Message, TraceEvent
from actors.firmware.commands import name_of
from actors.message import ValueType
from server.protocol import ROLES, Pose, compose, inverse
from supervisors.system import SimSystem
from world.scenario import Scenario

from .records import checkpoint, game_state, grid_msg, log_msg, pose_msg, stamp
from .runinfo import RunInfo, scenario_text
from .schemas import CHANNELS, FRAME, schema_bytes

__all__ = ["Recorder", "RecordingError", "POSE_PERIOD_S", "MAX_PER_CHANNEL"]

POSE_PERIOD_S = 0.2
"""Poses and paths are sampled this often [s simulated]."""
MAX_PER_CHANNEL = 5_000_000
"""Most messages kept per channel; more are counted in the summary (``skipped``), not written."""
_LEVELS = {EventKind.CRASH: "error", EventKind.ESCALATE: "error", EventKind.HUNG: "warning",
           EventKind.KILLED: "warning", EventKind.POISON: "warning", EventKind.FAULT: "warning",
           EventKind.LATE_REPLY: "warning", EventKind.RESTART: "info"}
_TYPE_NAMES = {int(t): t.name for t in ValueType}
_MAP_MARGIN_CELLS = 10  # unknown border kept round the known working map [cells]


class RecordingError(RuntimeError):
    """Raised by `Recorder` when its file cannot be written."""


class _Lines:
    """Splits a byte stream into lines (the JSON frames of a link)."""

    __slots__ = ("buf",)
    MAX = 65536  # a line longer than this is cut (the protocol's limit is far below) [bytes]

    def __init__(self) -> None:
        self.buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        self.buf += data
        if b"\n" not in data:
            if len(self.buf) > self.MAX:
                del self.buf[:]
            return []
        *lines, rest = bytes(self.buf).split(b"\n")
        self.buf = bytearray(rest)
        return lines


class Recorder:
    """Writes one game to an MCAP file (see the module docstring).

    Use it as a run observer (`started`, `finished`: what
    `supervisors.harness.headless.run_game` calls), or by hand with `start` and
    `stop` on a running system (the console's record key).

    Args:
        path: the ``.mcap`` file to write (created or replaced).
        info: how the run was made (the ``hideseek.run`` metadata).
        scenario_toml: the scenario's TOML text (the ``hideseek.scenario`` record).

    Raises:
        RecordingError: the file cannot be created.
    """

    @classmethod
    def for_scenario(cls, path: str | os.PathLike[str], scenario: Scenario, seed: int,
                     **run: Any) -> Recorder:
        """A recorder of a run of ``scenario`` with ``seed``: its `RunInfo` (``run``:
        `RunInfo.for_scenario`'s keywords) and the scenario's TOML as metadata.

        Raises:
            RecordingError: the file cannot be created.
        """
        return cls(path, RunInfo.for_scenario(scenario, seed, **run),
                   scenario_toml=scenario_text(scenario))

    def __init__(self, path: str | os.PathLike[str], info: RunInfo, *,
                 scenario_toml: str = "") -> None:
        self.path = os.fspath(path)
        self.info = info
        self.counts: dict[str, int] = {c.topic: 0 for c in CHANNELS}
        """Messages written per topic."""
        self.skipped = 0
        """Messages not written because their channel reached `MAX_PER_CHANNEL`."""
        try:
            self._file: IO[bytes] | None = open(self.path, "wb")  # noqa: SIM115 (stop closes)
        except OSError as exc:
            raise RecordingError(f"cannot write recording {self.path!r}: "
                                 f"{exc.strerror or exc}") from None
        w = self._writer = Writer(self._file, compression=CompressionType.ZSTD,
                                  chunk_size=4 * 1024 * 1024)
        w.start(profile="", library="hideseek")
        schema_ids: dict[str, int] = {}
        self._ids: dict[str, int] = {}
        for c in CHANNELS:
            if c.schema not in schema_ids:
                schema_ids[c.schema] = w.register_schema(c.schema, "jsonschema",
                                                         schema_bytes(c.schema))
            self._ids[c.topic] = w.register_channel(c.topic, "json", schema_ids[c.schema],
                                                    {"description": c.description})
        w.add_metadata("hideseek.run", info.to_metadata())
        w.add_metadata("hideseek.scenario", {"toml": scenario_toml})
        self._enc = msgspec.json.Encoder()
        self._system: SimSystem | None = None
        self._undo: list[Callable[[], None]] = []
        self._names: dict[int, str] = {}
        self._next_pose = 0.0
        self._next_map = 0.0
        self._next_tick = 0.0  # min(next_pose, next_map)
        self._to_map = Pose(0.0, 0.0, 0.0)
        self._last_grid: bytes | None = None
        self._last_upload: Any = None
        self._paths: dict[str, tuple] = {}
        self._faults_seen = 0
        self._events: trio.MemoryReceiveChannel | None = None
        self._lines: dict[tuple[str, str], _Lines] = {}
        self._ticking = False
        self._batch: list[tuple[float, str, Any, int]] = []
        self.counts_messages = 0
        """Internal messages written (in ``/actors/messages`` batches)."""

    # ---------------------------------------------------------------- run observer
    def started(self, system: SimSystem) -> None:
        """Begin recording ``system`` (the run observer's start)."""
        self.start(system)

    def finished(self, system: SimSystem, report: Any) -> None:
        """Take the last samples, write the summary and close the file."""
        summary = report.to_json() if report is not None and hasattr(report, "to_json") else {}
        self.stop(summary)

    # ---------------------------------------------------------------- start / stop
    def start(self, system: SimSystem) -> None:
        """Attach to a running system (once)."""
        if self._system is not None:
            raise RuntimeError("a Recorder records one system once")
        self._system = system
        start = system.scenario.starts["mapper"]
        self._to_map = inverse(Pose(start.x, start.y, start.heading_deg))
        trace = system.actors.trace
        taps = [trace.tap_messages(self._on_message), trace.subscribe(self._on_event)]
        self._undo += [s.close for s in taps]
        self._events = system.server.subscribe(capacity=4096)
        self._writer.add_metadata("hideseek.queues", {
            name: str(system.actors.statistics(name).capacity)
            for name in system.actors.names() if "/" in name})
        for role in ROLES:
            self._wrap_link(system, role)
        self._wrap_lidar(system)
        now = trio.current_time()
        # the game so far is in the state record, not replayed: faults injected before
        # now are there if still in force, and never on /faults
        self._add("/game/state", now, game_state(system, now))
        self._faults_seen = len(system.faults)
        self._next_pose = self._next_map = now
        self._tick(now)

    def stop(self, summary: dict[str, Any] | None = None) -> None:
        """Take the last samples, detach, write the summary and close the file (idempotent)."""
        if self._file is None:
            return
        system = self._system
        try:
            if system is not None:
                now = trio.current_time()
                self._next_pose = now
                self._tick(now, final=True)
        finally:
            for undo in reversed(self._undo):
                undo()
            self._undo.clear()
            if self._events is not None:
                self._events.close()
            data = {k: (v if isinstance(v, str) else self._enc.encode(v).decode())
                    for k, v in (summary or {}).items()}
            data["channel_counts"] = self._enc.encode(self.counts).decode()
            data["internal_messages"] = str(self.counts_messages)
            data["skipped"] = str(self.skipped)
            self._writer.add_metadata("hideseek.summary", data)
            self._writer.finish()
            self._file.close()
            self._file = None

    @property
    def recording(self) -> bool:
        """True from `start` until `stop`."""
        return self._system is not None and self._file is not None

    # ---------------------------------------------------------------- writing
    def _add(self, topic: str, t: float, obj: Any) -> None:
        n = self.counts[topic]
        if n >= MAX_PER_CHANNEL:
            self.skipped += 1
            return
        self.counts[topic] = n + 1
        ns = max(0, round(t * 1e9))
        self._writer.add_message(self._ids[topic], ns, self._enc.encode(obj), ns, n)

    # ---------------------------------------------------------------- callbacks
    def _on_message(self, time: float, kind: EventKind, queue: str, message: Any,
                    depth: int) -> None:
        """The message tap: every message sent, and the sampling clock."""
        if time >= self._next_tick and not self._ticking:
            self._tick(time)
        self._batch.append((time, queue, message, depth))

    def _flush_messages(self) -> None:
        """Write the messages tapped since the last flush as one ``hideseek.MessageBatch``
        (one file record per message would cost the game a fifth of its speed)."""
        batch = self._batch
        if not batch:
            return
        names = self._names
        rows = []
        for time, queue, message, depth in batch:
            if type(message) is Message:
                command = message.command
                name = names.get(command)
                if name is None:
                    name = names[command] = name_of(command)
                rows.append({"t": time, "queue": queue, "command": name,
                             "type": _TYPE_NAMES.get(message.type, str(message.type)),
                             "value": message.value, "depth": depth})
            else:
                rows.append({"t": time, "queue": queue, "command": repr(message)[:80],
                             "type": "OBJECT", "value": 0, "depth": depth})
        self._batch = []
        self.counts_messages += len(rows)
        t0 = rows[0]["t"]
        self._add("/actors/messages", t0, {"timestamp": stamp(t0), "messages": rows})

    def _on_event(self, event: TraceEvent) -> None:
        """The trace subscriber: drops and the runtime's lifecycle events."""
        if event.kind is EventKind.DROP:
            self._add("/actors/drops", event.time, {
                "timestamp": stamp(event.time), "queue": event.queue,
                "command": event.message[:120], "type": "", "value": 0, "depth": event.depth})
            return
        text = f"{event.actor} {event.detail}".strip()
        self._add("/actors/events", event.time,
                  log_msg(event.time, _LEVELS.get(event.kind, "debug"), event.kind.value, text))

    def _wrap_link(self, system: SimSystem, role: str) -> None:
        memory = system.memory_links.get(role)
        if memory is None:
            return
        link = system.world.wifly_link(role)
        up, down = link.on_server_receive, memory.outbound
        ups, downs = self._lines[(role, "up")], self._lines[(role, "down")] = _Lines(), _Lines()

        def on_up(data: bytes) -> None:
            self._frames(role, "up", ups.feed(data))
            up(data)

        def on_down(data: bytes) -> None:
            self._frames(role, "down", downs.feed(data))
            down(data)

        link.on_server_receive, memory.outbound = on_up, on_down

        def undo() -> None:
            if link.on_server_receive is on_up:
                link.on_server_receive = up
            if memory.outbound is on_down:
                memory.outbound = down
        self._undo.append(undo)

    def _frames(self, role: str, direction: str, lines: list[bytes]) -> None:
        if not lines:
            return
        now = trio.current_time()
        topic = f"/{role}/link"
        for line in lines:
            self._add(topic, now, {"timestamp": stamp(now), "rover": role,
                                   "direction": direction,
                                   "text": line.decode("utf-8", "replace")})

    def _wrap_lidar(self, system: SimSystem) -> None:
        lidar = system.world.lidar
        measure = lidar.measure
        n_rev = int(lidar.p.lidar_samples_per_rev)
        ranges = np.zeros(n_rev)
        state = {"count": 0, "pose": None}

        def recorded_measure(first: int, n: int, stuck: bool, pose: tuple[float, float, float],
                             *args: Any, **kwargs: Any) -> np.ndarray:
            dist = measure(first, n, stuck, pose, *args, **kwargs)
            if state["pose"] is None:
                state["pose"] = pose
            idx = np.full(n, first) if stuck else (first + np.arange(n)) % n_rev
            ranges[idx] = dist
            state["count"] += n
            if state["count"] >= n_rev:  # a revolution's worth of samples: one scan
                self._scan(ranges, state["pose"])
                state["count"] -= n_rev
                state["pose"] = pose
            return dist

        lidar.measure = recorded_measure

        def undo() -> None:
            if lidar.measure is recorded_measure:
                del lidar.measure  # back to the class's method
        self._undo.append(undo)

    def _scan(self, ranges: np.ndarray, pose: tuple[float, float, float]) -> None:
        now = trio.current_time()
        x, y, heading = pose
        p = compose(self._to_map, Pose(x, y, math.degrees(heading)))
        n = len(ranges)
        self._add("/mapper/scan", now, {
            "timestamp": stamp(now), "frame_id": FRAME, "pose": pose_msg(p.x, p.y, p.heading_deg),
            "start_angle": 0.0, "end_angle": 2.0 * math.pi * (n - 1) / n,
            "ranges": (ranges / 100.0).round(4).tolist(), "intensities": []})

    # ---------------------------------------------------------------- sampling
    def _tick(self, now: float, *, final: bool = False) -> None:
        """Sample what is due at ``now`` (never re-entered). ``final``: the last samples
        of a stop, with no checkpoint (checkpoints are taken only at the first message at
        or after each whole second, the instants a fork's checker uses too)."""
        system = self._system
        if system is None:
            return
        self._ticking = True
        try:
            self._flush_messages()
            self._drain_events()
            self._record_faults(system)
            if now >= self._next_pose:
                # the period's index, with a margin for 0.6 / 0.2 = 2.9999999999999996
                self._next_pose = (math.floor(now / POSE_PERIOD_S + 1e-6) + 1) * POSE_PERIOD_S
                self._poses(system, now)
            if final:
                self._maps(system, now)
            elif now >= self._next_map:
                self._next_map = math.floor(now) + 1.0
                self._maps(system, now)
                self._add("/checkpoints", now, checkpoint(system, now))
            self._next_tick = min(self._next_pose, self._next_map)
        finally:
            self._ticking = False

    def _drain_events(self) -> None:
        events = self._events
        if events is None:
            return
        while True:
            try:
                e = events.receive_nowait()
            except (trio.WouldBlock, trio.EndOfChannel, trio.ClosedResourceError):
                return
            body = " ".join(f"{k}={v}" for k, v in e.data.items())
            level = "warning" if e.kind in ("refused", "link_down", "bad_frame") else "info"
            self._add("/game/events", e.t,
                      log_msg(e.t, level, e.kind, f"{e.rover} {body}".strip()))

    def _record_faults(self, system: SimSystem) -> None:
        faults = system.faults
        while self._faults_seen < len(faults):
            f = faults[self._faults_seen]
            self._faults_seen += 1
            t = float(f.get("t", trio.current_time()))
            text = f"{f.get('kind')} on {f.get('target')}" + (
                f" for {f['duration_s']:g} s" if f.get("duration_s") else "")
            self._add("/faults", t, log_msg(t, "warning", str(f.get("id", "")), text))

    def _poses(self, system: SimSystem, now: float) -> None:
        ts = stamp(now)
        for role in ROLES:
            if role not in system.trees:
                continue
            t = system.world.true_pose(role)
            p = compose(self._to_map, Pose(t.x, t.y, t.heading_deg))
            self._add(f"/{role}/pose/true", now,
                      {"timestamp": ts, "frame_id": FRAME,
                       "pose": pose_msg(p.x, p.y, p.heading_deg)})
            cell = system.actors.whereis(f"{role}/nav")
            nav = cell.actor if cell is not None else None
            if nav is None or getattr(nav, "origin", None) is None:
                continue
            b = nav.map_pose
            self._add(f"/{role}/pose/believed", now, {
                "timestamp": ts, "frame_id": FRAME,
                "pose": pose_msg(b.x, b.y, b.heading_deg)})
            follower = getattr(nav, "follower", None) or getattr(
                getattr(nav, "ex", None), "follower", None)
            path = () if follower is None else tuple(follower.waypoints[follower.index:])
            if path != self._paths.get(role, ()):
                self._paths[role] = path
                points = [(b.x, b.y), *path] if path else []
                self._add(f"/{role}/path", now, {
                    "timestamp": ts, "frame_id": FRAME,
                    "poses": [pose_msg(x, y, 0.0) for x, y in points]})

    def _maps(self, system: SimSystem, now: float) -> None:
        grid = system.mapper_grid()
        if grid is not None:
            grid = grid.crop_known(margin_cells=_MAP_MARGIN_CELLS)
        cells = None if grid is None else np.asarray(grid.cells, np.int8)
        # nothing known yet: no map (it would be the whole 24 m grid, unknown)
        if grid is not None and cells is not None and (cells != -1).any():
            key = cells.tobytes() + repr((grid.origin_cm, cells.shape)).encode()
            if key != self._last_grid:
                self._last_grid = key
                self._add("/map/working", now, grid_msg(now, cells, grid.resolution_cm,
                                                        tuple(grid.origin_cm)))
        upload = system.server.game.map
        if upload is not None and upload is not self._last_upload:
            self._last_upload = upload
            self._add("/map/uploaded", now, grid_msg(now, np.asarray(upload.cells, np.int8),
                                                     upload.resolution_cm,
                                                     tuple(upload.origin_cm)))
