"""Console cost: simulated-time throughput with the console attached vs headless,
and key-to-actor latency.

Run as ``python -m benchmarks.console [--quick] [--live SCENARIO] [--tab TAB]``.
Both throughput runs use the fake system (`tui.fake.FakeSystem`) with the same
script (map the room, start a new game, map again ...), or with ``--live`` the
simulated system (`tui.live.LiveSystem`) playing the headless game by itself
(``hideseek play --auto``: the same game, event for event, on both sides), at
"as fast as possible";
the headless run is the baseline measured in the same process. "Attached" is
the console in Textual's headless driver at 120x40 showing tab ``TAB`` (queues
by default): it lays out and renders every frame but writes to no terminal, so
a real terminal adds the cost of output on top.

Both runs are timed over the same stretch of the game, from simulated second
``S0`` to ``S1`` (a task in Trio notes the wall and CPU time when the virtual
clock passes each): a game's cost per simulated second varies by half between
its phases, so timing each run for a fixed wall time compared different
stretches of the game.

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
import functools
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


class Timed:
    """Any console `System` plus a stopwatch: the wall and CPU time [s] when the
    virtual clock passes each second of ``stretch`` (noted in Trio, so exactly
    there whatever draws the screen)."""

    def __init__(self, inner, stretch: tuple[float, float]) -> None:
        self.inner = inner
        self.clock = inner.clock
        self.stretch = stretch
        self.marks: list[tuple[float, float]] = []  # (perf_counter, process_time) [s]

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    async def run(self, publish, requests) -> None:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._stopwatch)
            await self.inner.run(publish, requests)

    async def _stopwatch(self) -> None:
        for at in self.stretch:
            await trio.sleep_until(at)
            self.marks.append((time.perf_counter(), time.process_time()))

    def rates(self) -> tuple[float, float]:
        """Simulated seconds per wall second and per CPU second over the stretch."""
        (w0, c0), (w1, c1) = self.marks
        sim = self.stretch[1] - self.stretch[0]
        return sim / (w1 - w0), sim / (c1 - c0)


#: Simulated stretch [s] timed per system: about 3 s of wall time each, unloaded.
FAKE_STRETCH = (20.0, 800.0)
LIVE_STRETCH = (20.0, 140.0)


def fake_system(stretch: tuple[float, float] = FAKE_STRETCH) -> Timed:
    """The default system under test."""
    return Timed(ScriptedFake(speed=None), stretch)


def live_system(scenario: str, stretch: tuple[float, float] = LIVE_STRETCH):
    """A factory for the simulated system on a scenario (imported only when asked)."""
    from tui.live import LiveSystem
    from world.scenario import load_scenario

    loaded = load_scenario(scenario)
    return lambda: Timed(LiveSystem(loaded, seed=1, speed=None, db=":memory:", auto=True),
                         stretch)


def headless(make=fake_system) -> tuple[float, float]:
    """Simulated seconds per wall second and per CPU second, without the console."""
    timed = make()

    async def main() -> None:
        _, receive = trio.open_memory_channel[None](1)
        async with trio.open_nursery() as nursery:
            nursery.start_soon(timed.run, lambda item: None, receive)
            await trio.sleep_until(timed.stretch[1] + 1e-6)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=timed.clock)
    return timed.rates()


async def _wait(cond, timeout: float = 10.0, poll_s: float = 0.001) -> None:
    deadline = time.perf_counter() + timeout
    while not cond():
        if time.perf_counter() > deadline:
            raise TimeoutError("the console did not respond")
        await asyncio.sleep(poll_s)


def attached(make=fake_system, tab: str = "queues") -> tuple[float, float, float]:
    """Simulated seconds per wall second and per CPU second with the console showing
    ``tab``, and snapshots shown per wall second."""
    timed = make()
    app = ConsoleApp(timed)
    out = {}

    async def main() -> None:
        async with app.run_test(size=(120, 40)):
            await _wait(lambda: app.snapshot is not None)
            app.action_tab(tab)
            # poll coarsely: a 1 ms poll would itself cost the simulation time
            await _wait(lambda: len(timed.marks) >= 1, timeout=300.0, poll_s=0.02)
            n0, t0 = app.snapshots_shown, time.perf_counter()
            await _wait(lambda: len(timed.marks) >= 2, timeout=300.0, poll_s=0.02)
            out["fps"] = (app.snapshots_shown - n0) / (time.perf_counter() - t0)

    asyncio.run(main())
    return (*timed.rates(), out["fps"])


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
    parser.add_argument("--tab", choices=("queues", "log", "tree", "events"), default="queues",
                        help="the tab the console shows while measured (default queues)")
    args = parser.parse_args(argv)
    rounds, samples = (3, 20) if args.quick else (5, 100)
    s0, s1 = LIVE_STRETCH if args.live else FAKE_STRETCH
    stretch = (s0, s0 + (s1 - s0) / 3) if args.quick else (s0, s1)
    if args.live:
        try:
            make = live_system(args.live, stretch)
        except ValueError as exc:  # an unknown scenario (ScenarioError): no traceback
            parser.error(str(exc))
    else:
        make = functools.partial(fake_system, stretch)

    # Alternate baseline and console runs and take medians, so a change in the
    # machine's load during the benchmark hits both sides alike.
    runs = []
    for _ in range(rounds):
        base, base_cpu = headless(make)
        with_ui, with_ui_cpu, fps = attached(make, args.tab)
        runs.append((base, base_cpu, with_ui, with_ui_cpu, fps))
    med = [statistics.median(r[i] for r in runs) for i in range(5)]
    lat1 = key_latency(1.0, samples)
    latmax = key_latency(None, samples)
    figures = {
        "system": f"live:{args.live}" if args.live else "fake",
        "tab": args.tab,
        "sim_stretch_s": f"{stretch[0]:g}-{stretch[1]:g}",
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
