"""The fake system, in virtual time: phases advance on commands, faults act and end."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from tui.fake import FakeSystem
from tui.snapshot import CommandResult, Snapshot


class Harness:
    """Runs a FakeSystem in a nursery and records what it publishes."""

    def __init__(self, fake: FakeSystem) -> None:
        self.fake = fake
        self.results: list[CommandResult] = []
        self.snapshots: list[Snapshot] = []
        self.requests, self._receive = trio.open_memory_channel[None](1)

    def publish(self, item) -> None:
        (self.snapshots if isinstance(item, Snapshot) else self.results).append(item)

    async def snap(self) -> Snapshot:
        n = len(self.snapshots)
        await self.requests.send(None)
        while len(self.snapshots) == n:
            await trio.sleep(0.001)
        return self.snapshots[-1]


def run_fake(test, **kwargs):
    """Run ``await test(harness)`` with a fake at "as fast as possible" (virtual time)."""
    fake = FakeSystem(speed=None, **kwargs)
    h = Harness(fake)

    async def main():
        async with trio.open_nursery() as nursery:
            nursery.start_soon(fake.run, h.publish, h._receive)
            await test(h)
            nursery.cancel_scope.cancel()

    trio.run(main, clock=fake.clock)
    return h


def test_mapping_grows_the_map_and_completes():
    """Start mapping: known cells grow while mapping, and the phase reaches map ready."""
    seen = []

    async def test(h):
        h.fake.start_mapping()
        await trio.sleep(5)
        s1 = await h.snap()
        await trio.sleep(60)
        s2 = await h.snap()
        seen.extend([s1, s2])

    h = run_fake(test)
    s1, s2 = seen
    assert s1.phase == "mapping"
    known1 = int((s1.map.cells != -1).sum())
    known2 = int((s2.map.cells != -1).sum())
    assert 0 < known1 < known2
    assert s2.phase == "map_ready"
    assert len(s1.lidar_points) > 0
    assert h.results[0] == CommandResult("start_mapping", "ok", "")


def test_commands_in_the_wrong_phase_are_refused_with_reason():
    """hide_at before the map is ready is refused, naming the phase."""

    async def test(h):
        h.fake.hide_at(0.0, 0.0, 0.0)
        await trio.sleep(1)

    h = run_fake(test)
    assert h.results == [CommandResult("hide_at", "refused",
                                       "hide is valid in map_ready, not in idle")]


def test_a_whole_game_hide_then_seek_finds_the_hider():
    """map -> hide at a free spot -> seek at the same spot -> found."""
    phases = []

    async def test(h):
        h.fake.start_mapping()
        await trio.sleep(60)
        h.fake.hide_at(150.0, 130.0, 90.0)
        await trio.sleep(30)
        phases.append((await h.snap()).phase)
        h.fake.seek_at(0.0, 0.0)  # wrong place first
        await trio.sleep(30)
        phases.append((await h.snap()).phase)
        h.fake.seek_at(150.0, 130.0)
        await trio.sleep(30)
        s = await h.snap()
        phases.append(s.phase)
        phases.append(s.guesses)

    h = run_fake(test)
    assert phases == ["hidden", "not_found", "found", 2]
    assert all(r.status == "ok" for r in h.results)


def test_hide_spot_in_an_obstacle_is_refused():
    """A spot that is occupied is refused and the phase stays map ready."""

    async def test(h):
        h.fake.start_mapping()
        await trio.sleep(60)
        h.fake.hide_at(-55.0, 0.0, 0.0)  # inside the left wall
        await trio.sleep(1)

    h = run_fake(test)
    assert h.results[-1].status == "refused"
    assert "not known free space" in h.results[-1].reason


def test_injected_crash_restarts_the_actor_and_is_on_the_timeline():
    """A crash turns the node to restarting, then running with one more restart."""
    states = []

    async def test(h):
        h.fake.inject_fault("mapper/lidar", "crash", None, {})
        await trio.sleep(0.15)
        s = await h.snap()
        node = dict((n.name, n) for _, n in s.tree.walk())["mapper/lidar"]
        states.append((node.state, node.restarts, node.last_exit))
        await trio.sleep(2)
        s = await h.snap()
        node = dict((n.name, n) for _, n in s.tree.walk())["mapper/lidar"]
        states.append((node.state, node.restarts))
        states.append([e.kind for e in s.timeline])

    run_fake(test)
    assert states[0] == ("restarting", 0, "crashed: injected fault")
    assert states[1] == ("running", 1)
    assert states[2][-3:] == ["fault", "crash", "restart"]


def test_hang_is_detected_by_the_watchdog():
    """A hung actor is restarted with reason 'hung' after the watchdog deadline."""
    found = []

    async def test(h):
        h.fake.inject_fault("hider/motor", "hang", None, {})
        await trio.sleep(3)
        s = await h.snap()
        found.append(dict((n.name, n) for _, n in s.tree.walk())["hider/motor"])

    run_fake(test)
    assert found[0].last_exit == "hung" and found[0].restarts == 1


def test_flood_fills_the_queue_and_counts_drops_until_it_ends():
    """A 2 s flood fills the mailbox, drops grow, and the fault ends by itself."""
    out = []

    async def test(h):
        h.fake.inject_fault("mapper/lidar", "flood", 2.0, {})
        await trio.sleep(1)
        s = await h.snap()
        out.append(s)
        await trio.sleep(2)
        out.append(await h.snap())

    run_fake(test)
    q = {q.name: q for q in out[0].queues}["mapper/lidar"]
    assert q.depth == q.capacity and q.drops > 0
    assert [f.kind for f in out[0].faults] == ["flood"]
    assert out[1].faults == ()
    assert out[1].timeline[-1].kind == "clear"


def test_clear_fault_by_target_and_unknown_fault_is_refused():
    """clear_fault accepts a target name; an unknown one is refused."""

    async def test(h):
        h.fake.inject_fault("mapper.wifly", "drop", None, {})
        await trio.sleep(0.5)
        assert not (await h.snap()).links[0].up
        h.fake.clear_fault("mapper.wifly")
        h.fake.clear_fault("nothing")
        await trio.sleep(0.5)
        assert (await h.snap()).links[0].up

    h = run_fake(test)
    assert [r.status for r in h.results] == ["ok", "ok", "refused"]
    assert h.results[-1].reason == "no active fault 'nothing'"


@pytest.mark.parametrize("target,kind,reason", [
    ("mapper/lidar", "melt",
     "fault 'melt' is not valid for mapper/lidar; valid: crash, hang, flood"),
    ("toaster", "crash", "unknown fault target 'toaster'"),
])
def test_invalid_faults_are_refused(target, kind, reason):
    """Only catalogue faults are accepted, with a message naming the rule."""

    async def test(h):
        h.fake.inject_fault(target, kind, 1.0, {})
        await trio.sleep(0.5)

    h = run_fake(test)
    assert h.results == [CommandResult("inject_fault", "refused", reason)]


def test_speed_and_pause_change_the_clock():
    """set_speed(4) sets the clock's rate; pause stops it; snapshots report both."""
    fake = FakeSystem(speed=1.0)
    h = Harness(fake)
    out = []

    async def main():
        async with trio.open_nursery() as nursery:
            nursery.start_soon(fake.run, h.publish, h._receive)
            fake.set_speed(4)
            await trio.testing.wait_all_tasks_blocked()
            out.append((fake.clock.rate, fake.clock.autojump_threshold))
            fake.pause()
            await trio.testing.wait_all_tasks_blocked()
            out.append((fake.clock.rate, fake.clock.autojump_threshold, fake.snapshot().paused))
            fake.set_speed(None)
            fake.resume()
            await trio.testing.wait_all_tasks_blocked()
            out.append((fake.clock.rate, fake.clock.autojump_threshold, fake.snapshot().speed))
            nursery.cancel_scope.cancel()

    trio.run(main, clock=fake.clock)
    assert out == [(4.0, math.inf), (0.0, math.inf, True), (0.0, 0.0, None)]


def test_export_writes_pgm_and_yaml(tmp_path):
    """Export after mapping writes a map_server PGM whose size matches the grid."""

    async def test(h):
        h.fake.export_map(str(tmp_path))  # empty map: refused
        h.fake.start_mapping()
        await trio.sleep(10)
        h.fake.export_map(str(tmp_path))
        h.fake.export_map(str(tmp_path / "missing"))
        await trio.sleep(0.5)

    h = run_fake(test)
    assert [r.status for r in h.results] == ["refused", "ok", "ok", "refused"]
    data = (tmp_path / "map.pgm").read_bytes()
    assert data.startswith(b"P5\n80 60\n255\n")
    pixels = np.frombuffer(data[len(b"P5\n80 60\n255\n"):], np.uint8)
    assert set(np.unique(pixels)) <= {0, 205, 254} and (pixels == 254).any()
    assert "resolution: 0.05" in (tmp_path / "map.yaml").read_text()


def test_same_seed_same_run():
    """Two runs with one seed publish the same map and estimated poses."""
    outs = []
    for _ in range(2):
        got = []

        async def test(h, got=got):
            h.fake.start_mapping()
            await trio.sleep(12.3)
            got.append(await h.snap())

        run_fake(test, seed=7)
        outs.append(got[0])
    a, b = outs
    assert np.array_equal(a.map.cells, b.map.cells)
    assert a.rovers == b.rovers
