"""CPU seconds per game phase: where a headless game's time goes, phase by phase.

Run as ``python -m benchmarks.phase_cpu [--scenario ROOM] [--seed N]``.

Why: the phases cost very different CPU per simulated second (mapping, with its
LIDAR batches, scan matching and grid updates, several times seeking), so a
whole-game rate (`benchmarks.speedup`) mixes how long each phase lasts with what
it costs. This splits the two: per phase its simulated seconds, its CPU seconds and
their ratio.

The game is `hideseek run`'s (`run_game` under the virtual clock, Trio's order
seeded by the seed), played in this process with one observer that reads the
server's phase at every frame the server delivers (inline, no task: the same game,
the same trace hash, printed for the check). A phase's CPU runs from the first
frame seen in it to the first frame seen in the next, so its bounds are off by the
time between two frames (telemetry comes several times a second); the CPU before
the first frame (the system opening) counts as ``start``. CPU is the process's
(`time.process_time`): the world, every actor, the server and Trio; interpreter
start and imports are not in it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field

import trio

from actors import seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import GameReport, run_game
from supervisors.system import SimSystem
from world.scenario import builtin_scenarios, load_scenario


@dataclass
class PhaseClock:
    """A `RunObserver` that charges the process's CPU time to the game's phases."""

    cpu_s: dict[str, float] = field(default_factory=dict)
    """CPU seconds per phase name, in the order the phases were first seen."""
    _phase: str = "start"
    _since: float = 0.0

    def started(self, system: SimSystem) -> None:
        """Begin charging ``start``; watch the phase at every delivered frame."""
        self._since = time.process_time()
        game = system.server.game

        def on_frame(_rover: str, _role: str, _frame: object) -> None:
            phase = str(game.phase)
            if phase != self._phase:
                self._charge(phase)

        system.server.observe_frames(on_frame)

    def finished(self, _system: SimSystem, _report: GameReport) -> None:
        """Charge what is left to the phase the game ended in."""
        self._charge(self._phase)

    def _charge(self, next_phase: str) -> None:
        now = time.process_time()
        self.cpu_s[self._phase] = self.cpu_s.get(self._phase, 0.0) + now - self._since
        self._phase, self._since = next_phase, now


def measure(room: str, seed: int) -> tuple[GameReport, dict[str, float]]:
    """Play ``room`` with ``seed`` and return its report and CPU seconds per phase."""
    scenario = load_scenario(room)
    clock = PhaseClock()
    seed_trio_scheduler(seed)
    report = trio.run(lambda: run_game(scenario, seed, observers=[clock]),
                      clock=virtual_clock())
    return report, clock.cpu_s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.phase_cpu", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="round", help="a built-in room (default round)")
    ap.add_argument("--seed", type=int, default=1, help="the game's seed (default 1)")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args(argv)
    if args.scenario not in builtin_scenarios():
        print(f"phase_cpu: unknown room {args.scenario!r} "
              f"(known: {', '.join(builtin_scenarios())})", file=sys.stderr)
        return 2
    report, cpu = measure(args.scenario, args.seed)
    rows = {name: {"sim_s": report.phases.get(name, 0.0), "cpu_s": s}
            for name, s in cpu.items()}
    if args.json:
        print(json.dumps({"room": args.scenario, "seed": args.seed, "outcome": report.outcome,
                          "trace_hash": report.trace_hash, "phases": rows}))
        return 0
    print(f"{args.scenario} seed {args.seed}: {report.outcome}, "
          f"{report.sim_seconds:.1f} simulated s, trace hash {report.trace_hash[:8]}")
    print(f"{'phase':10s} {'sim s':>8s} {'CPU s':>7s} {'sim s per CPU s':>16s}")
    for name, row in rows.items():
        rate = row["sim_s"] / row["cpu_s"] if row["cpu_s"] > 0 else float("nan")
        print(f"{name:10s} {row['sim_s']:8.1f} {row['cpu_s']:7.2f} {rate:16.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
