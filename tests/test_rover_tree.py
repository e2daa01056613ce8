"""Rover supervision trees against the simulated world and the real server."""

from __future__ import annotations

import numpy as np
import pytest
import trio

from actors import Actor, BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from server.protocol import make_frame
from server.protocol.grid_map import GridMap
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors.rover import MAILBOX, rover_tree
from world import World, load_scenario, run_world


class RecorderNav(Actor):
    """Stand-in navigation: logs (time, command, payload) and takes pooled payloads."""

    def __init__(self, role: str, pool: BufferPool, logs: dict) -> None:
        self.role, self.pool, self.log = role, pool, logs.setdefault(role, [])

    async def handle(self, m: Message) -> None:
        payload = self.pool.take(int(m.value)) if m.type == 4 else m.value
        self.log.append((trio.current_time(), m.command, payload))


def recorder_factory(logs: dict):
    def make(role, *, pool, **_):
        return RecorderNav(role, pool, logs)
    return make


async def wait_until(predicate, timeout: float = 30.0) -> None:
    with trio.fail_after(timeout):
        while not predicate():
            await trio.sleep(0.1)


def seen(log, command, pred=lambda p: True) -> list:
    return [p for _, c, p in log if c == command and pred(p)]


@pytest.mark.trio
async def test_three_trees_connect_map_and_upload(autojump_clock, tmp_path) -> None:
    """Every rover says hello; the mapper's tree turns LIDAR bytes into map updates and
    uploads a map the server assembles."""
    world = World(load_scenario("empty"), np.random.default_rng(1))
    logs: dict = {}
    store = Store(tmp_path / "db.sqlite")
    async with open_server(store, ServerConfig()) as server, trio.open_nursery() as nursery, \
            open_actor_system(1) as system:
        for role in ("mapper", "hider", "seeker"):
            link = world.wifly_link(role)
            memory = server.attach_memory(outbound=link.server_write, name=f"sim:{role}")
            link.on_server_receive = memory.feed
        nursery.start_soon(run_world, world)
        for role in ("mapper", "hider", "seeker"):
            spec = rover_tree(role, world.hardware(role), nav_factory=recorder_factory(logs))
            await system.start_supervisor(spec, role)
        await wait_until(lambda: all(seen(logs.get(r, []), Cmd.NAV_LINK, lambda v: v == 1)
                                     for r in ("mapper", "hider", "seeker")))
        assert (await server.command("start_mapping")).ok
        mlog = logs["mapper"]
        await wait_until(lambda: seen(mlog, Cmd.NAV_NET, lambda f: f.cmd == "start"))
        await system.send("mapper/lidar", Message.float(Cmd.LIDAR_START, 0.5))
        await wait_until(lambda: seen(mlog, Cmd.NAV_SCAN_COUNT, lambda n: n >= 20))
        snap = seen(mlog, Cmd.NAV_MAP_UPDATE)[-1]
        assert isinstance(snap, GridMap)
        known = int(np.count_nonzero(snap.cells != -1))
        assert known > 1000  # a 4 x 3 m room seen from inside
        assert int(np.count_nonzero(snap.cells == 100)) > 100  # walls
        # the wall 50 cm behind the mapper (room x = 0) is occupied in the rover frame
        r, c = snap.world_to_cell(-51.0, 0.0)
        assert (snap.cells[r, c - 1: c + 2] == 100).any()
        cropped = snap.crop_known(1)
        tree_pool = _pool_of(system, "mapper")
        await system.send("mapper/wifly",
                          Message.handle(Cmd.WIFLY_SEND_MAP, tree_pool.put(cropped)))
        await wait_until(lambda: server.snapshot().map is not None)
        got = server.snapshot().map
        assert got.cells.shape == cropped.cells.shape
        assert (got.cells == cropped.cells).mean() > 0.99
        # navigation asks for the pose (as after its own restart) and gets it
        await system.send("mapper/motor", Message.uint(Cmd.MOTOR_GET_POSE, 0))
        await wait_until(lambda: seen(mlog, Cmd.NAV_POSE_HEADING), timeout=1)
        assert seen(mlog, Cmd.NAV_POSE_XY)[-1] == Message.pair(0, 0, 0).value
        nursery.cancel_scope.cancel()
    store.close()


def _pool_of(system, role: str) -> BufferPool:
    """The rover's pool, reached through its navigation actor (test only)."""
    return system.whereis(f"{role}/nav").actor.pool


@pytest.mark.trio
async def test_reliable_report_survives_a_link_drop_exactly_once(autojump_clock,
                                                                 tmp_path) -> None:
    """Frames sent while the WiFly link is down arrive once after the reconnect."""
    world = World(load_scenario("empty"), np.random.default_rng(2))
    logs: dict = {}
    store = Store(tmp_path / "db.sqlite")
    async with open_server(store, ServerConfig()) as server, trio.open_nursery() as nursery, \
            open_actor_system(2) as system:
        events = server.subscribe(4096)
        link = world.wifly_link("hider")
        memory = server.attach_memory(outbound=link.server_write, name="sim:hider")
        link.on_server_receive = memory.feed
        nursery.start_soon(run_world, world)
        await system.start_supervisor(
            rover_tree("hider", world.hardware("hider"), nav_factory=recorder_factory(logs)),
            "hider")
        hlog = logs["hider"]
        await wait_until(lambda: seen(hlog, Cmd.NAV_LINK, lambda v: v == 1))
        world.inject_fault("hider/wifly", "down", 12.0)
        pool = _pool_of(system, "hider")
        await trio.sleep(0.5)
        for k in range(5):
            frame = make_frame("invalid_spot", {"reason": f"test {k}"})
            await system.send("hider/wifly", Message.handle(Cmd.WIFLY_SEND, pool.put(frame)))
        await wait_until(lambda: seen(hlog, Cmd.NAV_LINK, lambda v: v == 0), timeout=10)
        await wait_until(lambda: len(seen(hlog, Cmd.NAV_LINK, lambda v: v == 1)) >= 2,
                         timeout=40)
        await trio.sleep(3.0)
        reports = []
        while True:
            try:
                ev = events.receive_nowait()
            except trio.WouldBlock:
                break
            if ev.kind == "report":
                reports.append(ev.data["report"])
        assert reports == ["invalid_spot"] * 5  # none lost, none duplicated
        wifly = system.whereis("hider/wifly").actor
        assert wifly.statistics()["unacked"] == 0
        assert wifly.hellos >= 2  # it did reconnect
        nursery.cancel_scope.cancel()
    store.close()


def test_tree_shape_per_role() -> None:
    """Mapper has lidar+map, seeker has ir, all have wifly, motor, nav; bad role refused."""
    class HW:
        from actors.firmware.hardware import HardwareSpec
        spec = HardwareSpec("hider", 0.5, 13.0)
    ids = {r: [c.id for c in rover_tree(r, HW()).children] for r in ("mapper", "hider", "seeker")}
    assert ids == {"mapper": ["wifly", "motor", "lidar", "map", "nav"],
                   "hider": ["wifly", "motor", "nav"],
                   "seeker": ["wifly", "motor", "ir", "nav"]}
    assert all(c.mailbox == MAILBOX[c.id] for c in rover_tree("mapper", HW()).children)
    with pytest.raises(ValueError, match="role must be one of mapper, hider, seeker, got 'x'"):
        rover_tree("x", HW())


@pytest.mark.trio
async def test_drivers_are_wired_by_the_init_hook_not_a_replaced_on_start() -> None:
    """Each driver's child spec carries the tree's ``init`` hook (navigation's does not),
    and the actors the tree makes keep their class's own ``on_start``."""
    class HW:
        from actors.firmware.hardware import HardwareSpec
        spec = HardwareSpec("mapper", 0.5, 13.0)
    children = rover_tree("mapper", HW(), nav_factory=recorder_factory({})).children
    assert {c.id: c.init is not None for c in children} == {
        "wifly": True, "motor": True, "lidar": True, "map": True, "nav": False}
    for c in children:
        assert "on_start" not in vars(c.start())


@pytest.mark.trio
async def test_a_restarted_motor_still_hears_its_counter_isr(autojump_clock) -> None:
    """After Motor Control crashes and restarts, Int E still reaches its mailbox: a move
    commanded to the new incarnation completes."""
    world = World(load_scenario("empty"), np.random.default_rng(1))
    logs: dict = {}
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        nursery.start_soon(run_world, world)
        await system.start_supervisor(
            rover_tree("hider", world.hardware("hider"), nav_factory=recorder_factory(logs)),
            "hider")
        first = system.whereis("hider/motor").actor
        await system.send("hider/motor", Message.uint(0xFFFF, 0))  # an unknown command: crash
        await wait_until(lambda: (cell := system.whereis("hider/motor")) is not None
                         and cell.actor is not first, timeout=5)
        await system.send("hider/motor", Message.float(Cmd.MOTOR_MOVE, 30.0))
        await wait_until(lambda: seen(logs["hider"], Cmd.NAV_MOTION_DONE), timeout=20)
        nursery.cancel_scope.cancel()
