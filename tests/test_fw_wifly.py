"""WiFly in isolation against a fake server end (a ReliableSession speaking the protocol)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
import trio

from actors import BufferPool, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.wifly import Wifly
from actors.firmware.hardware import Interrupt
from server.protocol import (
    GridMap,
    MapAssembler,
    ReliableSession,
    decode_line,
    make_frame,
    map_chunks,
    read_data,
)
from supervisors import ChildSpec, SupervisorSpec

from .test_fw_lidar import Recorder
from .test_fw_motor import FakeHardware


class FakeServer:
    """The server's end: welcomes hello, records delivered frames, can go deaf."""

    def __init__(self, hw: FakeHardware) -> None:
        self.session = ReliableSession(now=trio.current_time())
        self.got: list = []
        self.deaf = False
        self.hw = hw
        hw.wifly_write = self.from_rover

    def from_rover(self, data: bytes) -> None:
        if self.deaf:
            return
        for f in self.session.feed(data, trio.current_time()):
            self.got.append(f)
            if f.cmd == "hello":
                hello = read_data(f)
                self.session.reset_peer(hello.seq_base, hello.session)
                self.session.send(make_frame("welcome", self.welcome()))

    def welcome(self) -> dict:
        """The welcome's data now, as the server says it (its session id included)."""
        return {"server": "fake/1", "heartbeat_s": 1.0, "down_after_s": 5.0,
                "seq_base": self.session.seq_base, "session": self.session.session_id}

    async def run(self) -> None:
        while True:
            data = self.session.transmit(trio.current_time())
            isr = self.hw.handlers.get(Interrupt.INT_B)
            if data and isr is not None and not self.deaf:
                isr(data)
            await trio.sleep(0.05)


@contextlib.asynccontextmanager
async def linked_wifly():
    """A hider's WiFly linked to a `FakeServer`, one second after start (welcomed).

    Yields (system, server, tree, pool, log); the server stops on exit."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        server = FakeServer(hw)
        nursery.start_soon(server.run)
        tree = await system.start_supervisor(wifly_tree(hw, pool, log), "hider")
        await trio.sleep(1.0)
        yield system, server, tree, pool, log
        nursery.cancel_scope.cancel()


def arrived(pool: BufferPool) -> Message:
    """A WIFLY_SEND of an ``arrived`` report, as navigation posts it."""
    return Message.handle(Cmd.WIFLY_SEND,
                          pool.put(make_frame("arrived", {"x": 1, "y": 2, "heading": 3})))


def wifly_tree(hw, pool, log):
    return SupervisorSpec([
        ChildSpec("nav", lambda: Recorder(log, pool)),
        ChildSpec("wifly", lambda: Wifly(hw, pool, rover_id="hider-1", role="hider"),
                  mailbox=256)])


@pytest.mark.trio
async def test_hello_welcome_frames_and_map_download(autojump_clock) -> None:
    """Hello until welcome (NAV_LINK 1); frames go to nav; map chunks arrive as one map."""
    async with linked_wifly() as (system, server, _tree, pool, log):
        assert (Cmd.NAV_LINK, 1) in log
        assert server.got[0].cmd == "hello" and read_data(server.got[0]).id == "hider-1"
        server.session.send(make_frame("start"))
        cells = np.zeros((40, 60), dtype=np.int8)
        cells[0, :] = 100
        cells[5:9, 5:9] = -1
        for f in map_chunks(GridMap(cells, 5.0, (-10.0, -20.0)), map_id=7):
            server.session.send(f, reliable=True)
        await trio.sleep(3.0)
        frames = [p for c, p in log if c == Cmd.NAV_NET]
        assert [f.cmd for f in frames] == ["start"]
        (grid,) = [p for c, p in log if c == Cmd.NAV_MAP_DOWNLOAD]
        assert isinstance(grid, GridMap) and np.array_equal(grid.cells, cells)
        assert grid.origin_cm == (-10.0, -20.0)


@pytest.mark.trio
async def test_deaf_server_then_reconnect_loses_and_duplicates_nothing(autojump_clock) -> None:
    """Reliable frames and a map sent while the server is deaf arrive once, in order."""
    async with linked_wifly() as (system, server, _tree, pool, log):
        server.deaf = True
        for k in range(3):
            frame = make_frame("invalid_spot", {"reason": f"r{k}"})
            await system.send("hider/wifly", Message.handle(Cmd.WIFLY_SEND, pool.put(frame)))
        snap = GridMap(np.zeros((30, 30), dtype=np.int8), 5.0, (0.0, 0.0))
        await system.send("hider/wifly", Message.handle(Cmd.WIFLY_SEND_MAP, pool.put(snap)))
        await trio.sleep(8.0)
        assert (Cmd.NAV_LINK, 0) in log
        server.deaf = False
        await trio.sleep(20.0)
        assert [p for c, p in log if c == Cmd.NAV_LINK] == [1, 0, 1]
        reports = [read_data(f).reason for f in server.got if f.cmd == "invalid_spot"]
        assert reports == ["r0", "r1", "r2"]
        assembler = MapAssembler()
        maps = [m for f in server.got if f.cmd == "map"
                if (m := assembler.add(read_data(f))) is not None]
        assert len(maps) == 1 and maps[0].cells.shape == (30, 30)
        assert system.whereis("hider/wifly").actor.statistics()["unacked"] == 0


@pytest.mark.trio
async def test_restart_keeps_unacknowledged_frames(autojump_clock) -> None:
    """A WiFly crash while frames are unacknowledged: the new incarnation resends them."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    from actors.firmware.drivers.wifly import LinkMemory
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        server = FakeServer(hw)
        nursery.start_soon(server.run)
        memory = LinkMemory()
        spec = SupervisorSpec([
            ChildSpec("nav", lambda: Recorder(log, pool)),
            ChildSpec("wifly", lambda: Wifly(hw, pool, rover_id="h", role="hider",
                                             memory=memory))])
        await system.start_supervisor(spec, "hider")
        await trio.sleep(1.0)
        server.deaf = True
        await system.send("hider/wifly", arrived(pool))
        await trio.sleep(0.5)
        system.inject_crash("hider/wifly")
        await trio.sleep(0.5)
        server.deaf = False
        await trio.sleep(15.0)
        assert [f.cmd for f in server.got].count("arrived") == 1
        nursery.cancel_scope.cancel()


@pytest.mark.trio
@pytest.mark.parametrize("hold", [True, False])
async def test_hold_until_welcome_sends_only_hellos_before_the_welcome(autojump_clock,
                                                                      hold) -> None:
    """With hold_until_welcome (a rover on a real link) every frame before the welcome is
    a hello, and what navigation queued meanwhile follows it; without (the in-memory
    link) the session's frames and heartbeats go out from the start."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        server = FakeServer(hw)
        written: list[str] = []
        to_server = hw.wifly_write

        def wire(data: bytes) -> None:  # every frame the rover writes, heard or not
            written.extend(decode_line(ln).cmd for ln in data.splitlines() if ln.strip())
            to_server(data)

        hw.wifly_write = wire
        server.deaf = True
        nursery.start_soon(server.run)
        spec = SupervisorSpec([
            ChildSpec("nav", lambda: Recorder(log, pool)),
            ChildSpec("wifly", lambda: Wifly(hw, pool, rover_id="h", role="hider",
                                             hold_until_welcome=hold), mailbox=256)])
        await system.start_supervisor(spec, "hider")
        await system.send("hider/wifly", Message.handle(
            Cmd.WIFLY_SEND_UNRELIABLE, pool.put(make_frame("status", {"state": "idle"}))))
        await system.send("hider/wifly", arrived(pool))
        await trio.sleep(4.0)
        before = list(written)
        server.deaf = False
        await trio.sleep(10.0)
        got = [f.cmd for f in server.got]
        nursery.cancel_scope.cancel()
    if hold:
        assert before == ["hello"] * 3  # at 0, 1 and 3 s
        assert got[0] == "hello" and {"status", "arrived"} <= set(got)
    else:
        assert {"status", "heartbeat"} <= set(before)


def test_bad_rover_id_is_refused_at_construction() -> None:
    with pytest.raises(ValueError, match="does not fit its schema"):
        Wifly(FakeHardware(), BufferPool(4), rover_id="bad id!", role="hider")


@pytest.mark.trio
async def test_a_noop_flood_costs_queue_slots_not_restarts(autojump_clock) -> None:
    """A flood fault fills the mailbox with NOOPs: ignored, and the link keeps working."""
    async with linked_wifly() as (system, server, tree, pool, log):
        assert system.flood("hider/wifly", 1000, Message.int(Cmd.NOOP, 0)) == 256
        await system.send("hider/wifly", arrived(pool))
        await trio.sleep(2.0)
        assert [f.cmd for f in server.got].count("arrived") == 1
        assert [c.restarts for c in tree.which_children() if c.id == "wifly"] == [0]


@pytest.mark.trio
async def test_a_poison_message_gives_its_pool_buffer_back(autojump_clock) -> None:
    """A map WiFly cannot send crashes it mid-burst; the buffers of the dropped burst are freed."""
    async with linked_wifly() as (system, server, tree, pool, log):
        in_use = pool.statistics().in_use
        system.send_nowait("hider/wifly", Message.handle(Cmd.WIFLY_SEND_MAP,
                                                         pool.put("not a map")))
        system.send_nowait("hider/wifly", arrived(pool))
        await trio.sleep(1.0)
        assert [c.restarts for c in tree.which_children() if c.id == "wifly"] == [1]
        assert pool.statistics().in_use == in_use


def count_ticks(system) -> list[float]:
    """Wrap the live WiFly's burst handler: the times of the WIFLY_TIMER ticks it handles."""
    actor = system.whereis("hider/wifly").actor
    ticks: list[float] = []
    handle_burst = actor.handle_burst

    async def counting(messages):
        ticks.extend(trio.current_time() for m in messages if m.command == Cmd.WIFLY_TIMER)
        await handle_burst(messages)

    actor.handle_burst = counting
    return ticks


@pytest.mark.trio
async def test_an_idle_linked_wifly_wakes_only_for_its_heartbeats(autojump_clock) -> None:
    """Welcomed, with nothing to send: the timer fires about once per heartbeat (not
    every tick_s), and a heartbeat still leaves within a tick of falling due, so the
    link stays up on both ends."""
    async with linked_wifly() as (system, server, _tree, _pool, log):
        ticks = count_ticks(system)
        sent: list[float] = []
        to_server = server.hw.wifly_write

        def wire(data: bytes) -> None:
            sent.append(trio.current_time())
            to_server(data)

        server.hw.wifly_write = wire
        await trio.sleep(10.0)
        assert len(ticks) <= 12  # at most a heartbeat a second; ticking every 0.1 s made 100
        assert len(sent) >= 9
        assert max(b - a for a, b in zip(sent, sent[1:], strict=False)) <= 1.1 + 1e-6
        assert [p for c, p in log if c == Cmd.NAV_LINK] == [1]
        assert server.session.is_up(trio.current_time())


@pytest.mark.trio
async def test_a_deaf_server_takes_the_link_down_on_time(autojump_clock) -> None:
    """With nothing heard, the link goes down at the first tick ``down_after_s`` (5 s)
    after the server was last heard, and hellos follow with their backoff."""
    async with linked_wifly() as (system, server, _tree, _pool, log):
        actor = system.whereis("hider/wifly").actor
        server.deaf = True
        while actor.welcomed:
            await trio.sleep(0.01)
        heard = actor.session.last_heard
        assert 5.0 <= trio.current_time() - heard <= 5.1 + 0.01
        hellos = actor.hellos  # the first hello leaves as the link goes down
        await trio.sleep(3.5)  # the next two about 1 and 3 s later (backoff from hello_s)
        assert actor.hellos - hellos == 2


@pytest.mark.trio
async def test_a_tick_dropped_by_a_full_mailbox_does_not_stop_the_timer(
        autojump_clock) -> None:
    """The one-shot tick may find the mailbox full (a flood): the next burst arms the
    timer again, so heartbeats go on after the flood."""
    async with linked_wifly() as (system, server, _tree, _pool, log):
        ticks = count_ticks(system)
        system.flood("hider/wifly", 1000, Message.int(Cmd.NOOP, 0))
        await trio.sleep(0.5)
        ticks.clear()
        await trio.sleep(5.0)
        assert len(ticks) >= 4
        assert [p for c, p in log if c == Cmd.NAV_LINK] == [1]


@pytest.mark.trio
@pytest.mark.parametrize("hold", [False, True], ids=["sim-link", "real-link"])
async def test_a_welcome_sharing_a_chunk_with_later_frames_and_a_late_second_welcome_rewind_nothing(
        autojump_clock, hold: bool) -> None:
    """A slow line brings the welcome and the reliable frames after it in one chunk, and
    later a second welcome of the same server session (the answer to a hello repeated
    meanwhile) naming a seq already delivered: every frame reaches navigation once, in
    order, and none waits for a resend."""
    hw, pool, log = FakeHardware(), BufferPool(64), []
    async with trio.open_nursery() as nursery, open_actor_system(1) as system:
        server = FakeServer(hw)
        first = server.from_rover

        def from_rover(data: bytes) -> None:
            hellos = sum(f.cmd == "hello" for f in server.got)
            first(data)
            if hellos == 0 and any(f.cmd == "hello" for f in server.got):
                server.session.send(make_frame("start"))  # in the welcome's chunk
                server.session.send(make_frame("stop"))

        hw.wifly_write = from_rover
        nursery.start_soon(server.run)
        spec = SupervisorSpec([
            ChildSpec("nav", lambda: Recorder(log, pool)),
            ChildSpec("wifly", lambda: Wifly(hw, pool, rover_id="h", role="hider",
                                             hold_until_welcome=hold), mailbox=256)])
        await system.start_supervisor(spec, "hider")
        await trio.sleep(1.0)
        server.session.send(make_frame("welcome", {**server.welcome(), "seq_base": 1}))
        server.session.send(make_frame("destination", {"x": 1.0, "y": 2.0}))
        await trio.sleep(3.0)
        frames = [p.cmd for c, p in log if c == Cmd.NAV_NET]
        resent = server.session.stats(trio.current_time()).resent
        nursery.cancel_scope.cancel()
    assert frames == ["start", "stop", "destination"]
    assert resent == 0
