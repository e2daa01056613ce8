"""Console cost: simulated-time throughput with the console attached vs headless,
and key-to-actor latency.

Run as ``python -m benchmarks.console [--quick] [--live SCENARIO]``. Both
throughput runs use the fake system (`tui.fake.FakeSystem`), or with ``--live``
the simulated system (`tui.live.LiveSystem`), at "as fast as possible" with the
same script (map the room, start a new game, map again ...); the headless run is
the baseline measured in the same process. "Attached" is the console in
Textual's headless driver at 120x40: it lays out and renders every frame but
writes to no terminal, so a real terminal adds the cost of output on top.

Other processes on a shared machine take wall time from both runs unequally,
so the ratio is also given per CPU second of this process (``process_time``),
which such load does not skew.

Key-to-actor latency is the wall time from posting a key event to the app
until the system's command handler runs inside Trio (``space`` -> ``pause`` /
``resume``), at speed x1 and at "as fast as possible".
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import statistics
import sys
import time

import trio
from textual import events

from tui.app import ConsoleApp
from tui.fake import FakeSystem


class ScriptedFake(FakeSystem):
    """The fake plus a driver task that keeps it mapping, and command timestamps."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.handled: list[float] = []

    async def run(self, publish, requests) -> None:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._script)
            await super().run(publish, requests)

    async def _script(self) -> None:
        while True:
            self.new_game()
            self.start_mapping()
            await trio.sleep(40.0)

    def _do_pause(self) -> None:
        self.handled.append(time.perf_counter())
        super()._do_pause()

    def _do_resume(self) -> None:
        self.handled.append(time.perf_counter())
        super()._do_resume()


class Scripted:
    """Any console `System` plus a driver task: new game and start mapping every
    ``period_s`` simulated seconds (a refused command is simply ignored)."""

    def __init__(self, inner, period_s: float) -> None:
        self.inner = inner
        self.clock = inner.clock
        self.period_s = period_s

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    async def run(self, publish, requests) -> None:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._script)
            await self.inner.run(publish, requests)

    async def _script(self) -> None:
        while True:
            self.inner.new_game()
            self.inner.start_mapping()
            await trio.sleep(self.period_s)


def fake_system():
    """The default system under test."""
    return ScriptedFake(speed=None)


def live_system(scenario: str):
    """A factory for the simulated system on a scenario (imported only when asked)."""
    from tui.live import LiveSystem
    from world.scenario import load_scenario

    loaded = load_scenario(scenario)
    return lambda: Scripted(LiveSystem(loaded, seed=1, speed=None, db=":memory:"), 300.0)


def headless(wall_s: float, make=fake_system) -> tuple[float, float]:
    """Simulated seconds per wall second and per CPU second, without the console."""
    fake = make()
    out = {}

    async def main() -> None:
        _, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(fake.run, lambda item: None, receive)
            t0, c0, s0 = time.perf_counter(), time.process_time(), trio.current_time()
            while time.perf_counter() - t0 < wall_s:
                await trio.sleep(1.0)
            sim = trio.current_time() - s0
            out["rate"] = sim / (time.perf_counter() - t0), sim / (time.process_time() - c0)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=fake.clock)
    return out["rate"]


async def _wait(cond, timeout: float = 10.0) -> None:
    deadline = time.perf_counter() + timeout
    while not cond():
        if time.perf_counter() > deadline:
            raise TimeoutError("the console did not respond")
        await asyncio.sleep(0.001)


def attached(wall_s: float, make=fake_system) -> tuple[float, float, float]:
    """Simulated seconds per wall second and per CPU second with the console, and
    snapshots shown per wall second."""
    fake = make()
    app = ConsoleApp(fake)
    out = {}

    async def main() -> None:
        async with app.run_test(size=(120, 40)):
            await _wait(lambda: app.snapshot is not None)
            s0, n0 = app.snapshot.time_s, app.snapshots_shown
            t0, c0 = time.perf_counter(), time.process_time()
            await asyncio.sleep(wall_s)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            sim = app.snapshot.time_s - s0
            out["rate"] = (sim / wall, sim / cpu)
            out["fps"] = (app.snapshots_shown - n0) / wall

    asyncio.run(main())
    return (*out["rate"], out["fps"])


def key_latency(speed: float | None, samples: int) -> list[float]:
    """Wall milliseconds from posting ``space`` to the Trio-side handler, per sample."""
    fake = ScriptedFake(speed=speed)
    app = ConsoleApp(fake)
    lat: list[float] = []
    phase = random.Random(0)

    async def main() -> None:
        async with app.run_test(size=(120, 40)):
            await _wait(lambda: app.snapshot is not None)
            for _ in range(samples):
                # a random moment within a frame, not just after a snapshot arrived
                await asyncio.sleep(phase.uniform(0.0, 1.0 / 15))
                n = len(fake.handled)
                paused = app.snapshot.paused
                t0 = time.perf_counter()
                app.post_message(events.Key("space", " "))
                await _wait(lambda n=n: len(fake.handled) > n)
                lat.append((fake.handled[-1] - t0) * 1000.0)
                await _wait(lambda p=paused: app.snapshot.paused != p)

    asyncio.run(main())
    return lat


def pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.console", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="short runs (a smoke test)")
    parser.add_argument("--live", metavar="SCENARIO",
                        help="measure throughput on the simulated system with this scenario")
    args = parser.parse_args(argv)
    make = live_system(args.live) if args.live else fake_system
    wall_s, rounds, samples = (1.5, 3, 20) if args.quick else (3.0, 5, 100)

    # Alternate baseline and console runs and take medians, so a change in the
    # machine's load during the benchmark hits both sides alike.
    runs = []
    for _ in range(rounds):
        base, base_cpu = headless(wall_s, make)
        with_ui, with_ui_cpu, fps = attached(wall_s, make)
        runs.append((base, base_cpu, with_ui, with_ui_cpu, fps))
    med = [statistics.median(r[i] for r in runs) for i in range(5)]
    lat1 = key_latency(1.0, samples)
    latmax = key_latency(None, samples)
    figures = {
        "system": f"live:{args.live}" if args.live else "fake",
        "wall_s_per_run": wall_s,
        "rounds": rounds,
        "headless_sim_s_per_wall_s": round(med[0], 1),
        "console_sim_s_per_wall_s": round(med[2], 1),
        "ratio_console_vs_headless": round(statistics.median(r[2] / r[0] for r in runs), 3),
        "headless_sim_s_per_cpu_s": round(med[1], 1),
        "console_sim_s_per_cpu_s": round(med[3], 1),
        "ratio_per_cpu_s": round(statistics.median(r[3] / r[1] for r in runs), 3),
        "console_snapshots_per_s": round(med[4], 1),
        "key_to_actor_ms_p50_x1": round(statistics.median(lat1), 3),
        "key_to_actor_ms_p95_x1": round(pct(lat1, 0.95), 3),
        "key_to_actor_ms_p50_max": round(statistics.median(latmax), 3),
        "key_to_actor_ms_p95_max": round(pct(latmax, 0.95), 3),
    }
    print(f"{'measure':<34} {'value':>10}")
    print("-" * 45)
    for key, value in figures.items():
        print(f"{key:<34} {value:>10}")
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
