"""A scenario's [[faults]] for a rover attached over a link (`supervisors.attached_faults`)."""

from __future__ import annotations

import pathlib

import trio
import trio.testing

from supervisors.attached_faults import attached_schedule, send_scheduled_faults, simulated_only
from world.scenario import parse_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCHEDULE = """
[[faults]]
at_s = 2
target = "mapper/lidar"
kind = "dead"
duration_s = 3

[[faults]]
at_s = 1
target = "hider/motor"
kind = "stalled"

[[faults]]
at_s = 4
target = "mapper/nav"
kind = "crash"
"""


def _scenario():
    text = (ROOT / "world/scenarios/empty.toml").read_text() + SCHEDULE
    return parse_scenario(text)


def test_faults_of_attached_roles_leave_the_world_and_the_rest_stay() -> None:
    """With the mapper attached, its faults are the schedule sent over the link and the
    world keeps only the hider's; with every rover simulated nothing changes."""
    scenario = _scenario()
    simulated = ("hider", "seeker")
    assert [f.target for f in attached_schedule(scenario, simulated)] == ["mapper/lidar",
                                                                          "mapper/nav"]
    assert [f.target for f in simulated_only(scenario, simulated).faults] == ["hider/motor"]
    assert simulated_only(scenario, ("mapper", "hider", "seeker")) is scenario


def test_scheduled_faults_go_to_the_attached_rover_at_their_time() -> None:
    """Each fault is handed to the server's rover_fault at its time (by role); one the
    server refuses is reported, and the others still go."""
    calls: list[tuple] = []
    refused: list[str] = []

    class Server:
        def rover_fault(self, rover, op, target, kind, duration_s, params):
            calls.append((round(trio.current_time()), rover, op, target, kind, duration_s))
            if kind == "dead":
                raise ValueError("no attached rover 'mapper'")
            return "sent"

    async def main() -> None:
        faults = attached_schedule(_scenario(), ("hider", "seeker"))
        await send_scheduled_faults(Server(), faults, refused.append)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert calls == [(2, "mapper", "inject", "lidar", "dead", 3.0),
                     (4, "mapper", "inject", "nav", "crash", 0.0)]
    assert refused == ["scheduled dead on mapper/lidar at 2 s: no attached rover 'mapper'"]
