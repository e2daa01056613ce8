"""Shrinking real games: a campaign game or a scenario file, to a scenario file that fails alike.

`shrink_game` plays the room with candidate fault schedules (each in a fresh
Trio run on a virtual clock, with the campaign's probes and invariant checks:
`supervisors.harness.campaign.play.run_checked`), lets `shrink_schedule`
search, writes the result as scenario TOML, and plays that file once more to
check that it fails the same way. `shrink_campaign_game` is the worker entry
point an engine calls (strings and numbers in, a JSON-able dict out), as
`play_campaign_game` is for games.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from supervisors.harness.campaign.local import call
from supervisors.harness.campaign.plan import plan_game
from supervisors.harness.campaign.play import run_checked
from supervisors.harness.campaign.refs import CampaignError, parse_game_ref
from supervisors.harness.headless import Budget
from supervisors.harness.shrink.schedule import (
    DEFAULT_MAX_RUNS,
    DEFAULT_RESOLUTION_S,
    Failure,
    Played,
    ShrinkError,
    describe,
    shrink_schedule,
)
from supervisors.harness.shrink.toml import scenario_toml
from world.scenario import Scenario, ScheduledFault, parse_scenario

_DEFAULT_BUDGET_S = Budget().mapping


def with_faults(base: Scenario, faults: Sequence[ScheduledFault]) -> Scenario:
    """The room with this schedule instead of its own (sorted by start, ties in list order)."""
    return dataclasses.replace(base, faults=tuple(sorted(faults, key=lambda f: f.at_s)))


def player(base: Scenario, run_seed: int, budget: Budget, wall_timeout_s: float | None
           ) -> Callable[[tuple[ScheduledFault, ...]], Played]:
    """``play(schedule)`` for `shrink_schedule`: the room, seed and budget fixed."""

    def play(faults: tuple[ScheduledFault, ...]) -> Played:
        return play_scenario(with_faults(base, faults), run_seed, budget, wall_timeout_s)

    return play


def play_scenario(scenario: Scenario, run_seed: int, budget: Budget,
                  wall_timeout_s: float | None) -> Played:
    """One checked play; a play that raised (or was stopped by its guard) is a failure."""
    try:
        report, checks = run_checked(scenario, run_seed, budget, wall_timeout_s)
    except Exception as exc:  # noqa: BLE001 - a broken game is a result, as in a campaign
        return Played(Failure.of("failed", [f"harness.exception: {exc!r}"]), 0.0)
    return Played(Failure.of(report.outcome, checks["violations"]), report.sim_seconds,
                  report.trace_hash)


def _fault_json(f: ScheduledFault) -> dict[str, Any]:
    return {"target": f.target, "kind": f.kind, "at_s": f.at_s, "duration_s": f.duration_s,
            "params": dict(f.params)}


def shrink_game(base: Scenario, run_seed: int, *, budget_s: float = _DEFAULT_BUDGET_S,
                origin: str = "", max_runs: int = DEFAULT_MAX_RUNS,
                resolution_s: float = DEFAULT_RESOLUTION_S,
                wall_timeout_s: float | None = 600.0,
                on_run: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Shrink the fault schedule of ``base`` played with ``run_seed``; a JSON-able report.

    Args:
        base: the room with the failing schedule (its ``faults``).
        run_seed: the seed the game runs with.
        budget_s: simulated time allowed for mapping [s] (``hideseek run --budget``).
        origin: where the game came from, for the report (``campaign S:I``).
        max_runs: games at most, the first one included (the check of the
            written file comes on top).
        resolution_s: bisection precision [s].
        wall_timeout_s: guard per play [s] (see `play_campaign_game`).
        on_run: told the number of games played after each one, the check of the
            written file included (progress).

    Returns:
        ``origin``, ``room``, ``seed``, ``budget_s``, ``failure`` (text),
        ``outcome``, ``invariants``, ``original`` and ``shrunk`` (one line per
        fault), ``original_faults`` and ``shrunk_faults`` (dicts), ``runs``
        (the search's games and the check of the written file, as the file's header
        counts them), ``max_runs``, ``exhausted``, ``steps``, ``toml`` (the shrunk scenario),
        ``reproduces`` (that text, read back and played, fails the same way),
        ``same_trace`` (and plays the very same game), ``reproduce`` (the
        command, ``FILE`` standing for where the text is written).

    Raises:
        ShrinkError: the game does not fail.
    """
    budget = Budget(mapping=budget_s)
    found = shrink_schedule(base.faults, player(base, run_seed, budget, wall_timeout_s),
                            max_runs=max_runs, resolution_s=resolution_s, on_run=on_run)
    runs = found.runs + 1  # the search's, and one more: the check of the written file
    shrunk = with_faults(base, found.shrunk)
    command = f"hideseek run --scenario FILE --seed {run_seed}" + (
        f" --budget {budget_s:g}" if budget_s != _DEFAULT_BUDGET_S else "")
    header = [f"shrunk by hideseek shrink from {origin or base.name}: "
              f"{len(found.original)} faults -> {len(found.shrunk)}, {runs} runs (the last "
              "one plays this file)",
              f"fails: {found.failure}", f"reproduce: {command}", "original schedule:"]
    header += [f"  {describe(f)}" for f in found.original]
    text = scenario_toml(shrunk, header=header)
    again = play_scenario(parse_scenario(text, "<shrunk>"), run_seed, budget, wall_timeout_s)
    if on_run is not None:
        on_run(runs)
    return {
        "origin": origin or base.name, "room": base.name, "seed": run_seed,
        "budget_s": budget_s, "failure": str(found.failure),
        "outcome": found.failure.outcome, "invariants": list(found.failure.invariants),
        "original": [describe(f) for f in found.original],
        "shrunk": [describe(f) for f in found.shrunk],
        "original_faults": [_fault_json(f) for f in found.original],
        "shrunk_faults": [_fault_json(f) for f in found.shrunk],
        "runs": runs, "max_runs": max_runs, "exhausted": found.exhausted,
        "steps": list(found.steps), "toml": text,
        "reproduces": again.failure == found.failure,
        "same_trace": bool(again.trace_hash) and again.trace_hash == found.last.trace_hash,
        "reproduce": command,
    }


def shrink_campaign_game(ref: str, *, max_runs: int = DEFAULT_MAX_RUNS,
                         resolution_s: float = DEFAULT_RESOLUTION_S,
                         wall_timeout_s: float | None = 600.0,
                         on_run: Callable[[int], None] | None = None) -> dict[str, Any]:
    """The worker entry point: shrink campaign game ``ref``; `shrink_game`'s report.

    Raises:
        CampaignError: ``ref`` is not a valid game reference.
        ShrinkError: the game does not fail.
    """
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    out = shrink_game(spec.scenario(), spec.run_seed, budget_s=config.mapping_budget_s,
                      origin=f"campaign game {spec.ref}", max_runs=max_runs,
                      resolution_s=resolution_s, wall_timeout_s=wall_timeout_s, on_run=on_run)
    out["index"] = index
    out["ref"] = spec.ref
    return out


def shrink_failure(ref: str, **options: Any) -> dict[str, Any]:
    """`shrink_campaign_game` as an engine job: never raises for a game that cannot shrink.

    A game that does not fail when played again (it should: games are
    deterministic) or a bad reference gives ``{"ref", "index", "error"}``.
    """
    try:
        return shrink_campaign_game(ref, **options)
    except (ShrinkError, CampaignError) as exc:
        return {"ref": ref, "index": parse_game_ref(ref)[1] if ":" in ref else None,
                "error": str(exc)}


def shrinkable(results: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The campaign games `shrink_failures` shrinks: the failed ones with faults, by index."""
    return [r for r in sorted(results, key=lambda r: r["index"])
            if r["faults"] and (r["outcome"] != "found" or r["violations"])]


def shrink_failures(results: Iterable[dict[str, Any]], *, engine: Any = None,
                    max_runs: int = DEFAULT_MAX_RUNS,
                    resolution_s: float = DEFAULT_RESOLUTION_S,
                    wall_timeout_s: float | None = 600.0) -> Iterator[dict[str, Any]]:
    """Shrink each failed campaign game that had faults; yield the reports as they finish.

    Each shrink is one job on ``engine`` (an engine of
    `supervisors.harness.campaign.engines`, the same the games ran on), so the
    failures shrink in parallel; with no engine, one after another here.
    """
    options = {"max_runs": max_runs, "resolution_s": resolution_s,
               "wall_timeout_s": wall_timeout_s}
    jobs = [(shrink_failure, (r["ref"],), options) for r in shrinkable(results)]
    if engine is None:
        yield from (call(job) for job in jobs)
        return
    yield from engine.map(jobs, lost=lambda job, exc: {
        "ref": job[1][0], "index": parse_game_ref(job[1][0])[1],
        "error": f"worker lost: {type(exc).__name__}"})
