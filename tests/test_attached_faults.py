"""A scenario's [[faults]] for a rover attached over a link (`supervisors.attached_faults`)."""

from __future__ import annotations

import pathlib
import re

import numpy as np
import pytest
import trio
import trio.testing

from server.link_faults import LINK_TARGET
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors.attached_faults import attached_schedule, send_scheduled_faults, simulated_only
from tests.fake_rover import FakeRover, attach_outside
from world.scenario import LINK, ScenarioError, parse_scenario
from world.world import World

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


LINK_SCHEDULE = """
[[faults]]
at_s = 2
target = "mapper/link"
kind = "loss"
duration_s = 20
params = { percent = 30 }
"""


def test_a_scheduled_link_fault_breaks_an_attached_rovers_link_through_the_server() -> None:
    """``mapper/link loss`` in [[faults]] parses with the link's parameters and, at its
    time, reaches the attached mapper's link as the serve prompt's fault does."""
    scenario = parse_scenario((ROOT / "world/scenarios/empty.toml").read_text() + LINK_SCHEDULE)
    assert [(f.target, f.kind, f.params) for f in scenario.faults] == [
        ("mapper/link", "loss", {"percent": 30.0})]
    seen: list[list] = []
    refused: list[str] = []

    async def main() -> None:
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"m1"}))) as server:
                async with trio.open_nursery() as nursery:
                    await attach_outside(server, nursery, FakeRover("m1", "mapper"))
                    await send_scheduled_faults(
                        server, attached_schedule(scenario, ("hider", "seeker")), refused.append)
                    seen.append([(f.kind, f.params, f.duration_s)
                                 for f in server.link_faults_of("m1")])
                    nursery.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert seen == [[("loss", {"percent": 30.0}, 20.0)]] and refused == []
    assert LINK == LINK_TARGET


def test_a_scheduled_link_fault_is_a_simulated_rovers_wifly_fault() -> None:
    """With the mapper simulated the same entry breaks its WiFly in the world."""
    scenario = parse_scenario((ROOT / "world/scenarios/empty.toml").read_text() + LINK_SCHEDULE)
    world = World(scenario, np.random.default_rng(1))
    while world.time < 2.5:
        world.step()
    assert [(f.target, f.kind, f.params) for f in world.active_faults()] == [
        ("mapper/wifly", "loss", {"percent": 30.0})]


@pytest.mark.parametrize(("kind", "params", "message"), [
    ("crash", "{ }", "link faults are down, loss, corrupt, latency, got 'crash'"),
    ("dead", "{ }", "link faults are down, loss, corrupt, latency, got 'dead'"),
    ("loss", "{ ratio = 1 }", "fault 'loss' has no parameter 'ratio' (parameters: percent)"),
])
def test_a_scheduled_link_fault_with_a_wrong_kind_or_parameter_is_refused(
        kind: str, params: str, message: str) -> None:
    text = (ROOT / "world/scenarios/empty.toml").read_text() + (
        f'[[faults]]\nat_s = 1\ntarget = "mapper/link"\nkind = "{kind}"\nparams = {params}\n')
    with pytest.raises(ScenarioError, match=re.escape(f"faults[0]: {message}")):
        parse_scenario(text)
