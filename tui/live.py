"""The real system behind the console: `tui.snapshot.System` over a `SimSystem`.

`LiveSystem` opens the simulated world, the server and the rover trees
(`supervisors.system.open_sim_system`) inside the console's Trio guest run,
turns operator commands into server commands and fault injections, and builds
a `Snapshot` whenever the console asks for one. It reads the server's view
(phase, map, rover poses, link statistics), the runtime's (mailboxes, the
supervision tree, the trace) and, for the overlay and drift only, the world's
ground truth. The message log and timeline are `tui.activity`, the views of the
system's parts `tui.sim_views`.
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np
import trio

from server.export import write_pgm
from server.links import LinkSpec
from server.links.spec import PLAY_ROVER
from server.protocol import ROLES, GridMap
from server.protocol import Pose as FramePose
from server.store import Store
from supervisors.harness.headless import Budget, GameReport, finish_report, play_game
from supervisors.recording import Recorder, RecordingError
from supervisors.system import SimSystem, open_sim_system
from world.scenario import Scenario

from .activity import ActivityLog
from .attached_views import (
    attached_catalogue,
    attached_faults,
    attached_map,
    attached_queues,
    attached_trees,
)
from .controller import QueuedController
from .governor import GovernedClock
from .sim_views import (
    QueueRates,
    TruthOverlay,
    active_faults,
    fault_catalogue,
    link_stats,
    map_view,
    rover_views,
    snapshot_pose,
    tree_view,
)
from .snapshot import GridView, Publish, Snapshot

__all__ = ["LiveSystem", "ListenError"]

COMMAND_CAPACITY = 32  # operator commands waiting for Trio [commands]
#: Commands an auto game refuses (the scenario chooses), and those an attached rover does.
AUTO_REFUSED = ("start_mapping", "stop_mapping", "hide_at", "seek_at", "new_game",
                "inject_fault", "clear_fault", "export_map")
REAL_TIME_REFUSED = ("pause", "resume", "set_speed")
#: Mailbox statistics, the supervision tree and the fault catalogue are rebuilt on
#: every this many snapshots (the console draws those tables at a third of its rate).
TABLES_EVERY = 3


class ListenError(OSError):
    """Raised by `LiveSystem.run` when the address for attached rovers cannot be served."""


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
            if spec.kind not in PLAY_ROVER.kinds:
                raise ValueError(f"{PLAY_ROVER.option} must be {PLAY_ROVER.forms}, got "
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
        self.activity = ActivityLog(lambda: self.clock.current_time())
        """The message log and the timeline of events the console shows."""
        self._rates = QueueRates()
        self._truth = TruthOverlay(scenario)
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
                trace.subscribe(self.activity.on_trace)  # lifecycle events and drops
                if self._log_messages:
                    trace.tap_messages(self.activity.on_message)  # every send, cheaply
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
            elif spec.kind == "tcp_out":  # a rover listening on TCP: connect out to it
                # (pyserial's socket:// URL: the serial link's reconnecting loop serves it)
                system.server.start_serial(spec.url, spec.baud)
            self._event("link", f"{role}: waiting for the rover on {spec.text}")
        if self.remote:
            self._event("game", "a real rover is attached: real time only (x1)")
        if "mapper" in self.remote:
            self._event("game", "the map pane shows the mapper's working map as its "
                                "telemetry draws it, then the map it uploads")

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
        if role in self.remote:  # over the protocol (or on its link): the server's part
            rest = target.split("/", 1)[1] if "/" in target else ""
            return self._system.server.rover_fault(role, "inject", rest, kind,
                                                   duration_s or 0.0, dict(params))
        # the trace reports it on the Events tab (`activity.fault_text`), as it does scheduled ones
        return self._system.inject_fault(target, kind, duration_s or 0.0, **params)

    async def _do_clear_fault(self, fault: str) -> str:
        assert self._system is not None
        role, _, rest = fault.partition("/")
        if role in self.remote and rest:  # ``mapper/link``, ``mapper/lidar``: all on it
            text = self._system.server.rover_fault(role, "clear", rest, "*")
            self._event("clear", text)
            return text
        n = self._system.clear_fault(fault)
        if n == 0:
            raise ValueError(f"no active device fault {fault!r}")
        self._event("clear", f"cleared {n} fault(s): {fault}")
        return f"{n} cleared"

    async def _do_export_map(self, directory: str) -> str:
        from tui.pictures.map_image import export_png  # noqa: PLC0415 - Pillow when asked

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
        png = export_png(grid, out, name)
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
        self.activity.event(kind, text)

    # -- snapshot -----------------------------------------------------------------------
    def host_snapshot(self) -> Snapshot:
        """A snapshot built on the console's side of the thread, between two of Trio's
        batches (see `tui.snapshot`): the game never sees the console look."""
        self.activity.drain_server_events(self._server_events)
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
        grid = map_view(system)
        if grid is None or (self.remote and system.server.game.map is None):
            grid = attached_map(server, self.remote) or grid  # the mapper's working map
        if self._tables is None or self._snapshots % TABLES_EVERY == 0:
            tree = tree_view(system, self.activity.exits)
            if self.remote:  # attached rovers, from their telemetry
                tree = dataclasses.replace(tree, children=tree.children + attached_trees(
                    server, self.remote))
            self._tables = (self._rates.stats(system, now) + attached_queues(server, self.remote),
                            tree,
                            fault_catalogue(system, self.remote)
                            + attached_catalogue(server, self.remote))
        self._snapshots += 1
        queues, tree, catalogue = self._tables
        return Snapshot(
            time_s=now, speed=self._speed, paused=self._paused, speed_reached=reached,
            scenario=self.scenario.name,
            seed=self.seed, phase=server.phase, guesses=len(server.guesses), map=grid,
            truth=self._truth_view(grid),
            rovers=rover_views(system, server, self.scenario, self.remote, self._mapper_room),
            hide_spot=snapshot_pose(server.hide_spot),
            seek_guesses=tuple((g.x, g.y) for g in server.guesses),
            refused=(AUTO_REFUSED if self.auto else ()) + (REAL_TIME_REFUSED if self.remote
                                                            else ()),
            queues=queues, log=self.activity.log_lines(), tree=tree, links=link_stats(server),
            timeline=self.activity.timeline(),
            faults=active_faults(system) + attached_faults(system.server, self.remote),
            catalogue=catalogue)

    def _truth_view(self, grid: GridView | None) -> GridView | None:
        """Ground truth on the map's raster (see `TruthOverlay`)."""
        return self._truth.view(grid, self._mapper_room)
