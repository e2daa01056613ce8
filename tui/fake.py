"""A fake system that fulfils the console contract (`tui.snapshot.System`).

It exists so the console can be built, tested, demonstrated and benchmarked
before (and independently of) the real system. It is small but honest about
the things the console must show: a mapper that drives a fixed tour of a fixed
room and grows an occupancy grid from ray-cast LIDAR scans; a hider and a
seeker that drive straight to the spots they are given; mailboxes whose depth
and rate follow the activity; a decoded message log; a supervision tree where
an injected crash or hang visibly restarts; link statistics; a timeline; the
whole fault catalogue of DESIGN.md section 7 with durations.

Everything runs on Trio's clock (the system's own `MockClock`, so pause and
speed changes are real changes of simulated time) and all randomness comes from
one seeded generator. It is not a simulation: rovers pass through obstacles on
the way to a spot, and the map frame is the room's frame shifted to the
mapper's start. The room itself (its truth, the tour, ray casting) is
`tui.fake_room`; the fake's workers, fault catalogue and supervision tree are
`tui.fake_parts`.
"""

from __future__ import annotations

import math
import pathlib
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import trio
import trio.testing

from tui.controller import QueuedController
from tui.fake_parts import CAPACITY, WORKERS, Node, fault_catalogue, tree_view
from tui.fake_room import (
    LIDAR_RAYS,
    RES_CM,
    START_CM,
    TOUR_CM,
    carve,
    cast,
    clearance,
    room_grid,
    write_map,
)
from tui.snapshot import (
    FREE,
    MAX_LOG_LINES,
    MAX_TIMELINE,
    UNKNOWN,
    ActiveFault,
    GridView,
    LinkStats,
    LogLine,
    Pose,
    Publish,
    QueueStats,
    RoverView,
    Snapshot,
    TimelineEvent,
)

__all__ = ["FakeSystem", "COMMAND_CAPACITY", "TICK_S"]

#: Commands the fake's queue holds before it answers "busy".
COMMAND_CAPACITY = 64
#: Simulated time per step of the fake [s].
TICK_S = 0.1
SPEED_CMS = {"mapper": 25.0, "hider": 30.0, "seeker": 30.0}
RESTART_DELAY_S = 0.5
WATCHDOG_S = 1.0
FOUND_RADIUS_CM = 40.0


@dataclass(slots=True)
class _Rover:
    id: str
    role: str
    x: float
    y: float
    heading: float
    drift: np.ndarray = field(default_factory=lambda: np.zeros(2))
    goal: tuple[float, float] | None = None
    path: list[tuple[float, float]] = field(default_factory=list)


class FakeSystem(QueuedController):
    """A `tui.snapshot.System` with a fake room and fake rovers.

    Args:
        seed: seed of the one random generator.
        scenario: name shown in the console.
        speed: initial clock rate, None for "as fast as possible".
        paused: start with simulated time stopped.

    Attributes:
        calls: every controller call received, ``(method, args)``, newest last
            (bounded), for tests and the benchmark.
    """

    def __init__(self, *, seed: int = 0, scenario: str = "fake-room",
                 speed: float | None = 1.0, paused: bool = False) -> None:
        super().__init__(speed=speed, paused=paused, capacity=COMMAND_CAPACITY)
        self.seed = seed
        self.scenario = scenario
        self._rng = np.random.default_rng(seed)
        self._truth = room_grid()
        self._log: deque[LogLine] = deque(maxlen=MAX_LOG_LINES)
        self._timeline: deque[TimelineEvent] = deque(maxlen=MAX_TIMELINE)
        self._log_seq = 0
        self._event_seq = 0
        self._fault_seq = 0
        self._faults: dict[str, ActiveFault] = {}
        self._nodes: dict[str, Node] = {}
        self._queues: dict[str, list] = {}  # name -> [depth, capacity, count_window, rate, drops]
        self._links: dict[str, list[int | bool | float]] = {}
        self._catalogue = fault_catalogue()
        self._now = 0.0
        self._reset_game()

    # -- Trio side ----------------------------------------------------------
    async def run(self, publish: Publish, requests: trio.abc.ReceiveChannel[None]) -> None:
        """Run until cancelled (see `tui.snapshot.System.run`)."""
        self._publish = publish
        self._now = trio.current_time()
        self._event("game", f"fake system started (seed {self.seed})")
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._command_loop)
            nursery.start_soon(self._snapshot_loop, requests)
            while True:
                await trio.sleep(TICK_S)
                now = trio.current_time()
                self._step(now - self._now)
                self._now = now

    async def _snapshot_loop(self, requests: trio.abc.ReceiveChannel[None]) -> None:
        async for _ in requests:
            if self._publish is not None:
                self._publish(self.snapshot(trio.current_time()))

    def _before_command(self) -> None:
        self._now = trio.current_time()

    # -- commands (run in Trio); raise ValueError to refuse ------------------
    def _need_phase(self, command: str, *phases: str) -> None:
        if self._phase not in phases:
            raise ValueError(f"{command} is valid in {' or '.join(phases)}, not in {self._phase}")

    def _do_start_mapping(self) -> None:
        self._need_phase("start mapping", "idle")
        self._set_phase("mapping")

    def _do_stop_mapping(self) -> None:
        self._need_phase("stop mapping", "mapping")
        self._set_phase("map_ready")
        self._event("game", "mapping stopped early by the operator")

    def _do_hide_at(self, x: float, y: float, heading: float) -> str:
        self._need_phase("hide", "map_ready")
        grid = self._map_view()
        if grid.value_at(x, y) != FREE:
            raise ValueError(f"spot ({x:.0f}, {y:.0f}) cm is not known free space")
        rx, ry = x + START_CM[0], y + START_CM[1]
        if clearance(self._truth, rx, ry) < 15.0:
            raise ValueError(f"spot ({x:.0f}, {y:.0f}) cm has less than 15 cm clearance")
        self._hide = Pose(x, y, heading)
        self._send_to(self._rovers["hider"], (rx, ry))
        self._set_phase("hiding")
        return f"hider sent to ({x:.0f}, {y:.0f}) @ {heading:.0f} deg"

    def _do_seek_at(self, x: float, y: float, within: float | None = None) -> str:
        self._need_phase("seek", "hidden", "not_found")
        self._guesses.append((x, y))
        self._send_to(self._rovers["seeker"], (x + START_CM[0], y + START_CM[1]))
        self._set_phase("seeking")
        wider = "" if within is None else f", searching {within:.0f} cm round it"
        return f"seeker sent to ({x:.0f}, {y:.0f}){wider}"

    def _do_new_game(self) -> None:
        self._reset_game()
        self._event("game", "new game")

    def _do_inject_fault(self, target: str, kind: str, duration_s: float | None,
                         params: dict) -> str:
        kinds = {t.target: t.kinds for t in self._catalogue}
        if target not in kinds:
            raise ValueError(f"unknown fault target {target!r}")
        if kind not in kinds[target]:
            raise ValueError(f"fault {kind!r} is not valid for {target}; "
                             f"valid: {', '.join(kinds[target])}")
        if duration_s is not None and not duration_s > 0:
            raise ValueError(f"duration must be > 0 s, got {duration_s!r}")
        self._fault_seq += 1
        fid = f"f{self._fault_seq}"
        dur = f" for {duration_s:g} s" if duration_s else ""
        self._event("fault", f"{fid}: {kind} on {target}{dur}")
        if kind in ("crash", "hang"):
            node = self._nodes[target]
            if node.state != "running":
                return f"{fid} (already {node.state})"
            if kind == "crash":
                self._exit(target, "crashed: injected fault")
            else:
                node.hung, node.wake_s = True, self._now + WATCHDOG_S
            return fid
        until = None if duration_s is None else self._now + duration_s
        self._faults[fid] = ActiveFault(fid, target, kind, self._now, until)
        return fid

    def _do_clear_fault(self, fault: str) -> str:
        gone = [f for f in self._faults.values() if fault in (f.id, f.target)]
        if not gone:
            raise ValueError(f"no active fault {fault!r}")
        for f in gone:
            del self._faults[f.id]
            self._event("clear", f"{f.id}: {f.kind} on {f.target} cleared")
        return ", ".join(f.id for f in gone)

    def _do_export_map(self, directory: str) -> str:
        cells = self._map
        if not (cells != UNKNOWN).any():
            raise ValueError("the map is empty: start mapping first")
        out = pathlib.Path(directory).expanduser()
        if not out.is_dir():
            raise ValueError(f"export directory {directory!r} does not exist")
        pgm = write_map(cells, out)
        self._event("export", f"map saved to {pgm}")
        return str(pgm)

    # -- the fake world, stepped -------------------------------------------
    def _reset_game(self) -> None:
        self._phase = "idle"
        self._map = np.full(self._truth.shape, UNKNOWN, np.int8)
        self._lidar = np.zeros((0, 2))
        self._hide: Pose | None = None
        self._guesses: list[tuple[float, float]] = []
        self._tour = list(TOUR_CM)
        self._rovers = {
            "mapper": _Rover("mapper", "mapper", *START_CM, 0.0),
            "hider": _Rover("hider", "hider", 60.0, 250.0, -90.0),
            "seeker": _Rover("seeker", "seeker", 30.0, 110.0, 0.0),
        }
        for rid, workers in WORKERS.items():
            self._links.setdefault(rid, [True, 12.0, 0, 0, 0, 0, 0])
            for w in workers:
                self._nodes.setdefault(f"{rid}/{w}", Node())
                self._queues.setdefault(f"{rid}/{w}", [0, CAPACITY[w], 0, 0.0, 0])
        for name in ("system", "server", "world", "mapper", "hider", "seeker"):
            self._nodes.setdefault(name, Node())

    def _set_phase(self, phase: str) -> None:
        self._phase = phase
        self._event("phase", phase.replace("_", " "))

    def _event(self, kind: str, text: str) -> None:
        self._event_seq += 1
        self._timeline.append(TimelineEvent(self._event_seq, self._now, kind, text))

    def _say(self, actor: str, text: str) -> None:
        self._log_seq += 1
        self._log.append(LogLine(self._log_seq, self._now, actor, actor, text))
        q = self._queues.get(actor)
        if q is not None:
            q[2] += 1

    def _fault_on(self, target: str, *kinds: str) -> bool:
        return any(f.target == target and (not kinds or f.kind in kinds)
                   for f in self._faults.values())

    def _exit(self, name: str, reason: str) -> None:
        node = self._nodes[name]
        node.state, node.last_exit, node.last_exit_s = "restarting", reason, self._now
        node.hung, node.wake_s = False, self._now + RESTART_DELAY_S
        self._event("crash", f"{name} exited: {reason}")

    def _send_to(self, rover: _Rover, goal: tuple[float, float]) -> None:
        rover.goal = goal
        rover.path = [goal]

    def _map_view(self) -> GridView:
        return GridView(self._map, RES_CM, (-START_CM[0], -START_CM[1]))

    def _step(self, dt: float) -> None:
        if dt <= 0:
            return
        self._step_nodes()
        self._step_faults()
        if self._phase == "mapping":
            self._step_mapping(dt)
        for rid in ("hider", "seeker"):
            self._step_drive(self._rovers[rid], dt)
        self._step_queues(dt)
        self._step_links()

    def _step_nodes(self) -> None:
        for name, node in self._nodes.items():
            if node.wake_s is None or self._now < node.wake_s:
                continue
            if node.hung:
                self._exit(name, "hung")
            else:
                node.state, node.wake_s = "running", None
                node.restarts += 1
                self._event("restart", f"{name} restarted ({node.restarts})")

    def _step_faults(self) -> None:
        for f in list(self._faults.values()):
            if f.until_s is not None and self._now >= f.until_s:
                del self._faults[f.id]
                self._event("clear", f"{f.id}: {f.kind} on {f.target} ended")

    def _blocked(self, rid: str) -> bool:
        return (self._nodes[f"{rid}/motor"].state != "running" or self._nodes[f"{rid}/motor"].hung
                or self._fault_on(f"{rid}.motor", "stall")
                or self._fault_on(f"{rid}.encoder", "stuck"))

    def _drive(self, rover: _Rover, goal: tuple[float, float], dt: float) -> bool:
        """Move towards goal; True on arrival."""
        if self._blocked(rover.id):
            return False
        speed = SPEED_CMS[rover.role] * (0.5 if self._fault_on(f"{rover.id}.motor") else 1.0)
        dx, dy = goal[0] - rover.x, goal[1] - rover.y
        dist = math.hypot(dx, dy)
        step = speed * dt
        if dist > 1e-9:
            rover.heading = math.degrees(math.atan2(dy, dx))
        if dist <= step:
            rover.x, rover.y = goal
            return True
        rover.x += dx / dist * step
        rover.y += dy / dist * step
        slip = 3.0 if self._fault_on(f"{rover.id}.encoder", "slipping") else 0.3
        rover.drift += self._rng.normal(0.0, slip * dt, 2)
        self._say(f"{rover.id}/motor", f"MOTOR_MOVE {step:.1f} cm")
        self._say(f"{rover.id}/navigation",
                  f"NAV_TRAVEL ({step * 10:.0f}, {step * 10:.0f}) mm")
        return False

    def _step_drive(self, rover: _Rover, dt: float) -> None:
        if rover.goal is None:
            return
        if self._drive(rover, rover.goal, dt):
            rover.goal, rover.path = None, []
            if rover.role == "hider" and self._phase == "hiding":
                if self._hide is not None:
                    rover.heading = self._hide.heading_deg
                self._set_phase("hidden")
            elif rover.role == "seeker" and self._phase == "seeking":
                hx, hy = self._rovers["hider"].x, self._rovers["hider"].y
                near = math.hypot(rover.x - hx, rover.y - hy) <= FOUND_RADIUS_CM
                ir_high = self._fault_on("seeker.ir", "stuck_high")
                found = (near or ir_high) and not self._fault_on("seeker.ir", "stuck_low")
                self._say("seeker/ir", f"NAV_IR {int(found)}")
                self._set_phase("found" if found else "not_found")

    def _step_mapping(self, dt: float) -> None:
        mapper = self._rovers["mapper"]
        if not self._tour:
            self._set_phase("map_ready")
            self._event("game", "map complete: the tour is done")
            return
        mapper.path = list(self._tour)
        if self._drive(mapper, self._tour[0], dt):
            self._tour.pop(0)
        self._scan(mapper)

    def _scan(self, mapper: _Rover) -> None:
        """Ray-cast one LIDAR revolution in the truth grid and update the map."""
        if (self._nodes["mapper/lidar"].state != "running"
                or self._fault_on("mapper.lidar", "dead")):
            self._lidar = np.zeros((0, 2))
            return
        noise = 8.0 if self._fault_on("mapper.lidar", "noisy") else 1.0
        start = 0.0 if self._fault_on("mapper.lidar", "stuck") else self._rng.uniform(0, 4)
        angles = np.radians(start + np.arange(LIDAR_RAYS) * 360.0 / LIDAR_RAYS)
        rays = cast(self._truth, mapper.x, mapper.y, angles)
        carve(self._map, rays)
        steps, first, has = rays.steps, rays.first, rays.has
        dist = steps[first[has]] + self._rng.normal(0, noise, int(has.sum()))
        px = mapper.x + np.cos(angles[has]) * dist - START_CM[0]
        py = mapper.y + np.sin(angles[has]) * dist - START_CM[1]
        if self._fault_on("mapper.lidar", "garbage"):
            px = px + self._rng.uniform(-80, 80, px.shape)
        self._lidar = np.column_stack([px, py])
        for k in range(3):
            self._say("mapper/lidar", f"LIDAR_SAMPLE {np.degrees(angles[k]):.1f} deg "
                      f"{steps[first[k]]:.0f} cm")
        self._say("mapper/map", f"MAP_SCAN {int(has.sum())} points")

    def _step_queues(self, dt: float) -> None:
        for name, q in self._queues.items():
            rid, worker = name.split("/")
            flooded = self._fault_on(name, "flood")
            if flooded:
                q[2] += int(200 * dt)
                q[4] += int(150 * dt)
                q[0] = q[1]
            elif self._nodes[name].hung or self._nodes[name].state != "running":
                q[0] = min(q[1], q[0] + int(q[2] > 0) + 1)
            else:
                busy = q[2] > 0
                q[0] = int(self._rng.integers(0, max(2, q[1] // 4))) if busy else 0
            alpha = min(1.0, dt / 1.0)
            q[3] += alpha * (q[2] / dt - q[3])
            q[2] = 0
            if flooded and self._rng.random() < 0.3:
                self._say(name, "DROP overflow (queue full)")

    def _step_links(self) -> None:
        for rid, ln in self._links.items():
            dropped = self._fault_on(f"{rid}.wifly", "drop")
            ln[0] = not dropped and self._nodes[f"{rid}/wifly"].state == "running"
            if not ln[0]:
                continue
            base = 250.0 if self._fault_on(f"{rid}.wifly", "latency") else 12.0
            ln[1] = float(ln[1]) + 0.2 * (base + float(self._rng.normal(0, 2)) - float(ln[1]))
            ln[5] += 1
            ln[6] += 1
            if self._fault_on(f"{rid}.wifly", "loss") and self._rng.random() < 0.3:
                ln[2] += 1
                ln[3] += 1
            if self._fault_on(f"{rid}.wifly", "corrupt") and self._rng.random() < 0.3:
                ln[4] += 1

    # -- the snapshot --------------------------------------------------------
    def snapshot(self, now_s: float | None = None) -> Snapshot:
        """The current state as an immutable `Snapshot` (arrays are copies).

        Args:
            now_s: simulated time to report [s]; default the time of the last step.
        """
        truth = GridView(self._truth, RES_CM, (-START_CM[0], -START_CM[1]))
        rovers = []
        for r in self._rovers.values():
            mx, my = r.x - START_CM[0], r.y - START_CM[1]
            est = Pose(mx + float(r.drift[0]), my + float(r.drift[1]), r.heading)
            path = tuple((x - START_CM[0], y - START_CM[1]) for x, y in r.path)
            target = path[0] if path else None
            rovers.append(RoverView(r.id, r.role, est, Pose(mx, my, r.heading),  # type: ignore[arg-type]
                                    ((est.x_cm, est.y_cm),) + path if path else (), target))
        return Snapshot(
            time_s=self._now if now_s is None else now_s,
            speed=self._speed,
            paused=self._paused,
            scenario=self.scenario,
            seed=self.seed,
            phase=self._phase,
            guesses=len(self._guesses),
            map=GridView(self._map.copy(), RES_CM, (-START_CM[0], -START_CM[1])),
            truth=truth,
            rovers=tuple(rovers),
            lidar_points=self._lidar,
            hide_spot=self._hide,
            seek_guesses=tuple(self._guesses),
            queues=tuple(QueueStats(n.split("/")[0], n, q[0], q[1], q[3], q[4])
                         for n, q in self._queues.items()),
            log=tuple(self._log),
            tree=tree_view(self._nodes),
            links=tuple(LinkStats(rid, bool(ln[0]), float(ln[1]) if ln[0] else None,
                                  *(int(v) for v in ln[2:]))
                        for rid, ln in self._links.items()),
            timeline=tuple(self._timeline),
            faults=tuple(self._faults.values()),
            catalogue=self._catalogue,
        )
