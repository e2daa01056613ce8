"""The mapper's origin: Map Management's scan matching correction, kept by navigation.

The real Map Management and mapping navigation beside the fake motor, WiFly and
LIDAR of `test_nav_common`: the correction goes to navigation (not to Motor
Control), navigation plans and reports in the map frame through it, and each of
the two keeps it across the other's restart.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Any

import pytest
import trio

from actors import BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.hardware import HardwareSpec
from actors.firmware.mapping.map_management import MapManagement
from actors.firmware.nav.factory import make_nav
from actors.firmware.nav.options import NavMemory
from server.protocol.pose import Pose, compose
from supervisors import ChildSpec, SupervisorSpec
from tests.test_nav_common import Body, FakeLidar, FakeMotor, FakeWifly, net, wait_for

BENCH = HardwareSpec.bench("mapper")

CORRECTION = Pose(5.0, -2.0, 90.0)  # odometry -> map frame, as scan matching might find it


def mapper_tree(body: Body, pool: BufferPool, memory: NavMemory) -> SupervisorSpec:
    """Fake motor, WiFly and LIDAR; the real Map Management and navigation."""
    map_starts = [0]

    def make_map() -> MapManagement:
        map_starts[0] += 1
        return MapManagement(pool, BENCH, size_cm=(400, 400), restarted=map_starts[0] > 1)

    return SupervisorSpec([
        ChildSpec("motor", lambda: FakeMotor(body), mailbox=64),
        ChildSpec("wifly", lambda: FakeWifly(body, pool), mailbox=64),
        ChildSpec("lidar", lambda: FakeLidar(body), mailbox=16),
        ChildSpec("map", make_map, mailbox=64),
        ChildSpec("nav", lambda: make_nav("mapper", pool=pool, memory=memory), mailbox=256),
    ], intensity=20, period=1.0)


def actor(system: Any, name: str) -> Any:
    """The running incarnation of ``name`` (None between two)."""
    cell = system.whereis(name)
    return cell.actor if cell is not None else None


@contextlib.asynccontextmanager
async def corrected_mapper() -> AsyncIterator[tuple[Any, Body, BufferPool, NavMemory]]:
    """The mapper tree at odometry pose (100, 0) @ 0, once Map Management's scan matching
    found ``CORRECTION`` and published it (its next publication sends it)."""
    body = Body(pose=Pose(100.0, 0.0, 0.0))
    pool, memory = BufferPool(64), NavMemory()
    async with open_actor_system(seed=1) as system:
        await system.start_supervisor(mapper_tree(body, pool, memory), "mapper")
        await trio.sleep(0.5)
        actor(system, "mapper/map").localiser.restart_at(CORRECTION)
        await system.send("mapper/map", Message.uint(Cmd.MAP_GET, 0))
        await trio.sleep(0.1)
        yield system, body, pool, memory


async def restart(system: Any, name: str) -> Any:
    """Crash ``name``; its next incarnation, once running."""
    first = actor(system, name)
    system.inject_crash(name)
    assert await wait_for(lambda: actor(system, name) not in (None, first), 2.0, 0.01)
    return actor(system, name)


def same_pose(a: Pose | None, b: Pose, tol: float = 0.051) -> bool:
    """Equal within the wire's millimetre (and float32 heading)."""
    return a is not None and abs(a.x - b.x) <= tol and abs(a.y - b.y) <= tol and \
        abs(a.heading_deg - b.heading_deg) <= 1e-3


@pytest.mark.trio
async def test_the_correction_becomes_navigations_origin_not_motor_controls(
        autojump_clock) -> None:
    """Map Management's correction reaches navigation (NAV_MAP_ORIGIN_*): its map-frame pose
    and its pose reports are the correction composed with the odometry pose, it is
    retained, Motor Control hears nothing of it, and the server's identity ``origin``
    (sent with ``start``) does not undo it."""
    async with corrected_mapper() as (system, body, pool, memory):
        nav = actor(system, "mapper/nav")
        assert same_pose(nav.origin, CORRECTION)
        assert same_pose(Pose(*memory.origin), CORRECTION)
        want = compose(CORRECTION, body.pose)  # (5, 98) @ 90
        assert same_pose(nav.map_pose, want)
        await net(system, pool, "mapper", "origin", {"x": 0.0, "y": 0.0, "heading": 0.0})
        await trio.sleep(2.0)
        assert same_pose(nav.origin, CORRECTION)
        last = body.frames("pose")[-1].data
        assert (last["x"], last["y"], last["heading"]) == (5.0, 98.0, 90.0)
        assert {c for c, _ in body.motor_log} <= {"MOTOR_STOP", "MOTOR_GET_POSE"}


@pytest.mark.trio
async def test_a_restarted_map_management_takes_the_correction_back_from_navigation(
        autojump_clock) -> None:
    """Map Management crashes: its new incarnation asks navigation (NAV_MAP_LOST) and
    starts from the correction navigation kept, not from the identity."""
    async with corrected_mapper() as (system, _, _, _):
        again = await restart(system, "mapper/map")
        await trio.sleep(0.2)
        assert again.restarted
        assert same_pose(again.localiser.correction, CORRECTION)
        assert same_pose(actor(system, "mapper/nav").origin, CORRECTION)


@pytest.mark.trio
async def test_a_restarted_navigation_keeps_the_origin(autojump_clock) -> None:
    """Navigation crashes: its new incarnation has the origin from `NavMemory`, its
    map-frame pose and reports go through it, and it hands the origin to a Map Management
    restarted after it."""
    async with corrected_mapper() as (system, body, _, _):
        nav = await restart(system, "mapper/nav")
        await trio.sleep(2.0)
        assert nav.restarted and same_pose(nav.origin, CORRECTION)
        assert same_pose(nav.map_pose, compose(CORRECTION, body.pose))
        last = body.frames("pose")[-1].data
        assert (last["x"], last["y"], last["heading"]) == (5.0, 98.0, 90.0)
        again = await restart(system, "mapper/map")
        await trio.sleep(0.2)
        assert same_pose(again.localiser.correction, CORRECTION)
