"""The whole simulated system: world, server and one supervision tree per rover.

This is the one module outside ``tui/`` that wires the layers together
(DESIGN.md section 1). It builds, for one scenario and seed:

* the `World` (room, rovers' hardware, WiFly link models), stepped on Trio's clock;
* the game `Server` with its SQLite store, a memory link per simulated rover,
  bridged to that rover's WiFly link model (bytes only: the server never sees
  the world);
* an actor system with one supervision tree per rover (`supervisors.rover`),
  whose firmware sees only the hardware interface;
* a fault router: device faults go to the world, actor faults (crash, hang,
  flood) to the actor runtime; both are trace events.

Ground truth (true poses, the mapper's grid for metrics) is read here only by
probes for metrics and the console, never handed to firmware or server.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trio

from actors import (
    ActorSystem,
    EventKind,
    Trace,
    open_actor_system,
    seed_trio_scheduler,
    sleep,
)
from actors.clock import fast_instruments, skip_idle_io_polls
from actors.firmware.hardware import ROLES
from server.protocol import Pose
from server.server import Server, ServerConfig, open_server
from server.store import Store
from supervisors.attached_faults import (
    attached_schedule,
    send_scheduled_faults,
    simulated_only,
)
from supervisors.fault_router import ACTOR_FAULTS, FaultError, perform_actor_fault
from supervisors.rover import rover_tree
from world.faults import is_actor_fault
from world.scenario import Scenario
from world.world import World, run_world

__all__ = ["ACTOR_FAULTS", "SimSystem", "open_sim_system", "scenario_origins",
           "FaultError"]

_FAULT_POLL_S = 0.05  # how often scheduled actor faults are checked [s]


@dataclass
class SimSystem:
    """A running simulated system (made by `open_sim_system`)."""

    scenario: Scenario
    seed: int
    world: World
    server: Server
    actors: ActorSystem
    trees: dict[str, Any]
    """Role -> the rover's root supervisor."""
    faults: list[dict[str, Any]] = field(default_factory=list)
    """Every fault injected so far (device and actor), in order, for reports."""
    _world_origin: list[float] = field(default_factory=lambda: [0.0])
    """[Trio time at which the world's time was 0 [s]], set as the world starts stepping."""
    _actor_fault_ids: int = 0
    memory_links: dict[str, Any] = field(default_factory=dict)
    """Role -> the server's `MemoryLink` to that simulated rover (for recorders)."""

    def world_lag(self) -> float:
        """How far the world's stepping is behind Trio's clock [s] (about 0 when it keeps up).

        Under a scaled clock a slow machine cannot step the world as fast as the
        clock runs; the firmware's and the server's timers (heartbeats, link
        down after 5 s of silence) run on the clock, the bytes between them move
        only as the world steps. A console uses this to slow the clock down.
        """
        return trio.current_time() - (self._world_origin[0] + self.world.time)

    # ---------------------------------------------------------------- operator
    async def command(self, name: str, **kwargs: Any) -> Any:
        """An operator command to the server (see `Server.command`)."""
        return await self.server.command(name, **kwargs)

    # ---------------------------------------------------------------- faults
    def inject_fault(self, target: str, kind: str, duration_s: float = 0.0,
                     **params: float) -> str:
        """Inject a fault now; returns its id (``w<n>`` device, ``a<n>`` actor).

        Device faults (``mapper/lidar`` ``dead`` ...) go to the world. Actor faults
        target a registered actor (``mapper/nav`` ``crash`` | ``hang`` | ``flood``):
        ``hang`` blocks the actor's next message for ``duration_s`` (or
        ``params['seconds']``) so its watchdog fires; ``flood`` posts
        ``params['messages']`` no-op messages without waiting.

        Raises:
            FaultError: unknown target or kind, or a bad parameter.
        """
        if is_actor_fault(kind):
            return self._actor_fault(target, kind, duration_s, params)
        try:
            fid = self.world.inject_fault(target, kind, duration_s, **params)
        except ValueError as exc:
            raise FaultError(str(exc)) from None
        return f"w{fid}"  # the world's fault_injected event records it in `faults`

    def clear_fault(self, key: str) -> int:
        """Clear a device fault by id (``w3``) or every device fault on a target."""
        if key.startswith("w") and key[1:].isdigit():
            return self.world.clear_fault(int(key[1:]))
        return self.world.clear_fault(key)

    def _actor_fault(self, target: str, kind: str, duration_s: float,
                     params: dict[str, float]) -> str:
        perform_actor_fault(self.actors, target, kind, duration_s, params)
        self._actor_fault_ids += 1
        fid = f"a{self._actor_fault_ids}"
        self.faults.append({"id": fid, "t": trio.current_time(), "target": target,
                            "kind": kind, "duration_s": duration_s})
        return fid

    # ---------------------------------------------------------------- introspection
    def restarts(self) -> int:
        """Restarts of every firmware actor (and nested supervisor) so far."""
        def count(node: Any) -> int:
            return sum(c.restarts + count(c) for c in node.children)
        return sum(count(tree.snapshot()) for tree in self.trees.values())

    def dropped(self) -> int:
        """Messages dropped by full mailboxes so far."""
        total = 0
        for name in self.actors.names():
            total += self.actors.statistics(name).dropped
        return total

    def messages(self) -> int:
        """Messages delivered into mailboxes so far."""
        return sum(self.actors.statistics(name).sent for name in self.actors.names())

    def resent(self) -> int:
        """Frames resent by the server's reliable sessions so far."""
        snap = self.server.snapshot()
        return sum(r.stats.resent for r in snap.rovers)

    def mapper_grid(self) -> Any | None:
        """The mapper's working map right now (a probe for metrics and the console).

        Reads the Map Management actor's grid the way a debugger would read
        the rover's RAM; nothing is sent to the rover. None while it restarts.
        """
        cell = self.actors.whereis("mapper/map")
        actor = cell.actor if cell is not None else None
        grid = getattr(actor, "grid", None)
        return grid.snapshot() if grid is not None else None

    def tree_snapshots(self) -> list[Any]:
        """One `TreeNode` per rover, for a console."""
        return [tree.snapshot() for tree in self.trees.values()]


async def _watch_scheduled_actor_faults(system: SimSystem) -> None:
    """Hand the scenario's scheduled crash/hang/flood faults to the runtime when due."""
    while True:
        await sleep(_FAULT_POLL_S)
        for f in system.world.actor_faults_due():
            try:
                system.inject_fault(f.target, f.kind, f.duration_s, **f.params)
            except FaultError as exc:
                system.actors.trace.emit(EventKind.FAULT, f.target, detail=f"refused: {exc}")


async def _run_world(world: World, origin: list[float]) -> None:
    """`run_world`, noting the Trio time it aligns world time 0 to (in ``origin[0]``)."""
    origin[0] = trio.current_time() - world.time  # as run_world computes it, same instant
    await run_world(world)


def scenario_origins(scenario: Scenario) -> dict[str, Pose]:
    """Each role's start pose in the room frame [cm, deg]: the server's ``origins``."""
    return {role: Pose(p.x, p.y, p.heading_deg) for role, p in scenario.starts.items()}


def _world_events(trace: Trace, log: list[dict[str, Any]]) -> Callable[[str, str, dict], None]:
    """The world's event callback: every fault injection and clearance is a trace event."""
    def on_event(kind: str, target: str, detail: dict) -> None:
        trace.emit(EventKind.FAULT, target, detail=f"{kind} {sorted(detail.items())}")
        if kind == "fault_injected":
            log.append({"id": f"w{detail.get('id')}", "t": trio.current_time(),
                        "target": target, "kind": detail.get("kind"),
                        "duration_s": detail.get("duration_s", 0.0)})
    return on_event


@contextlib.asynccontextmanager
async def open_sim_system(scenario: Scenario, *, seed: int, store: Store,
                          trace: Trace | None = None,
                          nav_factory: Callable[..., Any] | None = None,
                          roles: tuple[str, ...] = ROLES,
                          server: Server | None = None) -> AsyncIterator[SimSystem]:
    """Run a simulated system for the block; everything stops cleanly on exit.

    Args:
        scenario: the room, start poses and fault schedule.
        seed: the run's seed: the world's noise, the actors' generators and
            Trio's scheduling order all derive from it.
        store: the server's database.
        trace: the trace hub (a new one by default).
        nav_factory: navigation actor factory for the rover trees (the real
            navigation by default; tests pass stand-ins).
        roles: which rovers are simulated (others may attach over real links).
        server: a running server to attach the simulated rovers to (``hideseek
            serve --rover ID=sim``); by default one is opened on ``store`` with
            the scenario's start poses as origins, and closed on exit.

    Raises:
        ValueError: a role that is not mapper, hider or seeker.
    """
    bad = [r for r in roles if r not in ROLES]
    if bad:
        raise ValueError(f"roles must be among {', '.join(ROLES)}, got {bad[0]!r}")
    seed_trio_scheduler(seed)
    fast_instruments()  # Trio's per-step instrument checks, cheaper (same events)
    skip_idle_io_polls()  # no epoll call in a round that cannot find anything (same events)
    trace = trace or Trace()
    fault_log: list[dict[str, Any]] = []
    schedule = attached_schedule(scenario, roles)  # faults for rovers attached elsewhere
    world = World(simulated_only(scenario, roles), np.random.default_rng(seed),
                  on_event=_world_events(trace, fault_log))
    async with contextlib.AsyncExitStack() as stack:
        if server is None:
            server = await stack.enter_async_context(
                open_server(store, ServerConfig(
                    origins=scenario_origins(scenario), simulated=tuple(roles),
                    rovers=frozenset(ROLES) - set(roles))))  # attached rovers: id = role
        memories = []
        for role in roles:
            link = world.wifly_link(role)
            memory = server.attach_memory(outbound=link.server_write, name=f"sim:{role}")
            link.on_server_receive = memory.feed
            memories.append(memory)
        stack.callback(lambda: [m.close() for m in memories])  # a server given outlives us
        # the world and the fault watcher stop first (cancelled); the rover trees
        # then stop gracefully, in reverse order, as open_actor_system closes
        async with open_actor_system(seed, trace=trace) as actors, \
                trio.open_nursery() as nursery:
            origin = [trio.current_time()]
            nursery.start_soon(_run_world, world, origin)
            trees = {}
            for role in roles:
                spec = rover_tree(role, world.hardware(role), nav_factory=nav_factory)
                trees[role] = await actors.start_supervisor(spec, role)
            system = SimSystem(scenario, seed, world, server, actors, trees, fault_log,
                               origin)
            system.memory_links = dict(zip(roles, memories, strict=True))
            nursery.start_soon(_watch_scheduled_actor_faults, system)
            if schedule:
                nursery.start_soon(send_scheduled_faults, server, schedule,
                                   lambda text: trace.emit(EventKind.FAULT, "attached",
                                                           detail=text))
            try:
                yield system
            finally:
                nursery.cancel_scope.cancel()
