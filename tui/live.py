"""The real system behind the console: `tui.snapshot.System` over a `SimSystem`.

`LiveSystem` opens the simulated world, the server and the rover trees
(`supervisors.system.open_sim_system`) inside the console's Trio guest run,
turns operator commands into server commands and fault injections, and builds
a `Snapshot` whenever the console asks for one. It reads the server's view
(phase, map, rover poses, link statistics), the runtime's (mailboxes, the
supervision tree, the trace) and, for the overlay and drift only, the world's
ground truth.
"""

from __future__ import annotations

import ast
import math
import pathlib
import re
from collections import deque
from collections.abc import Sequence
from itertools import islice
from typing import Any

import numpy as np
import trio

from actors import EventKind, Message, TraceEvent
from actors.firmware.commands import name_of
from server.export import write_pgm, write_png
from server.links import LinkSpec
from server.links.spec import DEFAULT_BAUD
from server.protocol import ROLES, GridMap, inverse
from server.protocol import Pose as FramePose
from server.protocol import compose as compose_pose
from server.store import Store
from supervisors.harness.headless import Budget, GameReport, finish_report, play_game
from supervisors.recording import Recorder, RecordingError
from supervisors.system import SimSystem, open_sim_system
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_DEVICES
from world.scenario import Scenario
from world.truth import truth_raster

from .controller import QueuedController
from .governor import GovernedClock
from .snapshot import (
    MAX_LOG_LINES,
    MAX_TIMELINE,
    ActiveFault,
    FaultTarget,
    GridView,
    LinkStats,
    LogLine,
    Pose,
    Publish,
    QueueStats,
    RoverView,
    Snapshot,
    TimelineEvent,
    TreeNode,
)

__all__ = ["LiveSystem", "ListenError", "fault_text"]

COMMAND_CAPACITY = 32  # operator commands waiting for Trio [commands]
PNG_SCALE = 4  # exported PNG: pixels per map cell edge (5 cm cells: 80 px per metre)
#: Commands an auto game refuses (the scenario chooses), and those an attached rover does.
AUTO_REFUSED = ("start_mapping", "stop_mapping", "hide_at", "seek_at", "new_game",
                "inject_fault", "clear_fault", "export_map")
REAL_TIME_REFUSED = ("pause", "resume", "set_speed")
#: Mailbox statistics, the supervision tree and the fault catalogue are rebuilt on
#: every this many snapshots (the console draws those tables at a third of its rate).
TABLES_EVERY = 3
_MAP_MARGIN_CELLS = 20  # unknown border shown around the known map [cells]
_MESSAGE_RE = re.compile(r"command=[^,]*?(\d+)>?,.*?value=([^)]+)\)")
_LIFECYCLE = {EventKind.CRASH, EventKind.RESTART, EventKind.HUNG, EventKind.ESCALATE,
              EventKind.FAULT, EventKind.KILLED, EventKind.POISON}


class ListenError(OSError):
    """Raised by `LiveSystem.run` when the address for attached rovers cannot be served."""


def _decode(message: str) -> str:
    """``Message(command=<Cmd.MOTOR_MOVE: 256>, ..., value=12.5)`` -> ``MOTOR_MOVE 12.5``."""
    m = _MESSAGE_RE.search(message)
    if m is None:
        return message[:80]
    return f"{name_of(int(m.group(1)))} {m.group(2)}"


def describe(message: Any) -> str:
    """A log line's text for a message object: ``MOTOR_MOVE 12.5`` for the firmware's
    `Message`, else its repr (at most 80 characters)."""
    if type(message) is Message:
        return f"{name_of(message.command)} {message.value!r}"
    return repr(message)[:80]


def fault_text(target: str, detail: str) -> str:
    """A device fault's trace event for people (``fault_injected [('duration_s', 60.0), ('id',
    1), ('kind', 'slipping'), ...]`` -> ``slipping on hider/encoder for 60 s (w1)``); ``""``
    for any other detail (actor faults read well as they are)."""
    what, _, rest = detail.partition(" ")
    if what not in ("fault_injected", "fault_cleared"):
        return ""
    try:
        fields = dict(ast.literal_eval(rest))
    except (ValueError, SyntaxError, TypeError):
        return ""
    fid = f"w{fields.get('id', '?')}"
    kind = fields.get("kind", "?")
    if what == "fault_cleared":
        return f"{kind} on {target} cleared ({fields.get('reason', 'cleared')}, {fid})"
    duration = float(fields.get("duration_s") or 0.0)
    params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in sorted(dict(fields.get("params") or {}).items()))
    return (f"{kind} on {target}" + (f" {params}" if params else "")
            + (f" for {duration:g} s" if duration else " until cleared")
            + (", scheduled" if fields.get("scheduled") else "") + f" ({fid})")


class LiveSystem(QueuedController):
    """The simulated system, as the console's `System` (see `tui.snapshot`).

    Args:
        scenario: the room and rovers.
        seed: the run's seed.
        speed: initial clock rate, None for as fast as possible.
        db: the server's SQLite file.
        log_messages: trace every message for the log pane (slower; the log
            then shows sends and receives, decoded).
        remote: rovers attached over real links instead of simulated here,
            ``role -> LinkSpec`` (``serial:PORT,BAUD``; ``tcp`` or ``udp``: the
            rover connects, or sends, to ``listen``; ``tcp:HOST:PORT``: the server
            connects to the rover there). With any, simulated time runs at real
            time only: a real rover cannot be paused or sped up, so speed and
            pause are refused.
        listen: where rovers on ``tcp`` connect and rovers on ``udp`` send
            (``tcp:HOST:PORT``, ``udp:HOST:PORT``; one of each at most is used).
        record: record the game from the start into this ``.mcap`` file (`record`
            starts and stops recording later).
        auto: play the headless operator's game by itself
            (`supervisors.harness.headless.play_game`: start mapping, hide at the
            scenario's spot, its guesses, the same retries) and end when it ends,
            with `report` filled; operator commands are then refused.
        budget: the auto game's time limits (`Budget`'s defaults when None).

    Without remote rovers the system runs on a `GovernedClock`: the headless
    game's virtual clock, released to the wall clock at the chosen speed, so
    every speed plays the same game (with ``auto``: the same trace hash as
    ``hideseek run``).

    Raises:
        ValueError: a remote role that is not mapper, hider or seeker, a link
            kind a rover cannot use, or ``tcp``/``udp`` without a ``listen`` of its kind.
    """

    def __init__(self, scenario: Scenario, *, seed: int = 1, speed: float | None = 1.0,
                 db: str = ":memory:", log_messages: bool = True,
                 remote: dict[str, LinkSpec] | None = None,
                 listen: Sequence[LinkSpec] = (), record: str | None = None,
                 auto: bool = False, budget: Budget | None = None) -> None:
        remote = dict(remote or {})
        for role, spec in remote.items():
            if role not in ROLES:
                raise ValueError(f"--rover {role}: the ID of an attached rover is its role, "
                                 f"one of {', '.join(ROLES)}")
            if spec.kind not in ("serial", "tcp", "udp", "tcp_listen"):
                raise ValueError(f"--rover {role}: a rover's link is serial:PORT[,BAUD], a "
                                 f"device path, tcp (it connects in), udp (it sends in) or "
                                 f"tcp:HOST:PORT (the server connects to it there), got "
                                 f"{spec.text!r}")
        listen = tuple(listen)
        for kind in ("tcp", "udp"):
            if any(spec.kind == kind for spec in remote.values()) and not any(
                    spec.kind.startswith(kind + "_") for spec in listen):
                raise ValueError(f"a rover on {kind} needs --listen {kind}:HOST:PORT")
        if remote and auto:
            raise ValueError("--auto plays the simulated game: no --rover with it")
        if remote:
            speed = 1.0  # a real rover lives in real time: a clock running at x1
        super().__init__(speed=speed, capacity=COMMAND_CAPACITY, governed=not remote)
        self.auto = auto
        """Playing the headless operator's game by itself (see the class docstring)."""
        self.budget = budget or Budget()
        self.report: GameReport | None = None
        """The auto game's report, once it has ended (what ``hideseek run`` prints)."""
        self._server_events: trio.MemoryReceiveChannel | None = None
        self.remote = remote
        """Role -> link of the rovers not simulated here."""
        self.listen = listen
        """Where rovers on ``tcp`` connect and rovers on ``udp`` send."""
        self.scenario = scenario
        self.seed = seed
        self._db = db
        self._log_messages = log_messages
        self._system: SimSystem | None = None
        self._log: deque[LogLine] = deque(maxlen=MAX_LOG_LINES)
        # messages as tapped (time, queue, message object, dropped), decoded into `_log`
        # only when a snapshot shows them: most scroll out between two frames, and
        # decoding each costs the simulation time
        self._raw_log: deque[tuple[float, str, Any, bool]] = deque(maxlen=MAX_LOG_LINES)
        self._decoded_seq = 0
        self._names: dict[int, str] = {}  # command code -> name, for the log
        self._timeline: deque[TimelineEvent] = deque(maxlen=MAX_TIMELINE)
        self._log_seq = 0
        self._event_seq = 0
        self._rates: dict[str, tuple[float, int, float]] = {}  # name -> (t, received, rate)
        self._exits: dict[str, float] = {}  # actor -> time of its last exit
        self._truth: GridView | None = None
        self._truth_raster: Any = None
        self._truth_key: tuple | None = None
        self._mapper_room = FramePose(0, 0, 0)
        self._snapshots = 0  # snapshots built
        self._tables: tuple[Any, Any, Any] | None = None  # (queues, tree, catalogue)
        self._record_path = record
        self._recorder: Recorder | None = None

    # -- Trio side ----------------------------------------------------------------------
    async def run(self, publish: Publish, requests: trio.abc.ReceiveChannel[None]) -> None:
        """Run the simulated system until cancelled, or with ``auto`` until the game ends
        (see `tui.snapshot.System.run`).

        The console's snapshots are built by `host_snapshot` on the console's side,
        so ``requests`` is not read: no task of the console wakes inside Trio, and
        the game's order of events is the headless game's (same trace hash).
        """
        self._publish = publish
        s = self.scenario.starts["mapper"]
        self._mapper_room = FramePose(s.x, s.y, s.heading_deg)
        roles = tuple(r for r in ROLES if r not in self.remote)
        with Store(self._db) as store:
            async with open_sim_system(self.scenario, seed=self.seed, store=store,
                                       roles=roles) as system:
                t_start = trio.current_time()
                self._system = system
                await self._prelude(system)
                if self._record_path:
                    try:
                        self._do_record(self._record_path)
                    except ValueError as exc:  # the console runs on, unrecorded
                        self._event("game", f"cannot record: {exc}")
                trace = system.actors.trace
                trace.subscribe(self._on_trace)  # lifecycle events and drops
                if self._log_messages:
                    trace.tap_messages(self._on_message)  # every send, cheaply
                self._server_events = system.server.subscribe()
                self._event("game", f"{self.scenario.name}: system started (seed {self.seed})")
                try:
                    if self.auto:
                        self._event("game", "auto play: the scenario's hide spot and guesses")
                        report = GameReport(self.scenario.name, self.seed)
                        try:
                            await play_game(system, report, self.budget)
                        finally:
                            finish_report(report, system, t_start)
                        self.report = report
                        return
                    await self._attach_remote(system)
                    await self._command_loop()
                finally:
                    if self._recorder is not None:  # the file is complete when the console ends
                        self._recorder.stop()

    async def _prelude(self, system: SimSystem) -> None:
        """Runs on the opened system before the console's own tasks start (a fork plays
        the recorded game to its time here: nothing of the console may run before)."""

    async def _attach_remote(self, system: SimSystem) -> None:
        """Serve the attached rovers' links (a failure to listen ends the system)."""
        for kind, start in (("tcp", system.server.listen_tcp),
                            ("udp", system.server.listen_udp)):
            where = next((s for s in self.listen if s.kind.startswith(kind + "_")), None)
            if where is None or not any(s.kind == kind for s in self.remote.values()):
                continue
            try:
                port = await start(where.host, where.port)
            except OSError as exc:  # a busy port: one line naming it (hideseek play, exit 2)
                raise ListenError(f"cannot listen on {where.text}: "
                                  f"{exc.strerror or exc}") from None
            self._event("link", f"listening for rovers on {kind}:{where.host}:{port}")
        for role, spec in self.remote.items():
            if spec.kind == "serial":
                system.server.start_serial(spec.url, spec.baud)
            elif spec.kind == "tcp_listen":  # a rover listening on TCP: connect out to it
                # (pyserial's socket:// URL: the serial link's reconnecting loop serves it)
                system.server.start_serial(f"socket://{spec.host}:{spec.port}", DEFAULT_BAUD)
            self._event("link", f"{role}: waiting for the rover on {spec.text}")
        if self.remote:
            self._event("game", "a real rover is attached: real time only (x1)")
        if "mapper" in self.remote:
            self._event("game", "the map shows once the mapper uploads it (its working map "
                                "is on the rover)")

    # -- commands (in Trio); raise ValueError to refuse ----------------------------------
    def _submit(self, name: str, *args: Any) -> None:
        if self.auto:  # the game is the headless operator's: nothing may change it
            self.calls.append((name, args))
            self._result(name, "refused", "auto play: the scenario chooses; pause, speed "
                                          "and the views are yours")
            return
        super()._submit(name, *args)

    def _real_time_only(self) -> None:
        if self.remote:
            raise ValueError(f"{', '.join(self.remote)} attached over a link: simulated time "
                             "runs at real time only (x1), no pause")

    def _do_pause(self) -> None:
        self._real_time_only()
        super()._do_pause()

    def _do_resume(self) -> None:
        self._real_time_only()
        super()._do_resume()

    def _do_set_speed(self, rate: float | None) -> str:
        self._real_time_only()
        return super()._do_set_speed(rate)

    async def _server_command(self, name: str, **kwargs: Any) -> str:
        assert self._system is not None
        result = await self._system.command(name, **kwargs)
        if not result.ok:
            raise ValueError(result.reason)
        return result.reason

    async def _do_start_mapping(self) -> str:
        return await self._server_command("start_mapping")

    async def _do_stop_mapping(self) -> str:
        return await self._server_command("stop_mapping")

    async def _do_hide_at(self, x: float, y: float, heading: float) -> str:
        return await self._server_command("hide", x=x, y=y, heading=heading)

    async def _do_seek_at(self, x: float, y: float, within: float | None = None) -> str:
        wider = {} if within is None else {"within": within}
        return await self._server_command("seek", x=x, y=y, **wider)

    async def _do_new_game(self) -> str:
        return await self._server_command("new_game")

    async def _do_inject_fault(self, target: str, kind: str, duration_s: float | None,
                               params: dict) -> str:
        assert self._system is not None
        role = target.split("/")[0].split(".")[0]
        if role in self.remote:
            raise ValueError(f"{role} is attached over {self.remote[role].text}: its devices "
                             "and actors are not simulated here")
        # the trace reports it on the Events tab (`fault_text`), as it does scheduled faults
        return self._system.inject_fault(target, kind, duration_s or 0.0, **params)

    async def _do_clear_fault(self, fault: str) -> str:
        assert self._system is not None
        n = self._system.clear_fault(fault)
        if n == 0:
            raise ValueError(f"no active device fault {fault!r}")
        self._event("clear", f"cleared {n} fault(s): {fault}")
        return f"{n} cleared"

    async def _do_export_map(self, directory: str) -> str:
        assert self._system is not None
        grid = self._system.server.game.map
        if grid is None:
            snap = self._system.mapper_grid()
            if snap is None:
                raise ValueError("there is no map yet: start mapping first")
            grid = GridMap(np.asarray(snap.cells, np.int8), snap.resolution_cm,
                           tuple(snap.origin_cm))
        out = pathlib.Path(directory).expanduser()
        if not out.is_dir():
            raise ValueError(f"export directory {directory!r} does not exist")
        name = f"map-{self.scenario.name}-seed{self.seed}-{trio.current_time():.0f}s"
        pgm, yaml = write_pgm(grid, out, name)
        png = write_png(grid, out, name, scale=PNG_SCALE)
        self._event("export", f"map saved: {pgm.name}, {yaml.name}, {png.name}")
        return f"{pgm}, {yaml}, {png}"

    # -- recording ----------------------------------------------------------------------
    def record(self, path: str | None = None) -> None:
        """Start recording the game as MCAP into ``path`` (a folder or None: a name of its
        own in that folder or the working directory), or stop the recording in progress.
        Queued like every command."""
        self._submit("record", path)

    def _do_record(self, path: str | None) -> str:
        assert self._system is not None
        if self._recorder is not None:
            rec, self._recorder = self._recorder, None
            rec.stop()
            self._event("game", f"recording saved: {rec.path}")
            return f"saved {rec.path}"
        if path is None or pathlib.Path(path).is_dir():
            path = str(pathlib.Path(path or ".") / (f"hideseek-{self.scenario.name}-seed"
                                                    f"{self.seed}-{trio.current_time():.0f}s.mcap"))
        try:
            recorder = Recorder.for_scenario(path, self.scenario, self.seed, operator="console")
        except RecordingError as exc:
            raise ValueError(str(exc)) from None
        recorder.start(self._system)
        self._recorder = recorder
        self._event("game", f"recording to {path}")
        return f"recording to {path}"

    @property
    def recording(self) -> str | None:
        """The file being recorded to, or None."""
        return None if self._recorder is None else self._recorder.path

    # -- events -------------------------------------------------------------------------
    def _event(self, kind: str, text: str) -> None:
        self._event_seq += 1
        self._timeline.append(TimelineEvent(self._event_seq, self.clock.current_time(), kind,
                                            text))

    def _on_message(self, time: float, kind: EventKind, queue: str, message: Any,
                    depth: int) -> None:
        """A message tap (`actors.Trace.tap_messages`): runs for every message sent."""
        self._log_seq += 1
        self._raw_log.append((time, queue, message, False))

    def _on_trace(self, event: TraceEvent) -> None:
        if event.kind is EventKind.DROP:
            self._log_seq += 1
            self._raw_log.append((event.time, event.queue, event.message, True))
            return
        if event.kind in _LIFECYCLE:
            if event.kind in (EventKind.CRASH, EventKind.HUNG, EventKind.KILLED):
                self._exits[event.actor] = event.time
            kind = {EventKind.RESTART: "restart", EventKind.FAULT: "fault"}.get(event.kind, "crash")
            text = fault_text(event.actor, event.detail) if kind == "fault" else ""
            self._event(kind, text or f"{event.kind.value} {event.actor} {event.detail}".strip())

    def _log_lines(self) -> tuple[LogLine, ...]:
        """The message log, decoding what was traced since the last snapshot."""
        raw = self._raw_log
        first = self._log_seq - len(raw) + 1  # seq of the oldest raw entry
        start = max(self._decoded_seq + 1, first)
        names = self._names
        append = self._log.append
        # indexing a deque walks it: take the new entries from its end in one go
        for i, (time, queue, message, dropped) in enumerate(
                islice(raw, start - first, None), start):
            if dropped:  # a drop is a trace event: its message is a repr already
                text = "DROP overflow " + _decode(message)
            elif type(message) is Message:
                command = message.command
                name = names.get(command)
                if name is None:
                    name = names[command] = name_of(command)
                text = f"{name} {message.value!r}"
            else:
                text = repr(message)[:80]
            append(LogLine(i, time, queue, queue, text))
        self._decoded_seq = self._log_seq
        return tuple(self._log)

    def _drain_server_events(self) -> None:
        """The server's events since the last snapshot, into the timeline (on the console's
        side: the channel only buffers, so no task wakes for it)."""
        events = self._server_events
        while events is not None:
            try:
                e = events.receive_nowait()
            except (trio.WouldBlock, trio.EndOfChannel, trio.ClosedResourceError):
                return
            if e.kind == "phase":
                self._event("phase", f"phase {e.data.get('phase')}"
                            + (f": {e.data['reason']}" if e.data.get("reason") else ""))
            elif e.kind in ("link_up", "link_down"):
                self._event("link", f"{e.rover} {e.kind.replace('_', ' ')}")
            elif e.kind in ("report", "refused", "map"):
                body = " ".join(f"{k}={v}" for k, v in e.data.items())
                self._event("game", f"{e.kind} {e.rover} {body}".strip())

    # -- snapshot -----------------------------------------------------------------------
    def host_snapshot(self) -> Snapshot:
        """A snapshot built on the console's side of the thread, between two of Trio's
        batches (see `tui.snapshot`): the game never sees the console look."""
        self._drain_server_events()
        return self.snapshot()

    def snapshot(self) -> Snapshot:
        """A whole picture of the system now (its queues, tree and fault catalogue as of
        at most `TABLES_EVERY` - 1 snapshots ago)."""
        system = self._system
        now = self.clock.current_time()
        reached = self.clock.reached() if isinstance(self.clock, GovernedClock) else None
        if system is None:
            return Snapshot(now, self._speed, self._paused, self.scenario.name, self.seed, "idle")
        server = system.server.snapshot()
        grid = self._map_view(system)
        if self._tables is None or self._snapshots % TABLES_EVERY == 0:
            self._tables = (self._queues(system, now), self._tree(system),
                            self._catalogue(system))
        self._snapshots += 1
        queues, tree, catalogue = self._tables
        return Snapshot(
            time_s=now, speed=self._speed, paused=self._paused, speed_reached=reached,
            scenario=self.scenario.name,
            seed=self.seed, phase=server.phase, guesses=len(server.guesses), map=grid,
            truth=self._truth_view(grid), rovers=self._rovers(system, server),
            hide_spot=_pose(server.hide_spot),
            seek_guesses=tuple((g.x, g.y) for g in server.guesses),
            refused=(AUTO_REFUSED if self.auto else ()) + (REAL_TIME_REFUSED if self.remote
                                                            else ()),
            queues=queues, log=self._log_lines(), tree=tree, links=self._links(server),
            timeline=tuple(self._timeline), faults=self._faults(system), catalogue=catalogue)

    def _map_view(self, system: SimSystem) -> GridView | None:
        snap = system.mapper_grid()
        if snap is None:
            grid = system.server.game.map
            if grid is None:
                return None
            return GridView(np.array(grid.cells, np.int8), grid.resolution_cm,
                            tuple(grid.origin_cm))
        snap = snap.crop_known(margin_cells=_MAP_MARGIN_CELLS)  # the room, not 24 m of nothing
        return GridView(np.array(snap.cells, np.int8), snap.resolution_cm, tuple(snap.origin_cm))

    def _truth_view(self, grid: GridView | None) -> GridView | None:
        """Ground truth resampled onto the map's raster (same frame and cells)."""
        if grid is None:
            return None
        key = (grid.shape, grid.origin_cm, grid.resolution_cm)
        if key != self._truth_key:
            if self._truth_raster is None:
                self._truth_raster = truth_raster(self.scenario, grid.resolution_cm)
            truth = self._truth_raster
            ny, nx = grid.shape
            x0, y0 = grid.origin_cm
            r = grid.resolution_cm
            xs = x0 + (np.arange(nx) + 0.5) * r
            ys = y0 + (np.arange(ny) + 0.5) * r
            mx, my = np.meshgrid(xs, ys)
            m = self._mapper_room
            h = math.radians(m.heading_deg)
            rx = m.x + math.cos(h) * mx - math.sin(h) * my
            ry = m.y + math.sin(h) * mx + math.cos(h) * my
            col = np.floor(rx / truth.resolution_cm).astype(int)
            row = np.floor(ry / truth.resolution_cm).astype(int)
            th, tw = truth.occupied.shape
            inside = (row >= 0) & (row < th) & (col >= 0) & (col < tw)
            cells = np.full((ny, nx), 100, np.int8)
            occ = truth.occupied[np.clip(row, 0, th - 1), np.clip(col, 0, tw - 1)]
            cells[inside & ~occ] = 0
            self._truth = GridView(cells, r, grid.origin_cm)
            self._truth_key = key
        return self._truth

    def _rovers(self, system: SimSystem, server: Any) -> tuple[RoverView, ...]:
        to_map = inverse(self._mapper_room)
        views = {r.role: r for r in server.rovers}
        out = []
        for role in ROLES:
            view = views.get(role)
            if role in self.remote:  # its true pose is in another world
                out.append(RoverView(role, role, _pose(view.pose if view else None), None,
                                     link=view.link if view else self.remote[role].text))
                continue
            t = system.world.true_pose(role)
            true = compose_pose(to_map, FramePose(t.x, t.y, t.heading_deg))
            pose = view.pose if view is not None and view.pose is not None else None
            if pose is None:  # before its first report: where the operator placed it
                start = self.scenario.starts[role]
                pose = compose_pose(to_map, FramePose(start.x, start.y, start.heading_deg))
            out.append(RoverView(role, role, _pose(pose), _pose(true),
                                 link=view.link if view else "memory"))
        return tuple(out)

    def _queues(self, system: SimSystem, now: float) -> tuple[QueueStats, ...]:
        out = []
        for name in system.actors.names():
            if "/" not in name:
                continue
            s = system.actors.statistics(name)
            t0, r0, rate = self._rates.get(name, (now, s.received, 0.0))
            if now - t0 >= 1.0:
                rate = (s.received - r0) / (now - t0)
                t0, r0 = now, s.received
            self._rates[name] = (t0, r0, rate)
            out.append(QueueStats(name.split("/")[0], name, s.depth, s.capacity, rate,
                                  s.dropped))
        return tuple(out)

    def _tree(self, system: SimSystem) -> TreeNode:
        def convert(node: Any) -> TreeNode:
            state = str(node.state)
            state = {"starting": "restarting"}.get(state, state)
            return TreeNode(node.name, str(node.kind), state, node.restarts,  # type: ignore[arg-type]
                            None if node.last_exit is None else str(node.last_exit),
                            self._exits.get(node.name),
                            tuple(convert(c) for c in node.children))
        roots = tuple(convert(n) for n in system.tree_snapshots())
        return TreeNode("system", "supervisor", "running", 0, None, None, roots)

    def _links(self, server: Any) -> tuple[LinkStats, ...]:
        out = []
        for r in server.rovers:
            s = r.stats
            out.append(LinkStats(r.id, s.up, None if s.rtt_s is None else s.rtt_s * 1000.0,
                                 s.lost, s.resent, s.bad_frames, s.frames_in, s.frames_out))
        return tuple(out)

    def _faults(self, system: SimSystem) -> tuple[ActiveFault, ...]:
        out = []
        for f in system.world.active_faults():
            until = f.start_s + f.duration_s if f.duration_s > 0 else None
            out.append(ActiveFault(f"w{f.id}", f.target, f.kind, f.start_s, until))
        return tuple(out)

    def _catalogue(self, system: SimSystem) -> tuple[FaultTarget, ...]:
        """Every target with every fault the catalogue has for it: a device and the
        actor that drives it share a name (``mapper/lidar``) and so one entry."""
        kinds: dict[str, dict[str, dict[str, float]]] = {}
        for role in ROLES:
            if role in self.remote:
                continue
            for device, device_kinds in DEVICE_FAULTS.items():
                if role in ROLE_DEVICES.get(device, ROLES):
                    kinds[f"{role}/{device}"] = dict(device_kinds)
        for name in system.actors.names():
            if "/" in name and name.split("/")[0] not in self.remote:
                kinds.setdefault(name, {}).update(ACTOR_FAULTS)
        return tuple(FaultTarget(target, tuple(by_kind),
                                 {k: dict(p) for k, p in by_kind.items() if p})
                     for target, by_kind in kinds.items())

def _pose(p: FramePose | None) -> Pose | None:
    return None if p is None else Pose(p.x, p.y, p.heading_deg)
