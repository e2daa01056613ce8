"""Benchmark: simulated seconds per wall second of the world alone, and LIDAR ray casting.

Run as ``python -m benchmarks.world [--quick]``. The world runs with three
rovers driving (seeded random PWM, changed every second), the LIDAR spinning
at PWM 0.5 (5.5 rev/s, 1980 samples/s) and the IR sampling at 20 Hz, with no
firmware attached (handlers only count). The baseline measured in the same run
is the same world with the LIDAR and IR off (physics, motors, encoders only);
the ratio is taken on CPU time. Each run reports simulated seconds per wall
second (``x``) and per CPU second of this process (``cpu x``): on a shared
machine the two differ by the time other processes took.
The ray casters are timed for whole 360-ray revolutions against the room's
segments: the fan caster the LIDAR uses (`world.raycast.FanCaster`), the
all-pairs `cast_rays`, and pymunk segment queries as the baseline; and for one
50 ms tick's fan (99 rays at 5.5 rev/s), where per-call overhead dominates.
Prints a table, then one line of JSON with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np
import pymunk

from world.geometry import boundary_segments, room_segments
from world.raycast import FanCaster, cast_rays
from world.scenario import load_scenario
from world.world import World

SCENARIOS = ("furniture", "round", "hall")


def run_world(name: str, tick_s: float, seconds: float, sensors: bool) -> tuple[float, float]:
    """Simulated seconds per wall second, and per CPU second of this process.

    The CPU figure is what the world costs when it has a core to itself; the wall
    figure also counts the time other processes on a shared machine took.
    """
    world = World(load_scenario(name), np.random.default_rng(1), tick_s=tick_s)
    count = [0]

    def sink(_payload: object) -> None:
        count[0] += 1

    for role in ("mapper", "hider", "seeker"):
        for line in (0xA, 0xB, 0xC, 0xD, 0xE):
            world.hardware(role).attach(line, sink)
    seeker = world.hardware("seeker")
    if sensors:
        world.hardware("mapper").set_lidar_pwm(0.5)
        seeker.set_ir_timer(20)
        seeker.attach(0xD, lambda _: seeker.start_adc())
    cmd = np.random.default_rng(2)
    start = time.perf_counter()
    cpu = time.process_time()
    next_cmd = 0.0
    while world.time < seconds:
        if world.time >= next_cmd:
            for role in ("mapper", "hider", "seeker"):
                world.hardware(role).set_tread_pwm(*cmd.uniform(-0.3, 1.0, 2))
            next_cmd += 1.0
        world.step()
    return (world.time / (time.perf_counter() - start),
            world.time / max(time.process_time() - cpu, 1e-9))


def best_of(repeats: int, name: str, tick_s: float, seconds: float,
            sensors: bool) -> tuple[float, float]:
    """The fastest of a few runs (wall and CPU separately): other load only slows a run."""
    runs = [run_world(name, tick_s, seconds, sensors) for _ in range(repeats)]
    return max(r[0] for r in runs), max(r[1] for r in runs)


def lidar_revs(name: str, revs: int) -> dict[str, float]:
    """Revolutions/s of the fan caster, of all-pairs casting and of pymunk; segment count."""
    s = load_scenario(name)
    segs = np.vstack([room_segments(*s.room_size), boundary_segments(list(s.obstacles))])
    origin = (s.starts["mapper"].x + 100.0, s.starts["mapper"].y + 100.0)
    step = math.radians(1.0)
    angles = np.arange(360) * step
    fan = FanCaster(segs)
    t = time.perf_counter()
    for i in range(revs):
        fan.cast_fan(origin, i * 0.01, step, 360, 4000.0)
    out = {"fan": revs / (time.perf_counter() - t)}
    t = time.perf_counter()
    for i in range(revs):
        fan.cast_fan(origin, i * 0.01, step, 99, 4000.0)
    out["fan_tick_us"] = (time.perf_counter() - t) / revs * 1e6
    t = time.perf_counter()
    for i in range(revs):
        cast_rays(origin, angles + i * 0.01, segs, 4000.0)
    out["pairs"] = revs / (time.perf_counter() - t)
    space = pymunk.Space()
    space.add(*[pymunk.Segment(space.static_body, (a, b), (c, d), 0.0) for a, b, c, d in segs])
    flt = pymunk.ShapeFilter()
    ends = [(origin[0] + 4000 * math.cos(a), origin[1] + 4000 * math.sin(a)) for a in angles]
    n = max(1, revs // 10)
    t = time.perf_counter()
    for _ in range(n):
        for end in ends:
            space.segment_query_first(origin, end, 0.0, flt)
    out["pymunk"] = n / (time.perf_counter() - t)
    out["segments"] = len(segs)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args()
    seconds = 20.0 if args.quick else 60.0
    repeats = 2 if args.quick else 3
    revs = 200 if args.quick else 2000
    figures: dict[str, float] = {}
    load = os.getloadavg()[0]
    figures["load_avg_1min"] = round(load, 2)
    print(f"world alone, 3 rovers driving, {seconds:g} simulated s per run, best of {repeats} "
          f"(load average {load:.2f} on {os.cpu_count()} cores)")
    print(f"{'scenario':<10} {'tick ms':>7} {'full x':>7} {'cpu x':>6} {'no sensors x':>13} "
          f"{'cpu x':>6} {'ratio':>6}")
    for name in SCENARIOS:
        for tick in (0.02, 0.05):
            full, full_cpu = best_of(repeats, name, tick, seconds, sensors=True)
            base, base_cpu = best_of(repeats, name, tick, seconds, sensors=False)
            key = f"{name}_{int(tick * 1000)}ms"
            figures[f"rtf_{key}"] = round(full, 1)
            figures[f"rtf_cpu_{key}"] = round(full_cpu, 1)
            figures[f"rtf_nosensors_{key}"] = round(base, 1)
            figures[f"rtf_cpu_nosensors_{key}"] = round(base_cpu, 1)
            figures[f"ratio_{key}"] = round(full_cpu / base_cpu, 3)
            print(f"{name:<10} {tick * 1000:>7.0f} {full:>7.0f} {full_cpu:>6.0f} {base:>13.0f} "
                  f"{base_cpu:>6.0f} {full_cpu / base_cpu:>6.2f}")
    print()
    print("LIDAR ray casting, 360 rays per revolution (revolutions/s), and one 99-ray tick")
    print(f"{'scenario':<10} {'segments':>8} {'fan':>7} {'all-pairs':>9} {'pymunk':>7} "
          f"{'fan/pymunk':>10} {'tick us':>8}")
    for name in SCENARIOS:
        r = lidar_revs(name, revs)
        figures[f"lidar_rev_s_{name}"] = round(r["fan"], 1)
        figures[f"lidar_rev_s_pairs_{name}"] = round(r["pairs"], 1)
        figures[f"lidar_rev_s_pymunk_{name}"] = round(r["pymunk"], 1)
        figures[f"lidar_ratio_{name}"] = round(r["fan"] / r["pymunk"], 2)
        figures[f"lidar_tick_us_{name}"] = round(r["fan_tick_us"], 1)
        print(f"{name:<10} {r['segments']:>8} {r['fan']:>7.0f} {r['pairs']:>9.0f} "
              f"{r['pymunk']:>7.0f} {r['fan'] / r['pymunk']:>10.2f} {r['fan_tick_us']:>8.1f}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
