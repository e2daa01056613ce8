"""Benchmark: simulated seconds per wall second of the world alone, and LIDAR ray casting.

Run as ``python -m benchmarks.world [--quick]``. The world runs with three
rovers driving (seeded random PWM, changed every second), the LIDAR spinning
at PWM 0.5 (5.5 rev/s, 1980 samples/s) and the IR sampling at 20 Hz, with no
firmware attached (handlers only count). The baseline measured in the same run
is the same world with the LIDAR and IR off (physics, motors, encoders only).
The ray caster is timed for whole 360-ray revolutions against the room's
segments, with pymunk segment queries as its baseline.
Prints a table, then one line of JSON with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import pymunk

from world.geometry import boundary_segments, room_segments
from world.raycast import cast_rays
from world.scenario import load_scenario
from world.world import World

SCENARIOS = ("furniture", "round", "hall")


def run_world(name: str, tick_s: float, seconds: float, sensors: bool) -> float:
    """Simulated seconds per wall second."""
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
    next_cmd = 0.0
    while world.time < seconds:
        if world.time >= next_cmd:
            for role in ("mapper", "hider", "seeker"):
                world.hardware(role).set_tread_pwm(*cmd.uniform(-0.3, 1.0, 2))
            next_cmd += 1.0
        world.step()
    return world.time / (time.perf_counter() - start)


def lidar_revs(name: str, revs: int) -> tuple[float, float, int]:
    """Revolutions/s of the numpy caster and of pymunk segment queries; segment count."""
    s = load_scenario(name)
    segs = np.vstack([room_segments(*s.room_size), boundary_segments(list(s.obstacles))])
    origin = (s.starts["mapper"].x + 100.0, s.starts["mapper"].y + 100.0)
    angles = np.radians(np.arange(360.0))
    t = time.perf_counter()
    for _ in range(revs):
        cast_rays(origin, angles, segs, 4000.0)
    ours = revs / (time.perf_counter() - t)
    space = pymunk.Space()
    space.add(*[pymunk.Segment(space.static_body, (a, b), (c, d), 0.0) for a, b, c, d in segs])
    flt = pymunk.ShapeFilter()
    ends = [(origin[0] + 4000 * math.cos(a), origin[1] + 4000 * math.sin(a)) for a in angles]
    n = max(1, revs // 10)
    t = time.perf_counter()
    for _ in range(n):
        for end in ends:
            space.segment_query_first(origin, end, 0.0, flt)
    theirs = n / (time.perf_counter() - t)
    return ours, theirs, len(segs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs")
    args = parser.parse_args()
    seconds = 20.0 if args.quick else 120.0
    revs = 200 if args.quick else 2000
    figures: dict[str, float] = {}
    print(f"world alone, 3 rovers driving, {seconds:g} simulated s per run")
    print(f"{'scenario':<10} {'tick ms':>7} {'full x':>8} {'no sensors x':>13} {'ratio':>6}")
    for name in SCENARIOS:
        for tick in (0.02, 0.05):
            full = run_world(name, tick, seconds, sensors=True)
            base = run_world(name, tick, seconds, sensors=False)
            key = f"{name}_{int(tick * 1000)}ms"
            figures[f"rtf_{key}"] = round(full, 1)
            figures[f"rtf_nosensors_{key}"] = round(base, 1)
            figures[f"ratio_{key}"] = round(full / base, 3)
            print(f"{name:<10} {tick * 1000:>7.0f} {full:>8.0f} {base:>13.0f} {full / base:>6.2f}")
    print()
    print("LIDAR ray casting, 360 rays per revolution")
    print(f"{'scenario':<10} {'segments':>8} {'numpy rev/s':>12} {'pymunk rev/s':>13} {'ratio':>6}")
    for name in SCENARIOS:
        ours, theirs, nseg = lidar_revs(name, revs)
        figures[f"lidar_rev_s_{name}"] = round(ours, 1)
        figures[f"lidar_rev_s_pymunk_{name}"] = round(theirs, 1)
        figures[f"lidar_ratio_{name}"] = round(ours / theirs, 2)
        print(f"{name:<10} {nseg:>8} {ours:>12.0f} {theirs:>13.0f} {ours / theirs:>6.2f}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
