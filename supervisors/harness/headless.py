"""A whole game without a person: the scenario's choices stand in for the operator.

`play_game` drives a running `SimSystem` through the game flow of DESIGN.md
section 6 (start mapping, wait for the mapper's own completion, hide at the
scenario's spot, seek at each guess in turn) and scores it with the metrics of
section 8. Where a person would try again, it does: a hider that cannot hide is
sent once more (`Budget.hide_attempts`); when every guess came back ``not_found``,
one wider search round the last guess (``seek ... within=``
`Budget.wider_within_cm`), counted in ``GameReport.wider_search``. `run_game`
opens the system, plays, and returns a `GameReport`; it is a plain function of
(scenario, seed), so a campaign worker can call it.

Like `supervisors.system`, this is wiring: it reads ground truth, but only to
score the game (coverage, accuracy, path length), never to steer it.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import trio

from actors import Trace
from server.store import Store
from supervisors.system import SimSystem, open_sim_system
from world.metrics import CoverageProbe, accuracy, coverage, path_length, t90, t99
from world.params import ROLES
from world.scenario import Scenario
from world.truth import truth_raster

__all__ = ["Budget", "GameReport", "RunObserver", "finish_report", "play_game", "run_game"]

_PROBE_S = 1.0  # how often coverage and the mapper's true pose are sampled [s]
_HELLO_TIMEOUT_S = 30.0


@dataclass(frozen=True, slots=True)
class Budget:
    """Simulated-time limits per phase [s]; a phase that overruns fails the game."""

    hello: float = _HELLO_TIMEOUT_S
    mapping: float = 1200.0
    hiding: float = 600.0
    seeking: float = 600.0  #: per guess
    hide_attempts: int = 2
    """Times the operator sends the hider to its spot when it answers that it cannot get
    there (the hider plans again from where it stands, its count of blocks afresh)."""
    wider_within_cm: float | None = 120.0
    """The wider search after the last guess failed: the hider believed within this of
    it [cm] (None: no wider search, the game ends ``not_found``)."""
    wider_seeking: float = 1200.0  #: for the wider search, which looks from many more points


@dataclass
class GameReport:
    """What `hideseek run --json` prints (DESIGN.md section 8 metrics)."""

    scenario: str
    seed: int
    outcome: str = "failed"  #: found / not_found / failed
    reason: str = ""
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    real_time_factor: float = 0.0
    coverage: float | None = None
    accuracy: float | None = None
    t90_s: float | None = None
    t99_s: float | None = None
    path_cm: float = 0.0
    phases: dict[str, float] = field(default_factory=dict)
    hide_attempts: int = 0
    guesses: int = 0
    wider_search: bool = False
    """Every guess failed and the operator's wider search round the last one ran."""
    restarts: int = 0
    faults: int = 0
    dropped: int = 0
    resent: int = 0
    messages: int = 0
    trace_hash: str = ""
    events: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The JSON object of ``--json`` (events left out: they go to the trace)."""
        d = asdict(self)
        d.pop("events")
        return d


class RunObserver(Protocol):
    """Watches a `run_game` (a recorder, a fork's checker). Both calls are synchronous:
    an observer must not add tasks or wait, so the game it watches is the same game."""

    def started(self, system: SimSystem) -> None:
        """The system is open, the game not begun."""

    def finished(self, system: SimSystem, report: GameReport) -> None:
        """The game is over (or failed, or was cancelled); ``report`` is filled in."""


class _Phases:
    """Waits for the server's game to reach a phase, logging what happens meanwhile."""

    def __init__(self, system: SimSystem) -> None:
        self._game = system.server.game
        self._events = system.server.subscribe()
        self.log: list[str] = []

    @property
    def phase(self) -> str:
        return str(self._game.phase)

    @property
    def reason(self) -> str:
        return self._game.last_reason

    async def until(self, wanted: set[str], timeout: float) -> str | None:
        """Wait until the game's phase is one of ``wanted``; None on timeout.

        The game object is the truth (read after every server event), so a
        phase reached before this call is seen at once.
        """
        with trio.move_on_after(timeout):
            while self.phase not in wanted:
                self._note(await self._events.receive())
            self._drain()
            return self.phase
        self._drain()
        return None

    def _note(self, event: Any) -> None:
        if event.kind in ("phase", "report", "refused", "map", "link_down", "link_up"):
            self.log.append(event.format())

    def _drain(self) -> None:
        """Log the events already queued: the phase is read from the game, which may
        be ahead of its events (the report that ended the game), and they belong in
        the log. Never waits, so the run's scheduling does not change."""
        while True:
            try:
                self._note(self._events.receive_nowait())
            except trio.WouldBlock:
                return


async def _wait_for_rovers(system: SimSystem, timeout: float) -> bool:
    with trio.move_on_after(timeout):
        while len(system.server.snapshot().rovers) < 3:
            await trio.sleep(0.1)
        return True
    return False


async def _probe(system: SimSystem, series: list[tuple[float, float]],
                 poses: list[tuple[float, float]], truth: Any) -> None:
    """Sample coverage of the mapper's working map and its true path (metrics only)."""
    probe = CoverageProbe(system.scenario.starts["mapper"], truth)
    t0 = trio.current_time()
    while True:
        p = system.world.true_pose("mapper")
        poses.append((p.x, p.y))
        grid = system.mapper_grid()
        if grid is not None:
            series.append((trio.current_time() - t0,
                           probe(grid.cells, grid.resolution_cm, grid.origin_cm)))
        await trio.sleep(_PROBE_S)


async def play_game(system: SimSystem, report: GameReport, budget: Budget) -> None:
    """Play the scenario's game on ``system``, filling ``report``."""
    scenario = system.scenario
    phases = _Phases(system)
    report.events = phases.log
    truth = truth_raster(scenario)
    series: list[tuple[float, float]] = []
    poses: list[tuple[float, float]] = []

    def fail(why: str) -> None:
        report.outcome, report.reason = "failed", why

    if not await _wait_for_rovers(system, budget.hello):
        return fail("not every rover said hello")
    async with trio.open_nursery() as probes:
        probes.start_soon(_probe, system, series, poses, truth)
        t = trio.current_time()
        result = await system.command("start_mapping")
        if not result.ok:
            return fail(f"start_mapping refused: {result.reason}")
        got = await phases.until({"map_ready"}, budget.mapping)
        report.phases["mapping"] = trio.current_time() - t
        probes.cancel_scope.cancel()
    if got is None:
        return fail(f"mapping did not finish within {budget.mapping:.0f} s")
    report.path_cm = path_length(poses)
    report.t90_s, report.t99_s = t90(series), t99(series)
    grid = system.server.game.map
    if grid is not None:
        start = scenario.starts["mapper"]
        report.coverage = coverage(grid.cells, grid.resolution_cm, grid.origin_cm, start, truth)
        world = system.world
        bodies = [(world.true_pose(role), world.params.length_cm, world.params.width_cm)
                  for role in ROLES]
        report.accuracy = accuracy(grid.cells, grid.resolution_cm, grid.origin_cm, start, truth,
                                   bodies)
    if scenario.hide_at is None:
        return fail("the scenario has no [game] hide_at")
    hide = scenario.hide_at
    t = trio.current_time()
    got = None
    while got != "hidden" and report.hide_attempts < budget.hide_attempts:
        report.hide_attempts += 1
        result = await system.command("hide", x=hide.x, y=hide.y, heading=hide.heading_deg,
                                      frame="room")
        if not result.ok:
            return fail(f"hide refused: {result.reason}")
        got = await phases.until({"hidden", "map_ready"}, budget.hiding)
        if got is None:
            break  # a hider that does not answer is not asked again
    report.phases["hiding"] = trio.current_time() - t
    if got != "hidden":
        return fail(f"hider did not hide: {phases.reason or 'timeout'}")
    t = trio.current_time()
    report.outcome = "not_found"
    guesses: list[tuple[float, float, float | None]] = [(x, y, None) for x, y in scenario.seek_at]
    if guesses and budget.wider_within_cm is not None:
        guesses.append((*guesses[-1][:2], budget.wider_within_cm))
    for x, y, within in guesses:
        report.guesses += 1
        extra = {} if within is None else {"within": within}
        report.wider_search = within is not None
        result = await system.command("seek", x=x, y=y, frame="room", **extra)
        if not result.ok:
            return fail(f"seek refused: {result.reason}")
        limit = budget.seeking if within is None else budget.wider_seeking
        got = await phases.until({"found", "not_found"}, limit)
        if got is None:
            report.phases["seeking"] = trio.current_time() - t
            return fail(f"seeker did not report within {limit:.0f} s")
        if got == "found":
            report.outcome = "found"
            break
    report.phases["seeking"] = trio.current_time() - t


def _game_hash(runtime_hash: str, report: GameReport) -> str:
    """The run's fingerprint: the runtime trace (lifecycle, faults, drops) plus the
    game's event log with its virtual timestamps and the message counters, so two
    runs of one seed match only if they played the same game, event for event."""
    h = hashlib.blake2b(runtime_hash.encode(), digest_size=16)
    for line in report.events:
        h.update(line.encode() + b"\n")
    h.update(f"{report.messages}|{report.dropped}|{report.restarts}|{report.resent}".encode())
    h.update(f"|{report.sim_seconds!r}|{report.coverage!r}|{report.accuracy!r}".encode())
    return h.hexdigest()


def finish_report(report: GameReport, system: SimSystem, t_start: float) -> None:
    """Fill the report's counters from ``system`` at the end of a game (also used by
    campaign workers, which play the game with their probes installed)."""
    report.sim_seconds = trio.current_time() - t_start
    report.restarts = system.restarts()
    report.faults = len(system.faults)
    report.dropped = system.dropped()
    report.resent = system.resent()
    report.messages = system.messages()
    for key in ("coverage", "accuracy"):
        v = getattr(report, key)
        if v is not None and not math.isfinite(v):
            setattr(report, key, None)
    report.trace_hash = _game_hash(system.actors.trace.hexdigest(), report)


async def run_game(scenario: Scenario, seed: int, *, db: str = ":memory:",
                   budget: Budget | None = None, trace: Trace | None = None,
                   observers: Sequence[RunObserver] = ()) -> GameReport:
    """Open a simulated system for ``scenario`` and ``seed``, play it, return the report.

    Run it under a virtual clock (`actors.virtual_clock`) to go as fast as the CPU allows.
    ``observers`` are told when the system is open and when the game is over (also
    when it failed or was cancelled).
    """
    report = GameReport(scenario.name, seed)
    budget = budget or Budget()
    with Store(db) as store:
        async with open_sim_system(scenario, seed=seed, store=store, trace=trace) as system:
            t_start = trio.current_time()
            for observer in observers:
                observer.started(system)
            try:
                await play_game(system, report, budget)
            finally:
                finish_report(report, system, t_start)
                for observer in observers:
                    observer.finished(system, report)
    return report
