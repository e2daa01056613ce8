"""Fault campaigns: many seeded games under random faults, invariants checked.

In the spirit of FoundationDB's simulation testing and TigerBeetle's VOPR:
game ``i`` of campaign ``S`` is a pure function of ``(S, i)`` and the
campaign's options, so every failure is reproducible from a short
reference, ``S:i[,key=value...]`` (see `CampaignConfig.game_ref`), which
``hideseek run --campaign REF`` accepts and plays with the same trace hash.

Planning (`plan_game`): ``numpy.random.default_rng([S, i])`` draws, in this
order, the game's run seed, then its fault schedule from the catalogue of
`FAULT_LABELS` (device faults of world/faults.py on a rover that has the
device, link faults, and crash/hang/flood on a firmware actor such as
``seeker/wifly``): exactly one fault per game in ``single`` mode, 0 to 3 in
``overlapping`` mode, none in ``none`` mode. Each fault has a start drawn in
the fault window and a duration (transient faults: permanent ones are what
docs/faults.md explains the system cannot survive). The room is a built-in
scenario chosen round-robin (its hide spot and guesses with it), or
``generate_scenario(S, i)``.

Playing (`play_campaign_game`, the worker entry point): a plain function of
strings and numbers returning a JSON-able dict, so a process pool here, or
Ray or Dask on a cluster (docs/scaling.md), can call it unchanged. It plays
the game exactly as `supervisors.harness.headless.run_game` does, with probes
attached that change nothing, then lets the system drain for a while and
checks the invariants of `supervisors.harness.invariants`.

Running (`run_campaign`): a pool of ``spawn`` worker processes, one per core
by default, handed the games longest expected first (`dispatch_order`) so
the workers finish together; results arrive in completion order, keyed by
index, and are summarised by `summarize` and stored by `CampaignStore`
(SQLite).

Like `supervisors.system` this is wiring: it reads ground truth (through
the system) only to check and score, never to steer.
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import os
import sqlite3
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trio

from actors import Trace, seed_trio_scheduler, virtual_clock
from server.store import Store, StoreError
from supervisors.harness import invariants as inv
from supervisors.harness.headless import Budget, GameReport, finish_report, play_game
from supervisors.system import open_sim_system
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_DEVICES
from world.params import ROLES
from world.scenario import (
    Scenario,
    ScenarioError,
    ScheduledFault,
    builtin_scenarios,
    generate_scenario,
    load_scenario,
)

__all__ = [
    "FAULT_LABELS", "MODES", "CampaignError", "CampaignConfig", "GameSpec", "plan_game",
    "parse_game_ref", "game_from_ref", "select_kinds", "play_campaign_game", "run_campaign",
    "summarize", "CampaignStore", "ACTORS_BY_ROLE", "default_workers", "MAX_GAMES",
    "seed_game_scheduler", "ROOM_CPU_S", "ORDER_BLOCK", "expected_cpu_s", "dispatch_order",
]

MODES = ("single", "overlapping", "none")
#: firmware actors per role (supervisors/rover.py registers them as ``role/name``)
ACTORS_BY_ROLE: dict[str, tuple[str, ...]] = {
    "mapper": ("nav", "motor", "wifly", "lidar", "map"),
    "hider": ("nav", "motor", "wifly"),
    "seeker": ("nav", "motor", "wifly", "ir"),
}
#: devices named without a side in the labels; the side is drawn ("" = both treads)
_SIDED = ("encoder", "motor")
#: every fault kind a campaign draws from: ``device:kind`` or ``actor:kind``
FAULT_LABELS: tuple[str, ...] = tuple(
    [f"{dev}:{kind}" for dev, kinds in DEVICE_FAULTS.items()
     if not dev.endswith(("_left", "_right")) for kind in kinds]
    + [f"actor:{kind}" for kind in ACTOR_FAULTS])

#: label -> (duration range [s], {parameter: (low, high)} drawn uniformly)
_DRAW: dict[str, tuple[tuple[float, float], dict[str, tuple[float, float]]]] = {
    "lidar:noisy": ((5.0, 30.0), {"sigma_cm": (5.0, 20.0)}),
    "encoder:slipping": ((2.0, 20.0), {"ratio": (0.3, 0.8)}),
    "motor:weak": ((2.0, 20.0), {"strength": (0.3, 0.8)}),
    "wifly:loss": ((5.0, 30.0), {"percent": (10.0, 50.0)}),
    "wifly:corrupt": ((5.0, 30.0), {"per_byte": (0.001, 0.02)}),
    "wifly:latency": ((5.0, 30.0), {"added_s": (0.1, 1.0)}),
    "actor:flood": ((0.0, 0.0), {"messages": (50.0, 500.0)}),
    "actor:crash": ((0.0, 0.0), {}),
    "actor:hang": ((2.0, 20.0), {}),
}
_DEFAULT_DRAW = ((2.0, 20.0), {})
_MAX_OVERLAP = 3            # faults at most per game in overlapping mode
_DRAIN_S = 30.0             # simulated time allowed after the game for in-flight frames [s]
_DRAIN_POLL_S = 0.5
MAX_GAMES = 1_000_000       # games per campaign at most


class CampaignError(ScenarioError):
    """Bad campaign options or game reference; the message is fit to show a user.

    A `ScenarioError` (so a `ValueError`): a game reference names a scenario.
    """


# ---------------------------------------------------------------------------- options

def select_kinds(text: str | None) -> tuple[str, ...]:
    """Fault labels chosen by a comma list (None or ``all``: every label).

    An item is a label (``wifly:loss``), a device or ``actor`` (every kind on
    it: ``wifly``), or a kind (``crash``, ``stuck``: on every device that has it).

    Raises:
        CampaignError: an item matches no label.
    """
    if text is None or text.strip() in ("", "all"):
        return FAULT_LABELS
    chosen: list[str] = []
    for item in (p.strip() for p in text.replace("+", ",").split(",")):
        if not item:
            continue
        hits = [lab for lab in FAULT_LABELS
                if item in (lab, lab.split(":")[0], lab.split(":")[1])]
        if not hits:
            raise CampaignError(f"unknown fault kind {item!r}; kinds are "
                                f"{', '.join(FAULT_LABELS)} (or a device, or 'actor')")
        chosen += [h for h in hits if h not in chosen]
    if not chosen:
        raise CampaignError(f"no fault kind chosen in {text!r}")
    return tuple(lab for lab in FAULT_LABELS if lab in chosen)


@dataclass(frozen=True, slots=True)
class CampaignConfig:
    """What determines a campaign's games, besides the game index."""

    seed: int
    mode: str = "single"
    """``single`` (one fault per game), ``overlapping`` (0..3) or ``none``."""
    kinds: tuple[str, ...] = FAULT_LABELS
    """Fault labels to draw from (`select_kinds`)."""
    rooms: tuple[str, ...] = ()
    """Built-in scenario names, round-robin (empty: every built-in)."""
    generated: bool = False
    """Procedural rooms (`generate_scenario(seed, i)`) instead of built-ins."""
    window_s: tuple[float, float] = (5.0, 240.0)
    """Simulated time range in which faults start [s]."""
    mapping_budget_s: float = 1200.0
    """Simulated time allowed for mapping [s] (as ``hideseek run --budget``)."""
    _builtins: tuple[str, ...] = field(default=(), init=False, repr=False, compare=False)
    """Every built-in room, read once here (reading them parses each file)."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise CampaignError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.mode not in MODES:
            raise CampaignError(f"mode must be {', '.join(MODES)}, got {self.mode!r}")
        bad = [k for k in self.kinds if k not in FAULT_LABELS]
        if bad or not self.kinds:
            raise CampaignError(f"fault kinds must be among {', '.join(FAULT_LABELS)}, "
                                f"got {', '.join(bad) or 'none'}")
        known = tuple(builtin_scenarios())
        object.__setattr__(self, "_builtins", known)  # frozen: set once, at construction
        for name in self.rooms:
            if name not in known:
                raise CampaignError(f"unknown built-in room {name!r}; rooms are "
                                    f"{', '.join(known)}")
        lo, hi = self.window_s
        if not 0 <= lo <= hi or not math.isfinite(hi):
            raise CampaignError(f"fault window must be 0 <= start <= end, got {lo}-{hi}")
        if not 0 < self.mapping_budget_s <= 1e6:
            raise CampaignError(f"mapping budget must be within (0, 1e6] s, "
                                f"got {self.mapping_budget_s!r}")

    def room_names(self) -> tuple[str, ...]:
        """The built-in rooms used, in round-robin order."""
        return self.rooms or self._builtins

    def budget(self) -> Budget:
        """Simulated-time budget of each game."""
        return Budget(mapping=self.mapping_budget_s)

    def game_ref(self, index: int) -> str:
        """``S:i`` plus every option that differs from the default: what reproduces game i."""
        parts = [f"{self.seed}:{index}"]
        default = CampaignConfig(0)
        if self.mode != default.mode:
            parts.append(f"mode={self.mode}")
        if self.generated:
            parts.append("rooms=generated")
        elif self.rooms:
            parts.append("rooms=" + "+".join(self.rooms))
        if self.kinds != default.kinds:
            parts.append("faults=" + "+".join(self.kinds))
        if self.window_s != default.window_s:
            parts.append(f"window={self.window_s[0]:g}-{self.window_s[1]:g}")
        if self.mapping_budget_s != default.mapping_budget_s:
            parts.append(f"budget={self.mapping_budget_s:g}")
        return ",".join(parts)


def parse_game_ref(text: str) -> tuple[CampaignConfig, int]:
    """Read a game reference ``S:i[,mode=..][,rooms=..][,faults=..][,window=A-B][,budget=..]``.

    Raises:
        CampaignError: malformed reference or bad option.
    """
    if not isinstance(text, str) or not text.strip():
        raise CampaignError("game reference must be S:i[,key=value...], got nothing")
    head, *options = text.strip().split(",")
    try:
        seed_s, index_s = head.split(":")
        seed, index = int(seed_s), int(index_s)
    except ValueError:
        raise CampaignError(f"game reference must start with SEED:INDEX, got {head!r}") from None
    if not 0 <= index < MAX_GAMES:
        raise CampaignError(f"game index must be within 0..{MAX_GAMES - 1}, got {index}")
    kw: dict[str, Any] = {}
    for opt in options:
        key, sep, value = opt.partition("=")
        if not sep:
            raise CampaignError(f"game reference option must be key=value, got {opt!r}")
        try:
            if key == "mode":
                kw["mode"] = value
            elif key == "rooms" and value == "generated":
                kw["generated"] = True
            elif key == "rooms":
                kw["rooms"] = tuple(v for v in value.split("+") if v)
            elif key == "faults":
                kw["kinds"] = select_kinds(value)
            elif key == "window":
                lo, hi = value.split("-")
                kw["window_s"] = (float(lo), float(hi))
            elif key == "budget":
                kw["mapping_budget_s"] = float(value)
            else:
                raise CampaignError(f"unknown game reference option {key!r} (options: mode, "
                                    "rooms, faults, window, budget)")
        except ValueError as exc:
            if isinstance(exc, CampaignError):
                raise
            raise CampaignError(f"bad game reference option {opt!r}: {exc}") from None
    return CampaignConfig(seed, **kw), index


# ---------------------------------------------------------------------------- planning

@dataclass(frozen=True, slots=True)
class GameSpec:
    """Everything that determines one campaign game (made by `plan_game`)."""

    config: CampaignConfig
    index: int
    run_seed: int
    """The seed the game runs with (world noise, actors, Trio's scheduling)."""
    room: str
    """A built-in scenario name, or ``generated``."""
    faults: tuple[ScheduledFault, ...]
    labels: tuple[str, ...]
    """The fault label of each fault, same order."""

    @property
    def ref(self) -> str:
        """The game reference (`CampaignConfig.game_ref`)."""
        return self.config.game_ref(self.index)

    @property
    def reproduce(self) -> str:
        """The command line that plays this game alone, with the same trace hash."""
        return f"hideseek run --campaign {self.ref}"

    def scenario(self) -> Scenario:
        """The room with this game's fault schedule."""
        base = (generate_scenario(self.config.seed, self.index) if self.room == "generated"
                else load_scenario(self.room))
        return dataclasses.replace(base, faults=tuple(sorted(
            base.faults + self.faults, key=lambda f: f.at_s)))


def _draw_fault(rng: np.random.Generator, label: str, window: tuple[float, float]
                ) -> ScheduledFault:
    device, kind = label.split(":")
    (d_lo, d_hi), ranges = _DRAW.get(label, _DEFAULT_DRAW)
    if device == "actor":
        role = ROLES[int(rng.integers(len(ROLES)))]
        names = ACTORS_BY_ROLE[role]
        target = f"{role}/{names[int(rng.integers(len(names)))]}"
    else:
        roles = ROLE_DEVICES.get(device, ROLES)
        role = roles[int(rng.integers(len(roles)))]
        side = ("", "_left", "_right")[int(rng.integers(3))] if device in _SIDED else ""
        target = f"{role}/{device}{side}"
    at = float(rng.uniform(*window))
    duration = float(rng.uniform(d_lo, d_hi)) if d_hi > 0 else 0.0
    params = {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in ranges.items()}
    if "messages" in params:
        params["messages"] = float(round(params["messages"]))
    return ScheduledFault(round(at, 3), target, kind, round(duration, 3),
                          {k: round(v, 4) for k, v in params.items()})


def plan_game(config: CampaignConfig, index: int) -> GameSpec:
    """Game ``index`` of the campaign: a pure function of (config, index).

    Raises:
        CampaignError: the index is out of range.
    """
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < MAX_GAMES:
        raise CampaignError(f"game index must be within 0..{MAX_GAMES - 1}, got {index!r}")
    rng = np.random.default_rng([config.seed, index])
    run_seed = int(rng.integers(1, 2**31 - 1))
    if config.mode == "single":
        n = 1
    elif config.mode == "overlapping":
        n = int(rng.integers(0, _MAX_OVERLAP + 1))
    else:
        n = 0
    labels = tuple(config.kinds[int(rng.integers(len(config.kinds)))] for _ in range(n))
    faults = tuple(_draw_fault(rng, lab, config.window_s) for lab in labels)
    if config.generated:
        room = "generated"
    else:
        names = config.room_names()
        room = names[index % len(names)]
    return GameSpec(config, index, run_seed, room, faults, labels)


def game_from_ref(ref: str) -> tuple[Scenario, int, float]:
    """What ``hideseek run --campaign REF`` plays: (scenario with faults, run seed, budget [s]).

    Raises:
        CampaignError: a bad reference (a `ScenarioError`, so ``hideseek run``
            reports it like any bad scenario).
    """
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    return spec.scenario(), spec.run_seed, config.mapping_budget_s


# ---------------------------------------------------------------------------- dispatch order

#: a game's expected CPU time per built-in room [s] (whole campaign game, one core; games of
#: campaigns 1 and 2 at commit f1f70c4, rounded: docs/scaling.md "Dispatch order"); only the
#: dispatch order reads it, so a stale figure costs the pool some balance at the end, never
#: a different result
ROOM_CPU_S: dict[str, float] = {
    "empty": 4.0, "corridor": 8.0, "round": 12.0, "gap": 12.0, "l_shaped": 12.0,
    "cluttered": 16.0, "furniture": 25.0, "hall": 30.0,
}
#: generated rooms (and rooms missing above): expected CPU time per m² of free floor [s]
#: (the built-in rooms' median; a generated campaign has only generated rooms, so only the
#: proportion to floor area matters)
_CPU_S_PER_FREE_M2 = 0.5
#: games ordered together; the blocks follow index order, so a campaign stopped early
#: (``--max-wall``) has played about a prefix of its games and planning stays bounded
ORDER_BLOCK = 64


def expected_cpu_s(spec: GameSpec, *, replayed: bool = False) -> float:
    """The game's expected CPU time [s], from what is known before it starts.

    The room decides most of it (a 4 x 3 m empty room maps in a minute of
    simulated time, a furnished one in up to ten), so built-in rooms use the
    measured `ROOM_CPU_S` and generated rooms their free floor area. A
    determinism replay plays the game twice. The figure only orders the
    dispatch: it never changes what a game does.
    """
    if spec.room in ROOM_CPU_S:
        cost = ROOM_CPU_S[spec.room]
    else:
        room = spec.scenario()
        width, height = room.room_size
        free_cm2 = width * height - sum(o.area for o in room.obstacles)
        cost = _CPU_S_PER_FREE_M2 * max(free_cm2, 0.0) / 1e4
    return 2.0 * cost if replayed else cost


def dispatch_order(config: CampaignConfig, start: int, games: int,
                   determinism_every: int = 0) -> Iterator[int]:
    """Game indices in the order a pool should start them: longest expected first.

    Games of one campaign differ tenfold in length, and a pool that starts
    them in index order can end with one worker playing a long game while
    the others idle. Longest-first (LPT) scheduling within blocks of
    `ORDER_BLOCK` games ends with the short ones, so the workers finish
    together. The first block takes the remainder, so the last block (whose
    end is the campaign's end) is always a full one. Results are keyed by
    index, so the order changes when a game finishes, never what it does.

    Yields:
        Each index of ``start .. start+games-1`` exactly once.
    """
    end = start + games
    first = start + (games % ORDER_BLOCK or ORDER_BLOCK)
    edges = [start, *range(first, end, ORDER_BLOCK), end]
    for lo, hi in zip(edges, edges[1:], strict=False):
        costs = {i: expected_cpu_s(plan_game(config, i), replayed=_replayed(i, determinism_every))
                 for i in range(lo, hi)}
        yield from sorted(costs, key=lambda i: (-costs[i], i))


def _replayed(index: int, determinism_every: int) -> bool:
    return bool(determinism_every) and index % determinism_every == 0


# ---------------------------------------------------------------------------- playing

def _actor_states(system: Any) -> dict[str, str]:
    out = {}
    for name in system.actors.names():
        cell = system.actors.whereis(name)
        if cell is not None:
            out[name] = str(cell.state.value)
    return out


def _all_running(system: Any) -> bool:
    return all(s == "running" for n, s in _actor_states(system).items() if "/" in n)


async def _drain(system: Any, probe: inv.DeliveryProbe, cut: float, limit_s: float) -> None:
    """Let in-flight frames land and restarting actors come back, up to ``limit_s`` [s]."""
    with trio.move_on_after(limit_s):
        while probe.pending(cut) or not _all_running(system):
            await trio.sleep(_DRAIN_POLL_S)


def _honesty(system: Any) -> list[inv.Violation]:
    roots: dict[str, Any] = {"server": system.server}
    allowed: dict[str, Any] = {"server": None}
    for name in system.actors.names():
        cell = system.actors.whereis(name)
        if cell is not None and cell.actor is not None and "/" in name:
            roots[name] = cell.actor
            hardware = system.world.hardware(name.split("/")[0])
            allowed[name] = (hardware, hardware.spec)
    return inv.check_honesty(roots, allowed) + inv.check_module_honesty()


async def play_checked(spec: GameSpec, *, trace: Trace | None = None,
                       drain_s: float = _DRAIN_S,
                       nav_factory: Callable[..., Any] | None = None
                       ) -> tuple[GameReport, dict[str, Any]]:
    """Play one campaign game with its probes; return the report and the checks.

    The game runs as `supervisors.harness.headless.run_game` runs it (same system,
    same driver, same report), so its trace hash is the one ``hideseek run``
    gives; the probes only copy bytes and count events.

    Args:
        spec: the game.
        trace: the trace hub (a new one by default).
        drain_s: simulated time allowed after the game for in-flight frames
            and restarting actors [s].
        nav_factory: tests only: a stand-in navigation for every rover (see
            `supervisors.rover.rover_tree`), e.g. one that breaks an invariant.

    Returns:
        (report, checks) where checks has ``violations`` (list of str),
        ``faults_fired`` and the event counts.
    """
    scenario = spec.scenario()
    report = GameReport(scenario.name, spec.run_seed)
    budget = spec.config.budget()
    with Store(":memory:") as store:
        async with open_sim_system(scenario, seed=spec.run_seed, store=store,
                                   trace=trace, nav_factory=nav_factory) as system:
            probe = inv.DeliveryProbe.install(system, trio.current_time)
            counts = inv.TraceCounts(system.actors.trace)
            t_start = trio.current_time()
            try:
                await play_game(system, report, budget)
            finally:
                finish_report(report, system, t_start)
            cut = trio.current_time()
            await _drain(system, probe, cut, drain_s)
            fired = len(system.faults)
            violations = (
                inv.check_ended(report.outcome, report.reason)
                + inv.check_actors_alive(_actor_states(system))
                + inv.check_no_escalation(counts.escalations, fired)
                + inv.check_exactly_once(probe.sent_and_delivered(cut))
                + inv.check_maps_equal(_stored_map(system, store), probe.uploaded_map())
                + _honesty(system)
                + [inv.Violation("harness.fault_refused", r) for r in counts.refused_faults])
            counts.close()
    checks = {"violations": [str(v) for v in violations], "faults_fired": fired,
              "events": dict(counts.counts), "escalations": list(counts.escalations)}
    return report, checks


def _stored_map(system: Any, store: Store) -> Any:
    try:
        return store.latest_map_of_game(system.server.game_id)
    except StoreError:
        return None


def seed_game_scheduler(seed: int) -> None:
    """Make Trio's task order a function of ``seed`` alone (call before ``trio.run``).

    The campaign's name for `actors.seed_trio_scheduler`, which seeds the shuffle
    of each batch of runnable tasks and turns on Trio's deterministic batch order
    (without it, deadline ties are broken by ``id()``, so a second game in the
    same pool worker played differently: measured, three runs of one seed in one
    process gave three trace hashes). Campaign games and ``hideseek run
    --campaign`` both use it.
    """
    seed_trio_scheduler(seed)


#: a play blocked without computing is stopped after this many times its CPU guard in wall time
WALL_GUARD_FACTOR = 10.0
_GUARD_POLL_S = 0.5          # how often the guard looks at the clocks [wall s]


class _Guard:
    """Cancels a Trio run once it used ``cpu_s`` of CPU time, or ``factor x cpu_s`` of wall time.

    CPU time, because on a loaded machine a healthy game can take ten times
    its CPU time in wall time (measured: a furniture game of 24 CPU s took
    over 600 wall s at load 12), while a game that loops forever burns CPU;
    the wall-time bound catches a game blocked without computing. An
    operational limit of the harness (a thread polling the clocks), not part
    of the simulation: it never fires in a healthy game.
    """

    def __init__(self, cpu_s: float, token: trio.lowlevel.TrioToken,
                 cancel: Callable[[], None], factor: float = WALL_GUARD_FACTOR) -> None:
        self.cpu_s, self.wall_s = cpu_s, factor * cpu_s
        self.fired = ""
        self._token, self._cancel = token, cancel
        self._stop = threading.Event()
        self._cpu0, self._wall0 = time.process_time(), time.perf_counter()
        self._thread = threading.Thread(target=self._watch, name="campaign-guard", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.wait(min(_GUARD_POLL_S, self.cpu_s)):
            cpu = time.process_time() - self._cpu0
            wall = time.perf_counter() - self._wall0
            if cpu >= self.cpu_s or wall >= self.wall_s:
                self.fired = (f"{cpu:.0f} CPU s of {self.cpu_s:g}" if cpu >= self.cpu_s
                              else f"{wall:.0f} wall s of {self.wall_s:g}")
                try:
                    self._token.run_sync_soon(self._cancel)
                except trio.RunFinishedError:
                    pass
                return

    def stop(self) -> None:
        """Stop watching (the run is over)."""
        self._stop.set()
        self._thread.join(timeout=5.0)


def _run_one(spec: GameSpec, wall_timeout_s: float | None,
             nav_factory: Callable[..., Any] | None = None) -> tuple[GameReport, dict]:
    """Play a game in a fresh Trio run on a virtual clock, cancelled by a `_Guard`."""
    seed_game_scheduler(spec.run_seed)
    guards: list[_Guard] = []

    async def main() -> tuple[GameReport, dict]:
        with trio.CancelScope() as scope:
            if wall_timeout_s is not None:
                guards.append(_Guard(wall_timeout_s, trio.lowlevel.current_trio_token(),
                                     scope.cancel))
            return await play_checked(spec, nav_factory=nav_factory)
        raise TimeoutError("game stopped by the guard after "
                           + (guards[0].fired if guards else "a cancellation"))

    try:
        return trio.run(main, clock=virtual_clock())
    finally:
        for guard in guards:
            guard.stop()


def play_campaign_game(ref: str, *, determinism: bool = False,
                       wall_timeout_s: float | None = None,
                       baseline: bool = True,
                       nav_factory: Callable[..., Any] | None = None) -> dict[str, Any]:
    """The worker entry point: play game ``ref`` and return its result as a JSON-able dict.

    Plain and pickleable (module-level, strings and numbers in, a dict of
    JSON types out), so a process pool, Ray (``ray.remote(play_campaign_game)``)
    or Dask (``client.submit``) can call it unchanged. It never raises for a
    game that goes wrong: the exception becomes a ``harness.exception``
    violation.

    Args:
        ref: the game reference ``S:i[,key=value...]`` (`CampaignConfig.game_ref`).
        determinism: play the game a second time and compare trace hashes.
        wall_timeout_s: guard per play [s]: a play is stopped once it used
            this much CPU time, or `WALL_GUARD_FACTOR` times this much wall
            time (blocked without computing); an operational limit, not part
            of the simulation, that a healthy game never reaches (the longest
            take about 35 CPU s). None for none.
        baseline: when the game fails and had faults, play it again without
            them, so the failure list tells fault-caused failures from others.
        nav_factory: tests only (in-process): a stand-in navigation, e.g. a
            nondeterministic one that the determinism check must catch.

    Returns:
        ``index``, ``ref``, ``reproduce``, ``room``, ``run_seed``, ``faults``
        (target/kind/at_s/duration_s/label each), ``outcome``, ``reason``,
        ``violations`` (``name: detail`` strings), ``faults_fired``,
        ``restarts``, ``resent``, ``dropped``, ``sim_s``, ``wall_s``, ``cpu_s``
        (this process's CPU time for the game, replays included [s]),
        ``trace_hash``, ``replay_hash`` (None unless replayed), ``events``,
        ``baseline`` (outcome without the faults, or None when not played),
        ``baseline_violations`` (the invariants that broke without the
        faults: a failure whose violation repeats without them is the game's,
        not fault recovery's).

    Raises:
        CampaignError: ``ref`` is not a valid game reference.
    """
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    out: dict[str, Any] = {
        "index": index, "ref": spec.ref, "reproduce": spec.reproduce, "room": spec.room,
        "run_seed": spec.run_seed,
        "faults": [{"label": lab, "target": f.target, "kind": f.kind, "at_s": f.at_s,
                    "duration_s": f.duration_s, "params": dict(f.params)}
                   for lab, f in zip(spec.labels, spec.faults, strict=True)],
        "outcome": "failed", "reason": "", "violations": [], "faults_fired": 0,
        "restarts": 0, "resent": 0, "dropped": 0, "sim_s": 0.0, "wall_s": 0.0, "cpu_s": 0.0,
        "trace_hash": "", "replay_hash": None, "events": {}, "baseline": None,
        "baseline_violations": [], "wider_search": False, "hide_attempts": 0,
    }
    wall0 = time.perf_counter()  # wall and CPU time are measured for the report only
    cpu0 = time.process_time()
    try:
        report, checks = _run_one(spec, wall_timeout_s, nav_factory)
        out.update(outcome=report.outcome, reason=report.reason, restarts=report.restarts,
                   resent=report.resent, dropped=report.dropped, sim_s=report.sim_seconds,
                   trace_hash=report.trace_hash, violations=checks["violations"],
                   faults_fired=checks["faults_fired"], events=checks["events"],
                   wider_search=report.wider_search, hide_attempts=report.hide_attempts)
        if determinism:
            again, _ = _run_one(spec, wall_timeout_s, nav_factory)
            out["replay_hash"] = again.trace_hash
            out["violations"] += [
                f"{v} (replay: {again.outcome} after {again.sim_seconds:.1f} s, "
                f"first: {report.outcome} after {report.sim_seconds:.1f} s)"
                for v in inv.check_determinism(report.trace_hash, again.trace_hash)]
        if baseline and spec.faults and (out["violations"] or out["outcome"] != "found"):
            calm, calm_checks = _run_one(dataclasses.replace(spec, faults=(), labels=()),
                                         wall_timeout_s, nav_factory)
            out["baseline"] = calm.outcome
            out["baseline_violations"] = calm_checks["violations"]
    except Exception as group:  # noqa: BLE001 - a broken game is a result, not a crash
        exc = _leaf(group)
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" at {last[0].filename.rsplit('/', 2)[-1]}:{last[0].lineno}" if last else ""
        out["violations"] = [f"harness.exception: {type(exc).__name__}: {exc}{where}"]
        out["reason"] = out["reason"] or f"{type(exc).__name__}: {exc}"
    out["wall_s"] = time.perf_counter() - wall0
    out["cpu_s"] = time.process_time() - cpu0
    return out


def _leaf(exc: BaseException) -> BaseException:
    """The first real exception inside nested exception groups (what a user needs to see)."""
    while isinstance(exc, BaseExceptionGroup) and exc.exceptions:
        exc = exc.exceptions[0]
    return exc


# ---------------------------------------------------------------------------- running

def _call(job: tuple[Callable[..., dict], str, bool, float | None]) -> dict[str, Any]:
    worker, ref, determinism, wall_timeout_s = job
    return worker(ref, determinism=determinism, wall_timeout_s=wall_timeout_s)


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def run_campaign(config: CampaignConfig, games: int, *, workers: int | None = None,
                 worker: Callable[..., dict[str, Any]] = play_campaign_game,
                 determinism_every: int = 10, wall_timeout_s: float | None = 600.0,
                 start: int = 0, pool: Any = None) -> Iterator[dict[str, Any]]:
    """Play games ``start .. start+games-1`` of a campaign; yield results as they finish.

    A pool gets the games in `dispatch_order` (longest expected first, in
    blocks); in this process they are played in index order. Either way each
    game is played once and its result carries its ``index``.

    Args:
        config: the campaign.
        games: how many games (1..`MAX_GAMES`).
        workers: worker processes (default: one per core); 0 plays in this
            process (debugging, tests).
        worker: the entry point (`play_campaign_game`; tests pass stand-ins,
            which must be module-level functions for the ``spawn`` pool).
        determinism_every: replay every n-th game to compare trace hashes
            (0: never).
        wall_timeout_s: guard per play [s] (see `play_campaign_game`).
        start: index of the first game.
        pool: an already started ``multiprocessing`` pool to use (``workers``
            is then ignored); benchmarks pass a warmed-up one.

    Raises:
        CampaignError: a bad count.
    """
    if isinstance(games, bool) or not isinstance(games, int) or not 1 <= games <= MAX_GAMES:
        raise CampaignError(f"games must be within 1..{MAX_GAMES}, got {games!r}")
    if workers is not None and (not isinstance(workers, int) or not 0 <= workers <= 256):
        raise CampaignError(f"workers must be within 0..256, got {workers!r}")
    if not isinstance(determinism_every, int) or determinism_every < 0:
        raise CampaignError(f"determinism_every must be >= 0, got {determinism_every!r}")
    n = default_workers() if workers is None else workers
    if pool is None and n == 0:  # in this process: index order, easiest to follow
        for i in range(start, start + games):
            yield _call((worker, config.game_ref(i), _replayed(i, determinism_every),
                         wall_timeout_s))
        return
    jobs = ((worker, config.game_ref(i), _replayed(i, determinism_every), wall_timeout_s)
            for i in dispatch_order(config, start, games, determinism_every))
    if pool is not None:
        yield from pool.imap_unordered(_call, jobs, chunksize=1)
        return
    ctx = multiprocessing.get_context("spawn")
    # recycle workers now and then: a game stopped by its guard may leave garbage
    with ctx.Pool(min(n, games), maxtasksperchild=100) as pool:
        yield from pool.imap_unordered(_call, jobs, chunksize=1)


# ---------------------------------------------------------------------------- summary

def _failed(r: dict[str, Any]) -> bool:
    return r["outcome"] != "found" or bool(r["violations"])


def _cause(r: dict[str, Any]) -> str | None:
    """Whose failure a failed game is: ``faults``, ``game``, or None (not known).

    ``game`` when it fails without faults too (it had none, or its replay
    without them also failed or broke an invariant), ``faults`` when that
    replay found the hider with every invariant kept; None when no replay
    was played (``baseline=False``) or the game did not fail.
    """
    if not _failed(r):
        return None
    if not r["faults"]:
        return "game"
    if r.get("baseline") is None:
        return None
    return "faults" if r["baseline"] == "found" and not r.get("baseline_violations") else "game"


def summarize(config: CampaignConfig, results: list[dict[str, Any]], *,
              wall_s: float, workers: int) -> dict[str, Any]:
    """The campaign's JSON summary (what ``hideseek campaign --json`` prints).

    A game counts as a failure when the hider was not found or an invariant
    broke; per fault label, a fault is *injected* when its start came before
    the game ended, *recovered* when such a game did not fail. Each failure
    says whose it is (``cause``: ``faults``, ``game`` or None, see `_cause`),
    from the replay of the game without its faults.
    """
    results = sorted(results, key=lambda r: r["index"])
    outcomes = Counter(r["outcome"] for r in results)
    per_kind: dict[str, Counter] = {}
    for r in results:
        for f in r["faults"]:
            c = per_kind.setdefault(f["label"], Counter())
            if f["at_s"] > r["sim_s"] + 1e-9 and r["outcome"] != "failed":
                c["not_reached"] += 1  # the game was over before the fault's start
                continue
            c["injected"] += 1
            c["failed" if _failed(r) else "recovered"] += 1
    violated = Counter(v.split(":", 1)[0] for r in results for v in r["violations"])
    replayed = [r for r in results if r["replay_hash"] is not None]
    games = len(results)
    return {
        "campaign": {"seed": config.seed, "mode": config.mode, "kinds": list(config.kinds),
                     "rooms": "generated" if config.generated else list(config.room_names()),
                     "window_s": list(config.window_s)},
        "games": games,
        "found": outcomes.get("found", 0),
        "not_found": outcomes.get("not_found", 0),
        "failed": outcomes.get("failed", 0),
        "games_with_violations": sum(1 for r in results if r["violations"]),
        "success_rate": (sum(1 for r in results if not _failed(r)) / games) if games else 0.0,
        "found_rate": (outcomes.get("found", 0) / games) if games else 0.0,
        "found_by_wider_search": sum(1 for r in results
                                     if r["outcome"] == "found" and r.get("wider_search")),
        "found_after_second_hide": sum(1 for r in results if r["outcome"] == "found"
                                       and r.get("hide_attempts", 0) > 1),
        "fault_kinds": {k: {"injected": c["injected"], "recovered": c["recovered"],
                            "failed": c["failed"], "not_reached": c["not_reached"]}
                        for k, c in sorted(per_kind.items())},
        "violations": dict(sorted(violated.items())),
        "failures_also_without_faults": sum(1 for r in results if _cause(r) == "game"),
        "failures_by_cause": dict(sorted(Counter(_cause(r) or "unknown" for r in results
                                                 if _failed(r)).items())),
        "restarts": sum(r["restarts"] for r in results),
        "resent": sum(r["resent"] for r in results),
        "dropped": sum(r["dropped"] for r in results),
        "sim_s": round(sum(r["sim_s"] for r in results), 1),
        "determinism": {"replayed": len(replayed),
                        "mismatched": sum(1 for r in replayed
                                          if r["replay_hash"] != r["trace_hash"])},
        "workers": workers,
        "wall_s": round(wall_s, 2),
        "games_per_wall_minute": round(60.0 * games / wall_s, 2) if wall_s > 0 else None,
        "failures": [{"index": r["index"], "room": r["room"], "outcome": r["outcome"],
                      "reason": r["reason"], "violations": r["violations"],
                      "faults": [f"{f['target']} {f['kind']} at {f['at_s']:g} s for "
                                 f"{f['duration_s']:g} s" for f in r["faults"]],
                      "without_faults": r.get("baseline"),
                      "without_faults_violations": r.get("baseline_violations", []),
                      "cause": _cause(r),
                      "reproduce": r["reproduce"]}
                     for r in results if _failed(r)],
    }


# ---------------------------------------------------------------------------- storage

_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaigns (
    id INTEGER PRIMARY KEY, seed INTEGER NOT NULL, config TEXT NOT NULL,
    started REAL NOT NULL, summary TEXT
);
CREATE TABLE IF NOT EXISTS campaign_games (
    campaign INTEGER NOT NULL REFERENCES campaigns(id), idx INTEGER NOT NULL,
    ref TEXT NOT NULL, room TEXT NOT NULL, outcome TEXT NOT NULL, reason TEXT NOT NULL,
    violations TEXT NOT NULL, faults TEXT NOT NULL, restarts INTEGER NOT NULL,
    resent INTEGER NOT NULL, sim_s REAL NOT NULL, wall_s REAL NOT NULL,
    trace_hash TEXT NOT NULL, replay_hash TEXT,
    PRIMARY KEY (campaign, idx)
);
"""


class CampaignStore:
    """Campaign results in SQLite: one row per campaign, one per game (committed as they come).

    Its own tables, in its own file by default, beside (not inside) the
    server's game store.
    """

    def __init__(self, path: str) -> None:
        try:
            self._db = sqlite3.connect(path)
            self._db.executescript(_SCHEMA)
        except sqlite3.Error as exc:
            raise CampaignError(f"cannot open campaign store {path!r}: {exc}") from None

    def __enter__(self) -> CampaignStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Commit and close."""
        self._db.commit()
        self._db.close()

    def new_campaign(self, config: CampaignConfig, started: float) -> int:
        """A campaign row; ``started`` is the wall time it began [s since the epoch]."""
        cfg = json.dumps({k: v for k, v in dataclasses.asdict(config).items()
                          if not k.startswith("_")})
        cur = self._db.execute("INSERT INTO campaigns (seed, config, started) VALUES (?, ?, ?)",
                               (config.seed, cfg, started))
        self._db.commit()
        return int(cur.lastrowid)

    def add_game(self, campaign: int, r: dict[str, Any]) -> None:
        """Store one game's result (as returned by `play_campaign_game`)."""
        self._db.execute(
            "INSERT OR REPLACE INTO campaign_games VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (campaign, r["index"], r["ref"], r["room"], r["outcome"], r["reason"],
             json.dumps(r["violations"]), json.dumps(r["faults"]), r["restarts"], r["resent"],
             r["sim_s"], r["wall_s"], r["trace_hash"], r["replay_hash"]))
        self._db.commit()

    def finish(self, campaign: int, summary: dict[str, Any]) -> None:
        """Attach the summary to the campaign row."""
        self._db.execute("UPDATE campaigns SET summary = ? WHERE id = ?",
                         (json.dumps(summary), campaign))
        self._db.commit()

    def games(self, campaign: int) -> list[tuple]:
        """(idx, outcome, violations JSON, trace_hash) per stored game, by index."""
        return self._db.execute("SELECT idx, outcome, violations, trace_hash FROM "
                                "campaign_games WHERE campaign = ? ORDER BY idx",
                                (campaign,)).fetchall()
