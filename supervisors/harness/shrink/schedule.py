"""Shrinking a failing fault schedule to a 1-minimal one that fails the same way.

Given a game (a room, a run seed, a budget) whose fault schedule makes it
fail, `shrink_schedule` looks for a smaller schedule that still fails *the
same way*: the same outcome and the same broken invariants (`Failure`). In
the manner of Hypothesis, which first shrinks a failing example's structure
and then each value, it goes in four steps, each a deterministic search that
keeps every candidate that still fails:

1. **which faults**: none at all, then delta debugging over the list
   (`ddmin`), to a set of which no single fault can go;
2. **how late**: each fault's start moves later by bisection, its end kept
   (a fault with no end, or an instant one, may start as late as the game
   lasted);
3. **how short**: each fault's duration by bisection (a fault with no end
   is first tried with one, at the game's end);
4. **how mild**: each device fault is tried as a milder kind of the same
   device (`MILDER`), mildest first, with that kind's default parameters.

A last pass drops any fault that the later steps made unnecessary, so the
result is 1-minimal again. Every game costs a run; runs are cached (the
same schedule is never played twice) and bounded by ``max_runs``: out of
runs, the search stops with the smallest schedule found so far, which does
fail the same way. Games are deterministic, so the search is too.

Pure of the game itself: the caller passes ``play``, a function from a
schedule to a `Played` (`supervisors.harness.shrink.game` plays real games).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from supervisors.harness.shrink.ddmin import ddmin
from world.faults import ACTOR_FAULTS, check_fault
from world.scenario import ScheduledFault

#: per device, its fault kinds from mildest to most severe; a fault may become a kind
#: listed before its own (the IR's two kinds are equally bad, actor faults differ in kind)
MILDER: dict[str, tuple[str, ...]] = {
    "lidar": ("noisy", "stuck", "garbage", "dead"),
    "encoder": ("slipping", "stuck"),
    "motor": ("weak", "stalled"),
    "wifly": ("latency", "loss", "corrupt", "down"),
}
#: actor faults that happen at an instant: their duration means nothing
INSTANT_KINDS = frozenset(k for k in ACTOR_FAULTS if k != "hang")
DEFAULT_MAX_RUNS = 100      # games a shrink may play, the first one included
DEFAULT_RESOLUTION_S = 1.0  # bisection stops when start or duration is known this closely [s]


class ShrinkError(ValueError):
    """Raised by `shrink_schedule` when the game does not fail; the message is fit for a user."""


@dataclass(frozen=True, slots=True)
class Failure:
    """How a game failed: what two runs must share to fail "the same way"."""

    outcome: str
    """``found``, ``not_found`` or ``failed``."""
    invariants: tuple[str, ...]
    """Names of the broken invariants (``liveness.ended``), sorted, each once."""

    @classmethod
    def of(cls, outcome: str, violations: Sequence[str]) -> Failure:
        """From an outcome and ``name: detail`` violation strings."""
        return cls(outcome, tuple(sorted({v.split(":", 1)[0] for v in violations})))

    @property
    def failed(self) -> bool:
        """True unless the hider was found with every invariant kept."""
        return self.outcome != "found" or bool(self.invariants)

    def __str__(self) -> str:
        broken = f", broke {', '.join(self.invariants)}" if self.invariants else ""
        return f"{self.outcome}{broken}"


@dataclass(frozen=True, slots=True)
class Played:
    """One play of a schedule: how it ended and how long the game lasted."""

    failure: Failure
    sim_s: float
    """Simulated time the game lasted [s]."""
    trace_hash: str = ""


@dataclass(frozen=True, slots=True)
class ShrinkOutcome:
    """What `shrink_schedule` found."""

    original: tuple[ScheduledFault, ...]
    shrunk: tuple[ScheduledFault, ...]
    """Fails as ``failure``; 1-minimal unless ``exhausted``."""
    failure: Failure
    first: Played
    """The play of the original schedule."""
    last: Played
    """The play of the shrunk schedule."""
    runs: int
    """Games played, the first one included."""
    exhausted: bool
    """The run budget ran out before the search ended."""
    steps: tuple[str, ...]
    """Each change that was kept, in order, for the report."""


class _OutOfRuns(Exception):
    """The run budget is spent (raised inside a step, caught by `shrink_schedule`)."""


def _key(faults: Sequence[ScheduledFault]) -> tuple:
    return tuple((f.at_s, f.target, f.kind, f.duration_s, tuple(sorted(f.params.items())))
                 for f in faults)


class _Oracle:
    """``play`` cached and bounded, answering "does it still fail the same way?".

    Every step keeps each candidate that fails the same way as soon as it is
    found, so the last such candidate (``best``) is the smallest schedule so
    far: what is left when the runs run out.
    """

    def __init__(self, play: Callable[[tuple[ScheduledFault, ...]], Played],
                 max_runs: int, on_run: Callable[[int], None] | None = None) -> None:
        self._play, self.max_runs, self._on_run = play, max_runs, on_run
        self.runs = 0
        self._seen: dict[tuple, Played] = {}
        self.target: Failure | None = None
        self.best: tuple[ScheduledFault, ...] = ()

    def played(self, faults: Sequence[ScheduledFault]) -> Played:
        key = _key(faults)
        if key not in self._seen:
            if self.runs >= self.max_runs:
                raise _OutOfRuns
            self.runs += 1
            self._seen[key] = self._play(tuple(faults))
            if self._on_run is not None:
                self._on_run(self.runs)
        return self._seen[key]

    def fails(self, faults: Sequence[ScheduledFault]) -> bool:
        same = self.played(faults).failure == self.target
        if same:
            self.best = tuple(faults)
        return same


def shrink_schedule(faults: Sequence[ScheduledFault],
                    play: Callable[[tuple[ScheduledFault, ...]], Played], *,
                    max_runs: int = DEFAULT_MAX_RUNS,
                    resolution_s: float = DEFAULT_RESOLUTION_S,
                    on_run: Callable[[int], None] | None = None) -> ShrinkOutcome:
    """Shrink a failing schedule (see the module docstring for the steps).

    Args:
        faults: the schedule that fails.
        play: plays a schedule in the game being shrunk (deterministic).
        max_runs: games at most, the first one included (>= 1).
        resolution_s: bisection precision for starts and durations [s] (> 0).
        on_run: told the number of games played after each one (progress).

    Raises:
        ShrinkError: the schedule does not make the game fail.
        ValueError: a bad ``max_runs`` or ``resolution_s``.
    """
    if isinstance(max_runs, bool) or not isinstance(max_runs, int) or not 1 <= max_runs <= 10_000:
        raise ValueError(f"max_runs must be within 1..10000, got {max_runs!r}")
    if not 0 < resolution_s <= 1e4:
        raise ValueError(f"resolution_s must be within (0, 1e4] s, got {resolution_s!r}")
    oracle = _Oracle(play, max_runs, on_run)
    first = oracle.played(faults)
    if not first.failure.failed:
        raise ShrinkError(f"the game does not fail (outcome {first.failure.outcome}, every "
                          "invariant kept): nothing to shrink")
    oracle.target, oracle.best = first.failure, tuple(faults)
    steps: list[str] = []
    exhausted = False
    try:
        _fewer(oracle, steps)
        for i in range(len(oracle.best)):
            _later(oracle, i, first.sim_s, resolution_s, steps)
            _shorter(oracle, i, first.sim_s, resolution_s, steps)
            _milder(oracle, i, steps)
        _fewer(oracle, steps, again=True)
    except _OutOfRuns:
        exhausted = True
        steps.append(f"out of runs ({max_runs}): stopped with the smallest schedule so far")
    last = oracle.played(oracle.best)  # played already: from the cache
    return ShrinkOutcome(tuple(faults), oracle.best, first.failure, first, last, oracle.runs,
                         exhausted, tuple(steps))


def describe(f: ScheduledFault) -> str:
    """``mapper/lidar dead at 12.5 s for 3 s`` (params appended when there are any)."""
    span = "until cleared" if f.duration_s == 0 and f.kind not in INSTANT_KINDS else (
        "" if f.kind in INSTANT_KINDS else f"for {f.duration_s:g} s")
    params = "".join(f" {k}={v:g}" for k, v in sorted(f.params.items()))
    return f"{f.target} {f.kind} at {f.at_s:g} s {span}{params}".replace("  ", " ").strip()


def _fewer(oracle: _Oracle, steps: list[str], *, again: bool = False) -> None:
    """Step 1 (and the last pass): no faults at all, else a 1-minimal subset (ddmin)."""
    before = oracle.best
    if not before:
        return
    if oracle.fails(()):
        steps.append("fails the same way without any fault: the faults are not the cause")
        return
    kept = ddmin(list(before), oracle.fails)
    oracle.best = tuple(kept)
    if len(kept) < len(before):
        gone = [describe(f) for f in before if f not in kept]
        steps.append(f"{'then ' if again else ''}dropped {len(gone)} of {len(before)} "
                     f"faults: {'; '.join(gone)}")


def _replace(oracle: _Oracle, i: int, fault: ScheduledFault) -> tuple[ScheduledFault, ...]:
    return oracle.best[:i] + (fault,) + oracle.best[i + 1:]


def _later(oracle: _Oracle, i: int, game_s: float, res: float, steps: list[str]) -> None:
    """Step 2: fault ``i`` starts as late as it can (bisection), its end kept."""
    f = oracle.best[i]
    bounded = f.duration_s > 0 and f.kind not in INSTANT_KINDS
    end = f.at_s + f.duration_s if bounded else game_s
    lo, hi = f.at_s, end - (res if bounded else 0.0)   # lo fails; hi is not known to
    while hi - lo > res:
        mid = round((lo + hi) / 2, 3)
        duration = round(end - mid, 3) if bounded else f.duration_s
        if oracle.fails(_replace(oracle, i, dataclasses.replace(f, at_s=mid,
                                                                duration_s=duration))):
            lo = mid
        else:
            hi = mid
    if lo > f.at_s:
        steps.append(f"{f.target} {f.kind}: starts at {lo:g} s instead of {f.at_s:g} s")


def _shorter(oracle: _Oracle, i: int, game_s: float, res: float, steps: list[str]) -> None:
    """Step 3: fault ``i`` lasts as briefly as it can (bisection)."""
    f = oracle.best[i]
    if f.kind in INSTANT_KINDS:
        return
    if f.duration_s > 0:
        hi = f.duration_s
    else:  # until cleared: first try an end at the game's end
        hi = round(game_s - f.at_s, 3)
        if hi <= res or not oracle.fails(_replace(oracle, i, dataclasses.replace(
                f, duration_s=hi))):
            return
    lo = 0.0                                         # hi fails; lo (no fault) is not known to
    while hi - lo > res:
        mid = round((lo + hi) / 2, 3)
        if oracle.fails(_replace(oracle, i, dataclasses.replace(f, duration_s=mid))):
            hi = mid
        else:
            lo = mid
    if hi != f.duration_s:
        was = f"{f.duration_s:g} s" if f.duration_s else "until cleared"
        steps.append(f"{f.target} {f.kind}: lasts {hi:g} s instead of {was}")


def _milder(oracle: _Oracle, i: int, steps: list[str]) -> None:
    """Step 4: fault ``i`` as a milder kind of its device, mildest first."""
    f = oracle.best[i]
    device = f.target.split("/", 1)[1].removesuffix("_left").removesuffix("_right")
    kinds = MILDER.get(device, ())
    if f.kind not in kinds:
        return
    for kind in kinds[:kinds.index(f.kind)]:
        params = check_fault(f.target, kind, f.duration_s, {})
        if oracle.fails(_replace(oracle, i, dataclasses.replace(f, kind=kind, params=params))):
            steps.append(f"{f.target}: {kind} instead of {f.kind}")
            return
