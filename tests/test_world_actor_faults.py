"""Scheduled actor faults on actors named like devices reach the actor runtime."""

from __future__ import annotations

from importlib import resources

import numpy as np
import trio

from actors import seed_trio_scheduler, virtual_clock
from server.store import Store
from supervisors.system import open_sim_system
from world.scenario import parse_scenario
from world.world import World

SCHEDULE = """
[[faults]]
at_s = 1
target = "hider/motor"
kind = "crash"
[[faults]]
at_s = 1.5
target = "mapper/lidar"
kind = "hang"
duration_s = 2
[[faults]]
at_s = 2
target = "seeker/ir"
kind = "flood"
params = { messages = 20 }
[[faults]]
at_s = 2.5
target = "seeker/wifly"
kind = "crash"
[[faults]]
at_s = 3
target = "hider/motor"
kind = "weak"
duration_s = 1
"""


def test_scheduled_crash_hang_flood_on_device_named_actors_are_performed() -> None:
    """hider/motor crash, mapper/lidar hang, seeker/ir flood and seeker/wifly crash reach the
    actors; hider/motor weak, a device fault on the same name, reaches the world."""
    text = resources.files("world.scenarios").joinpath("empty.toml").read_text(encoding="utf-8")
    scenario = parse_scenario(text + SCHEDULE, "empty+faults")
    seen: dict = {}

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_sim_system(scenario, seed=1, store=store) as system:
                await trio.sleep(3.2)
                seen["device"] = [(f.target, f.kind) for f in system.world.active_faults()]
                await trio.sleep(2.0)
                seen["faults"] = [(f["target"], f["kind"]) for f in system.faults]
                seen["exits"] = {name: str(system.actors.whereis(name).last_exit.kind)
                                 for name in ("hider/motor", "mapper/lidar", "seeker/wifly")}

    seed_trio_scheduler(1)
    trio.run(main, clock=virtual_clock())
    assert seen["faults"][:4] == [("hider/motor", "crash"), ("mapper/lidar", "hang"),
                                  ("seeker/ir", "flood"), ("seeker/wifly", "crash")]
    assert seen["exits"] == {"hider/motor": "crash", "mapper/lidar": "hung",
                             "seeker/wifly": "crash"}
    assert seen["device"] == [("hider/motor", "weak")]


def test_next_actor_fault_time_follows_the_schedule_and_ends_with_none() -> None:
    """A poller can sleep until the next scheduled actor fault and stop after the last."""
    text = resources.files("world.scenarios").joinpath("empty.toml").read_text(encoding="utf-8")
    world = World(parse_scenario(text + SCHEDULE, "empty+faults"), np.random.default_rng(1))
    assert world.next_actor_fault_s() == 1.0  # the device fault at 3 s is not an actor's
    while world.time < 1.6:
        world.step()
    assert [f.kind for f in world.actor_faults_due()] == ["crash", "hang"]
    assert world.next_actor_fault_s() == 2.0
    while world.time < 2.6:
        world.step()
    world.actor_faults_due()
    assert world.next_actor_fault_s() is None
