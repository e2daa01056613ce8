"""Playing one campaign game: probes attached, invariants checked, a guard on its time.

`play_campaign_game` is the worker entry point: a plain function of strings
and numbers returning a JSON-able dict, so the local process pool and Ray
(`supervisors.harness.campaign.cluster`) call it unchanged. It plays the game
exactly as `supervisors.harness.headless.run_game` does, with probes attached
that change nothing, then lets the system drain for a while and checks the
invariants of `supervisors.harness.invariants`.

Like `supervisors.system` this is wiring: it reads ground truth (through the
system) only to check and score, never to steer.
"""

from __future__ import annotations

import dataclasses
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import trio

from actors import Trace, running, seed_trio_scheduler, virtual_clock
from server.store import Store, StoreError
from supervisors.harness import invariants as inv
from supervisors.harness.campaign.plan import GameSpec, plan_game
from supervisors.harness.campaign.refs import parse_game_ref
from supervisors.harness.headless import Budget, GameReport, finish_report, play_game
from supervisors.system import open_sim_system
from world.scenario import Scenario

_DRAIN_S = 30.0             # simulated time allowed after the game for in-flight frames [s]
_DRAIN_POLL_S = 0.5


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

    `play_checked_scenario` with the game's room and faults, run seed and budget.
    """
    return await play_checked_scenario(spec.scenario(), spec.run_seed, spec.config.budget(),
                                       trace=trace, drain_s=drain_s, nav_factory=nav_factory)


async def play_checked_scenario(scenario: Scenario, run_seed: int, budget: Budget, *,
                                trace: Trace | None = None, drain_s: float = _DRAIN_S,
                                nav_factory: Callable[..., Any] | None = None
                                ) -> tuple[GameReport, dict[str, Any]]:
    """Play a scenario (faults included) with the campaign's probes; return report and checks.

    The game runs as `supervisors.harness.headless.run_game` runs it (same system,
    same driver, same report), so its trace hash is the one ``hideseek run``
    gives; the probes only copy bytes and count events.

    Args:
        scenario: the room with its fault schedule.
        run_seed: the seed the game runs with.
        budget: the simulated-time limits.
        trace: the trace hub (a new one by default).
        drain_s: simulated time allowed after the game for in-flight frames
            and restarting actors [s].
        nav_factory: tests only: a stand-in navigation for every rover (see
            `supervisors.rover.rover_tree`), e.g. one that breaks an invariant.

    Returns:
        (report, checks) where checks has ``violations`` (list of str),
        ``faults_fired``, the event counts and ``passages`` (per rover: entries
        into the room's narrow passages, `world.passages.PassageCounter.summary`).
    """
    report = GameReport(scenario.name, run_seed)
    with Store(":memory:") as store:
        async with open_sim_system(scenario, seed=run_seed, store=store,
                                   trace=trace, nav_factory=nav_factory) as system:
            probe = inv.DeliveryProbe.install(system, trio.current_time)
            founds = inv.FoundProbe.install(system)
            passages = inv.install_passage_counter(system)
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
                + inv.check_found_is_true(report.outcome, founds.founds)
                + inv.check_actors_alive(_actor_states(system))
                + inv.check_no_escalation(counts.escalations, fired)
                + inv.check_exactly_once(probe.sent_and_delivered(cut))
                + inv.check_maps_equal(_stored_map(system, store), probe.uploaded_map())
                + _honesty(system)
                + [inv.Violation("harness.fault_refused", r) for r in counts.refused_faults])
            counts.close()
    checks = {"violations": [str(v) for v in violations], "faults_fired": fired,
              "events": dict(counts.counts), "escalations": list(counts.escalations),
              "passages": passages.summary()}
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
    """Play a campaign game in a fresh Trio run (`run_checked`)."""
    return run_checked(spec.scenario(), spec.run_seed, spec.config.budget(), wall_timeout_s,
                       nav_factory)


def run_checked(scenario: Scenario, run_seed: int, budget: Budget,
                wall_timeout_s: float | None,
                nav_factory: Callable[..., Any] | None = None
                ) -> tuple[GameReport, dict[str, Any]]:
    """Play a scenario in a fresh Trio run on a virtual clock, cancelled by a `_Guard`.

    Trio's scheduling is seeded from ``run_seed`` first (`seed_game_scheduler`),
    so the same arguments give the same game (trace hash) in any process.

    Raises:
        TimeoutError: the guard stopped the play (``wall_timeout_s``, see
            `play_campaign_game`); anything the game raised.
    """
    seed_game_scheduler(run_seed)
    guards: list[_Guard] = []

    async def main() -> tuple[GameReport, dict]:
        with trio.CancelScope() as scope:
            if wall_timeout_s is not None:
                guards.append(_Guard(wall_timeout_s, trio.lowlevel.current_trio_token(),
                                     scope.cancel))
            return await play_checked_scenario(scenario, run_seed, budget,
                                               nav_factory=nav_factory)
        raise TimeoutError("game stopped by the guard after "
                           + (guards[0].fired if guards else "a cancellation"))

    try:
        return running.run(main, clock=virtual_clock())
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
        ``passages`` (per rover: ``entries`` into the room's narrow passages,
        ``through``, ``back``, ``inside`` at the end),
        ``baseline`` (outcome without the faults, or None when not played),
        ``baseline_violations`` (the invariants that broke without the
        faults: a failure whose violation repeats without them is the game's,
        not fault recovery's).

    Raises:
        CampaignError: ``ref`` is not a valid game reference.
    """
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    out = _blank_result(spec)
    wall0 = time.perf_counter()  # wall and CPU time are measured for the report only
    cpu0 = time.process_time()
    try:
        _play_into(out, spec, determinism=determinism, baseline=baseline,
                   wall_timeout_s=wall_timeout_s, nav_factory=nav_factory)
    except Exception as group:  # noqa: BLE001 - a broken game is a result, not a crash
        exc = _leaf(group)
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" at {last[0].filename.rsplit('/', 2)[-1]}:{last[0].lineno}" if last else ""
        out["violations"] = [f"harness.exception: {type(exc).__name__}: {exc}{where}"]
        out["reason"] = out["reason"] or f"{type(exc).__name__}: {exc}"
    out["wall_s"] = time.perf_counter() - wall0
    out["cpu_s"] = time.process_time() - cpu0
    return out


def lost_result(ref: str, why: str) -> dict[str, Any]:
    """The result of a game an engine could not play (its worker died every time it tried).

    A failure with a ``harness.worker_lost`` violation, so the summary shows it
    with the command that plays it alone.
    """
    out = _blank_result(plan_game(*parse_game_ref(ref)))
    out["violations"] = [f"harness.worker_lost: {why}"]
    out["reason"] = why
    return out


def _blank_result(spec: GameSpec) -> dict[str, Any]:
    """The result of a game not (yet) played: what is known from its plan alone."""
    return {
        "index": spec.index, "ref": spec.ref, "reproduce": spec.reproduce, "room": spec.room,
        "run_seed": spec.run_seed,
        "faults": [{"label": lab, "target": f.target, "kind": f.kind, "at_s": f.at_s,
                    "duration_s": f.duration_s, "params": dict(f.params)}
                   for lab, f in zip(spec.labels, spec.faults, strict=True)],
        "outcome": "failed", "reason": "", "violations": [], "faults_fired": 0,
        "restarts": 0, "resent": 0, "dropped": 0, "sim_s": 0.0, "wall_s": 0.0, "cpu_s": 0.0,
        "trace_hash": "", "replay_hash": None, "events": {}, "baseline": None,
        "baseline_violations": [], "wider_search": False, "hide_attempts": 0,
        "devices": dict(spec.devices), "passages": {},
    }


def _play_into(out: dict[str, Any], spec: GameSpec, *, determinism: bool, baseline: bool,
               wall_timeout_s: float | None, nav_factory: Callable[..., Any] | None) -> None:
    """Play the game (and its replays) and fill ``out`` in; raises what a play raised."""
    report, checks = _run_one(spec, wall_timeout_s, nav_factory)
    out.update(outcome=report.outcome, reason=report.reason, restarts=report.restarts,
               resent=report.resent, dropped=report.dropped, sim_s=report.sim_seconds,
               trace_hash=report.trace_hash, violations=checks["violations"],
               faults_fired=checks["faults_fired"], events=checks["events"],
               wider_search=report.wider_search, hide_attempts=report.hide_attempts,
               passages=checks["passages"])
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


def _leaf(exc: BaseException) -> BaseException:
    """The first real exception inside nested exception groups (what a user needs to see)."""
    while isinstance(exc, BaseExceptionGroup) and exc.exceptions:
        exc = exc.exceptions[0]
    return exc
