"""Per-call CPU of the paths a game takes per event outside the firmware and the world,
for one tree or two side by side.

Run as ``python -m benchmarks.runtime_calls [--trees DIR,DIR] [--rounds N]``. Each
round starts, in every tree's directory (so that tree's code is imported), one
process that times, on the virtual clock under the seeded scheduler:

* ``sleep_us``: a sleep and its wake-up (`actors.sleep`, three tasks sleeping in
  turn, the way the world's ticks and the actors' timers sleep);
* ``arm_us``: a watchdog guard armed at a new instant (`actors.watchdog.Guard`),
  as for every message handled after the clock moved (the clock's jump between
  two arms, timed alone, subtracted);
* ``timer_us``: one round of the server timer's wait that its deadline ends
  (`server.kick.Kick.wait_until`; in a tree without it, a `trio.Event` waited on
  in a `trio.move_on_at` scope, as the timer did there);
* ``pose_us`` and ``compose_us``: making a `server.protocol.Pose` and composing two
  (the firmware's dead reckoning and the server's frames);

and one ``hideseek run --help`` process (``start_s``: interpreter start and the
imports a headless game's command makes). CPU is ``time.process_time`` inside, and
the ``RUSAGE_CHILDREN`` delta for the start. The trees alternate (the one that goes
first swaps from round to round) and are byte-compiled first; the table gives each
figure's median over the rounds. A tree without a module timed here (an old tree)
shows no figure for it. The last line is the figures as JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

from benchmarks.speedup import byte_compile, children_cpu_s, is_tree

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_PROBE = r'''
import json, sys, time
sys.path.insert(0, ".")
import trio
from actors import seed_trio_scheduler, sleep, virtual_clock
from actors.watchdog import Guard
from server.protocol.pose import Pose, compose
N = int(sys.argv[1])
out = {}

async def sleeper(n):
    for _ in range(n):
        await sleep(0.01)

async def main():
    t = time.process_time()
    async with trio.open_nursery() as nursery:
        for _ in range(3):
            nursery.start_soon(sleeper, N)
    out["sleep_us"] = (time.process_time() - t) / (3 * N) * 1e6
    guard = Guard(0.5)
    clock = trio.lowlevel.current_clock()
    t = time.process_time()
    for _ in range(N):
        clock.jump(0.001)
    jumps = time.process_time() - t
    t = time.process_time()
    for _ in range(N):
        clock.jump(0.001)
        guard.arm()
    out["arm_us"] = (time.process_time() - t - jumps) / N * 1e6
    guard.disarm()
    try:
        from server.kick import Kick
        kick = Kick()
        wait = lambda deadline: kick.wait_until(deadline)
    except ImportError:  # a tree whose server timer waited on an Event in a cancel scope
        async def wait(deadline):
            with trio.move_on_at(deadline):
                await trio.Event().wait()
    t = time.process_time()
    for _ in range(N):
        await wait(trio.current_time() + 0.01)
    out["timer_us"] = (time.process_time() - t) / N * 1e6

seed_trio_scheduler(1)
trio.run(main, clock=virtual_clock())
a, b = Pose(10.0, 20.0, 30.0), Pose(1.0, 2.0, 170.0)
t = time.process_time()
for _ in range(5 * N):
    Pose(1.0, 2.0, 3.0)
out["pose_us"] = (time.process_time() - t) / (5 * N) * 1e6
t = time.process_time()
for _ in range(5 * N):
    compose(a, b)
out["compose_us"] = (time.process_time() - t) / (5 * N) * 1e6
print(json.dumps(out))
'''


def _child_cpu(cmd: list[str], cwd: str) -> tuple[float, str]:
    """Run ``cmd`` in ``cwd``; its CPU seconds (user + system) and its stdout."""
    before = children_cpu_s()
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    return children_cpu_s() - before, done.stdout


def measure(tree: str, n: int) -> dict[str, float]:
    """One round of every figure for ``tree`` (missing figures are left out)."""
    figures: dict[str, float] = {}
    _, out = _child_cpu([sys.executable, "-c", _PROBE, str(n)], tree)
    lines = out.strip().splitlines()
    if lines:
        figures.update(json.loads(lines[-1]))
    figures["start_s"], _ = _child_cpu([sys.executable, "-m", "tui.cli", "run", "--help"], tree)
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.runtime_calls",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", default=_ROOT,
                        help="comma-separated tree directories (default: this tree)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds per tree (default 5)")
    parser.add_argument("--calls", type=int, default=40_000,
                        help="calls per figure and round (default 40000)")
    args = parser.parse_args(argv)
    trees = [os.path.abspath(t) for t in args.trees.split(",") if t]
    if not trees or args.rounds < 1 or args.calls < 1:
        parser.error("give at least one tree, --rounds >= 1 and --calls >= 1")
    for tree in trees:
        if not is_tree(tree):
            parser.error(f"{tree} is not a hideseek tree (no tui/cli.py)")
        byte_compile(tree)
    runs: dict[str, list[dict[str, float]]] = {t: [] for t in trees}
    for r in range(args.rounds):
        for tree in (trees if r % 2 == 0 else trees[::-1]):
            runs[tree].append(measure(tree, args.calls))
    result: dict[str, dict[str, float]] = {}
    names = ("sleep_us", "arm_us", "timer_us", "pose_us", "compose_us", "start_s")
    print(f"{'tree':<40}" + "".join(f"{n:>12}" for n in names))
    for tree in trees:
        result[tree] = {n: statistics.median(r[n] for r in runs[tree])
                        for n in names if all(n in r for r in runs[tree])}
        print(f"{tree[-40:]:<40}" + "".join(
            f"{result[tree][n]:>12.3f}" if n in result[tree] else f"{'-':>12}" for n in names))
    print(json.dumps({"rounds": args.rounds, "calls": args.calls, "median": result}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
