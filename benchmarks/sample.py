"""Statistical CPU profile of one headless game: where the CPU goes.

Run as ``python -m benchmarks.sample --scenario hall --seed 1 [--every-ms 2] [--top 40]
[--phase mapping|hiding|seeking]``.

Why not cProfile: it charges every Python-level call, so numpy-heavy code that
goes through numpy's Python wrappers looks several times dearer than it is. A
``SIGPROF`` timer that fires every ``--every-ms`` of CPU time interrupts the game
wherever it is; the handler only counts the interrupted stack:

- *self*: the innermost frame (any file), as ``file:function``;
- *inclusive*: every distinct ``file:function`` on the stack (project files and
  Trio), so a firmware handler's share includes the numpy it calls;
- *innermost project line*: the innermost frame in this repository, with its line;
- *area*: the outermost project frame below the runtime (firmware module, world
  module, or "runtime" when only actors/ and Trio are on the stack).

The first line after the summary counts the samples per game phase (the server
game's phase when the sample was taken: mapping until the map is ready, hiding
until the hider is hidden, seeking until the hider is found); ``--phase`` keeps
only the samples of one phase in the tables.

The game is the one ``hideseek run --scenario S --seed N`` plays (same trace hash:
the handler reads frames only, and Trio's signal wake-up fd is unset so the
signals do not wake its event loop). The sampling itself costs a little CPU.
"""

from __future__ import annotations

import argparse
import collections
import os
import signal
import sys
import time
from types import FrameType
from typing import Any

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _label(frame: FrameType) -> str:
    code = frame.f_code
    path = code.co_filename
    if path.startswith(_ROOT):
        path = os.path.relpath(path, _ROOT)
    else:
        parts = path.split(os.sep)
        path = os.sep.join(parts[-2:])
    return f"{path}:{code.co_name}"


def _area(labels: list[str]) -> str:
    """The outermost firmware/world/supervisor/benchmark frame, or "runtime"."""
    for lab in reversed(labels):  # outermost last in `labels`, so scan from the outside in
        path = lab.partition(":")[0]
        if path.startswith(("actors/firmware/", "world/", "server/")) \
                or path in ("supervisors/system.py", "supervisors/invariants.py"):
            return path
    return "runtime (actors/, trio)"


_PHASE_OF = {"idle": "start", "mapping": "mapping", "map_ready": "hiding", "hiding": "hiding",
             "hidden": "seeking", "seeking": "seeking", "found": "end", "not_found": "end"}
"""The server game's phases, as the phases of the game the samples are counted in."""


class _PhaseWatch:
    """A `run_game` observer that keeps the system, so the sampler can read the server
    game's phase (a plain attribute read, safe in a signal handler)."""

    def __init__(self) -> None:
        self._system: Any = None
        self._over = False

    def started(self, system: Any) -> None:
        self._system = system

    def finished(self, system: Any, report: Any) -> None:
        self._system = None
        self._over = True

    def phase(self) -> str:
        """start, mapping, hiding, seeking or end."""
        system = self._system
        if system is None:
            return "end" if self._over else "start"
        return _PHASE_OF.get(str(system.server.game.phase), "end")


async def _quiet(game: Any) -> Any:
    """Await ``game`` with Trio's signal wake-up fd unset: each SIGPROF would otherwise
    wake Trio's I/O wait and change the order of events (another game)."""
    signal.set_wakeup_fd(-1)
    return await game


def main(argv: list[str] | None = None) -> int:
    """Play one game under the sampler and print the three tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="hall")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--every-ms", type=float, default=2.0)
    ap.add_argument("--top", type=int, default=40)
    ap.add_argument("--phase", default="", choices=("", "mapping", "hiding", "seeking"),
                    help="count only the samples taken in this phase of the game")
    ap.add_argument("--callers", default="",
                    help="also count the callers (two frames up) of innermost frames "
                         "whose label contains this text")
    args = ap.parse_args(argv)

    import trio  # noqa: PLC0415

    from actors import seed_trio_scheduler, virtual_clock  # noqa: PLC0415
    from supervisors.harness.headless import run_game  # noqa: PLC0415
    from world.scenario import load_scenario  # noqa: PLC0415

    own: collections.Counter[str] = collections.Counter()
    incl: collections.Counter[str] = collections.Counter()
    area: collections.Counter[str] = collections.Counter()
    line: collections.Counter[str] = collections.Counter()
    callers: collections.Counter[str] = collections.Counter()
    total = [0]
    phases: collections.Counter[str] = collections.Counter()
    game = _PhaseWatch()

    def on_prof(_sig: int, frame: FrameType | None) -> None:
        labels: list[str] = []
        f = frame
        while f is not None:
            labels.append(_label(f))
            f = f.f_back
        if not labels:
            return
        phase = game.phase()
        phases[phase] += 1
        if args.phase and phase != args.phase:
            return
        total[0] += 1
        own[labels[0]] += 1
        if args.callers and args.callers in labels[0]:
            callers[" <- ".join(labels[:4])] += 1
        for lab in set(labels):
            incl[lab] += 1
        area[_area(labels)] += 1
        f = frame
        while f is not None:
            path = f.f_code.co_filename
            if path.startswith(_ROOT) and "/.venv/" not in path:
                line[f"{_label(f)}:{f.f_lineno}"] += 1
                break
            f = f.f_back

    scenario = load_scenario(args.scenario)
    seed_trio_scheduler(args.seed)
    signal.signal(signal.SIGPROF, on_prof)
    every = args.every_ms / 1000.0
    cpu0 = time.process_time()
    signal.setitimer(signal.ITIMER_PROF, every, every)
    try:
        report = trio.run(_quiet, run_game(scenario, args.seed, observers=(game,)),
                          clock=virtual_clock())
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0.0, 0.0)
    cpu = time.process_time() - cpu0
    n = max(1, total[0])
    print(f"{args.scenario} seed {args.seed}: outcome {report.outcome}, sim "
          f"{report.sim_seconds:.0f} s, CPU {cpu:.1f} s, RTFc {report.sim_seconds / cpu:.1f}, "
          f"hash {report.trace_hash}, {total[0]} samples", file=sys.stdout)
    print("samples per phase: " + ", ".join(f"{k} {100.0 * v / max(1, sum(phases.values())):.0f} %"
                                             for k, v in phases.items()))
    for title, counter in (("area", area), ("self", own), ("inclusive", incl),
                           ("innermost project line", line), ("callers", callers)):
        print(f"\n-- {title} --")
        for lab, k in counter.most_common(args.top):
            print(f"{100.0 * k / n:5.1f} %  {lab}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
