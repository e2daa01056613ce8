"""One seed, one event stream; and `run_world` paces the world on Trio's clock."""

from __future__ import annotations

import numpy as np
import pytest
import trio
import trio.testing

from world.scenario import load_scenario
from world.world import World, run_world


def record(seed: int, seconds: float = 3.0) -> list[tuple]:
    """Drive all three rovers with fixed commands and record every device event."""
    world = World(load_scenario("furniture"), np.random.default_rng(seed))
    events: list[tuple] = []
    for role in ("mapper", "hider", "seeker"):
        hw = world.hardware(role)
        for line in (0xA, 0xB, 0xC, 0xD, 0xE):
            hw.attach(line, lambda p, r=role, ln=line: events.append((world.ticks, r, ln, p)))
    link = world.wifly_link("hider")
    link.on_server_receive = lambda b: events.append((world.ticks, "server", 0, b))
    world.inject_fault("hider/wifly", "corrupt", per_byte=0.02)
    world.hardware("mapper").set_lidar_pwm(0.5)
    world.hardware("seeker").set_ir_timer(25)
    seeker = world.hardware("seeker")
    seeker.attach(0xD, lambda _: seeker.start_adc())
    for k in range(int(seconds / world.tick_s)):
        if k % 10 == 0:
            world.hardware("mapper").set_tread_pwm(0.5, 0.3)
            world.hardware("hider").set_tread_pwm(-0.4, 0.4)
            world.hardware("seeker").set_tread_pwm(0.6, 0.6)
            world.hardware("hider").wifly_write(b'{"cmd": "hello"}\n')
        world.step()
    return events


def test_same_seed_gives_identical_event_streams() -> None:
    a, b = record(42), record(42)
    assert len(a) > 500
    assert {e[2] for e in a} >= {0xA, 0xC, 0xE, 0}
    assert a == b


def test_different_seeds_give_different_streams() -> None:
    assert record(1) != record(2)


def test_run_world_steps_on_virtual_time() -> None:
    """A 60 s world run takes 60 s of Trio time and no real waiting."""
    world = World(load_scenario("empty"), np.random.default_rng(0))
    world.hardware("mapper").set_tread_pwm(0.5, 0.5)

    async def main() -> float:
        start = trio.current_time()
        await run_world(world, stop_at=60.0)
        return trio.current_time() - start

    elapsed = trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert elapsed == pytest.approx(60.0)
    assert world.time == pytest.approx(60.0)
    assert world.true_pose("mapper").x > 300


def test_run_world_ticks_line_up_with_trio_time() -> None:
    """Each tick happens at its own Trio time, so other tasks see the world advance."""
    world = World(load_scenario("empty"), np.random.default_rng(0))
    seen: list[tuple[float, float]] = []

    async def main() -> None:
        start = trio.current_time()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(run_world, world, 1.0)
            for _ in range(4):
                await trio.sleep(0.25)
                seen.append((trio.current_time() - start, world.time))

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    for t, wt in seen:
        assert wt == pytest.approx(t, abs=world.tick_s + 1e-9)
