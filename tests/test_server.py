"""The server end to end with fake rovers on in-memory links, in virtual time."""

from __future__ import annotations

import trio
import trio.testing

from server.protocol import Pose, ReliableSession, decode_line, make_frame
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover, memory_pipe

ORIGINS = {"m1": Pose(100.0, 100.0, 90.0), "h1": Pose(150.0, 100.0, 90.0),
           "s1": Pose(100.0, 50.0, 0.0)}


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


async def _wait_phase(server, phase: str, timeout: float = 120.0) -> None:
    with trio.fail_after(timeout):
        while server.snapshot().phase != phase:
            await trio.sleep(0.1)


def test_whole_game_in_memory() -> None:
    """Map, a refused hide, hide, a wrong guess, a right guess: found; all stored."""
    store = Store(":memory:")

    async def main() -> None:
        async with open_server(store, ServerConfig(origins=ORIGINS)) as server:
            events = server.subscribe()
            rovers = {"m1": FakeRover("m1", "mapper"), "h1": FakeRover("h1", "hider"),
                      "s1": FakeRover("s1", "seeker", hider_at=Pose(60.0, 10.0))}
            async with trio.open_nursery() as nursery:
                for r in rovers.values():
                    receive, send, _ = memory_pipe(server.attach_memory)
                    nursery.start_soon(r.run, receive, send)
                await trio.sleep(2)
                assert (await server.command("hide", x=0, y=0)).reason == \
                    "hide needs phase map_ready, the game is idle"
                assert (await server.command("start_mapping")).ok
                await _wait_phase(server, "map_ready")
                refused = await server.command("hide", x=50.0, y=50.0)  # on the box
                assert refused.ok
                await _wait_phase(server, "map_ready", 30)
                await trio.sleep(5)
                snap = server.snapshot()
                assert snap.phase == "map_ready" and snap.reason == "spot is occupied"
                assert (await server.command("hide", x=60.0, y=10.0, heading=45)).ok
                await _wait_phase(server, "hidden")
                assert (await server.command("seek", x=-20.0, y=60.0)).ok
                await _wait_phase(server, "not_found")
                assert (await server.command("seek", x=55.0, y=5.0)).ok
                await _wait_phase(server, "found")
                snap = server.snapshot()
                assert [(g.x, g.y) for g in snap.guesses] == [(-20.0, 60.0), (55.0, 5.0)]
                assert all(v.stats.up for v in snap.rovers)
                # origins: map frame is the mapper's start frame (100, 100) @ 90 deg
                h = rovers["h1"].origin
                assert (round(h.x, 6), round(h.y, 6), h.heading_deg) == (0.0, -50.0, 0.0)
                s = rovers["s1"].origin
                assert (round(s.x), round(s.y), s.heading_deg) == (-50, 0, -90.0)
                assert rovers["h1"].map.same_as(rovers["m1"].room)
                nursery.cancel_scope.cancel()
            kinds = []
            while True:
                try:
                    kinds.append(events.receive_nowait().kind)
                except trio.WouldBlock:
                    break
            assert {"hello", "link_up", "map", "report", "phase", "command"} <= set(kinds)
        game = store.games()[0]
        assert (game.status, game.phase, game.outcome) == ("finished", "found",
                                                           "found after 2 guesses")
        assert len(store.maps()) == 1
        reports = [d["report"] for t, k, r, d in store.events(game.id) if k == "report"]
        assert reports == ["invalid_spot", "arrived", "not_found", "found"]

    run(main)


def test_commands_refused_without_rover_and_with_bad_arguments() -> None:
    """A command for a role nobody plays, or with wrong arguments, is refused with a reason."""
    async def main() -> None:
        async with open_server(Store(":memory:")) as server:
            r = await server.command("start_mapping")
            assert (r.ok, r.reason) == (False, "no mapper has said hello yet")
            r = await server.command("dance")
            assert not r.ok and r.reason.startswith("unknown command 'dance'")
            r = await server.command("new_game", speed=3)
            assert not r.ok and "bad arguments for new_game" in r.reason

    run(main)


async def _raw_client(server, *, trusted: bool = True):
    """A raw session on a memory link: returns (session, link, inbox)."""
    inbox: list[bytes] = []
    link = server.attach_memory(inbox.append, trusted=trusted)
    return ReliableSession(), link, inbox


def _lines(inbox: list[bytes]) -> list:
    out = [decode_line(x) for chunk in inbox for x in chunk.splitlines()]
    inbox.clear()
    return out


def test_bad_frames_are_answered_and_link_stays_up() -> None:
    """Garbage, frames before hello, wrong tokens and server-only cmds each get an error."""
    async def main() -> None:
        config = ServerConfig(tokens={"*": "sesame"}, rovers=frozenset({"m1"}))
        async with open_server(Store(":memory:"), config) as server:
            _, link, inbox = await _raw_client(server, trusted=False)
            link.feed(b"not json\n")
            link.feed(b'{"cmd":"pose","type":"pose","data":{"x":1,"y":2}}\n')
            link.feed(b'{"cmd":"hello","type":"rover","data":{"id":"m1","role":"mapper"}}\n')
            await trio.sleep(0.5)
            faults = [(f.cmd, f.data["fault"], f.data["detail"]) for f in _lines(inbox)
                      if f.cmd == "error"]
            assert faults == [
                ("error", "not_json", "JSON is malformed: invalid character (byte 4)"),
                ("error", "not_allowed", "send hello first"),
                ("error", "auth", "bad or missing token for 'm1'"),
            ]
            link.feed(b'{"cmd":"hello","type":"rover","data":{"id":"m1","role":"mapper",'
                      b'"token":"sesame"}}\n')
            link.feed(b'{"cmd":"start","type":"none","data":null,"seq":1}\n')
            link.feed(b'{"cmd":"pose","type":"pose","data":{"x":"far","y":2}}\n')
            await trio.sleep(0.5)
            got = _lines(inbox)
            assert got[0].cmd == "welcome"
            assert [(f.data["fault"], f.data.get("cmd")) for f in got if f.cmd == "error"] == [
                ("not_allowed", "start"), ("bad_data", "pose")]
            assert any(f.ack == 1 for f in got)  # the bad reliable frame is still acked
            rover = server.snapshot().rovers[0]
            assert rover.stats.up and rover.stats.bad_frames == 2

    run(main)


def test_link_goes_down_after_silence_and_comes_back() -> None:
    """A rover silent for 5 s is reported down; when it speaks again it is up."""
    async def main() -> None:
        async with open_server(Store(":memory:")) as server:
            events = server.subscribe()
            rover = FakeRover("h1", "hider")
            receive, send, _ = memory_pipe(server.attach_memory)
            async with trio.open_nursery() as nursery:
                nursery.start_soon(rover.run, receive, send)
                await trio.sleep(3)
                rover.silent = True
                t0 = trio.current_time()
                await trio.sleep(10)
                rover.silent = False
                await trio.sleep(3)
                nursery.cancel_scope.cancel()
            seen = []
            while True:
                try:
                    e = events.receive_nowait()
                except trio.WouldBlock:
                    break
                if e.kind in ("link_up", "link_down"):
                    seen.append((e.kind, round(e.t - t0)))
            assert [k for k, _ in seen] == ["link_up", "link_down", "link_up"]
            assert 4 <= seen[1][1] <= 6

    run(main)


def test_rover_reconnect_resumes_reliable_delivery() -> None:
    """A destination queued while the hider's stream was gone reaches it after a new hello."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(origins=ORIGINS)) as server:
            _, link, inbox = await _raw_client(server)
            hello = make_frame("hello", {"id": "h1", "role": "hider"})
            from server.protocol import encode_frame
            link.feed(encode_frame(hello))
            await trio.sleep(0.2)
            link.close()
            await trio.sleep(0.2)
            server.game.phase = server.game.phase.MAP_READY  # skip mapping for this test
            from tests.fake_rover import room_map
            server.game.map = room_map()
            assert (await server.command("hide", x=60, y=10)).ok
            _, link2, inbox2 = await _raw_client(server)
            link2.feed(encode_frame(hello))
            await trio.sleep(2)
            cmds = [f.cmd for f in _lines(inbox2)]
            assert cmds[0] == "welcome"
            assert [c for c in cmds if c in ("origin", "start", "destination")][:3] == [
                "origin", "start", "destination"]

    run(main)
