"""Bounds on outside peers: connection cap, hello and idle timeouts, bad-frame budget,
bad frames summarised in storage, sessions reclaimed, descriptors running out, big maps."""

from __future__ import annotations

import errno
import os

import numpy as np
import trio
import trio.testing

from server.protocol import Frame, GridMap, decode_line, encode_frame, make_frame, map_chunks
from server.server import MAX_MAP_CHUNKS, ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover
from tests.raw_client import Outside, hello, open_raw_tcp, read_until_closed


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


async def _tcp_rover(nursery, port: int, rover: FakeRover, source: str = "127.0.0.2"):
    stream = await open_raw_tcp(port, source)
    nursery.start_soon(rover.run, lambda: stream.receive_some(4096), stream.send_all)
    return stream


def test_connection_cap_holds_and_a_legit_rover_is_still_served() -> None:
    """200 idle connections against a cap of 8: the server holds at most 8, the
    connected rover stays up, and a rover connecting during the flood is welcomed."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1", "s1"}), max_connections=8)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            async with trio.open_nursery() as nursery:
                h1 = FakeRover("h1", "hider")
                await _tcp_rover(nursery, port, h1)
                await trio.sleep(1)
                idle = []
                for _ in range(200):
                    idle.append(await open_raw_tcp(port))
                    await trio.sleep(0.001)
                    assert s.snapshot().connections <= 8
                s1 = FakeRover("s1", "seeker")
                await _tcp_rover(nursery, port, s1)
                await trio.sleep(2)
                assert h1.welcomed and s1.welcomed
                views = {v.id: v for v in s.snapshot().rovers}
                assert views["h1"].stats.up and views["s1"].stats.up
                assert s.snapshot().connections <= 8
                for st in idle:
                    await st.aclose()
                nursery.cancel_scope.cancel()

    run(main)


def test_one_address_holds_few_connections_without_hello() -> None:
    """Idle connections from one address beyond max_pending_per_address wait, at most
    max_waiting of them (the oldest closed first), and are closed at the hello timeout;
    a rover from another address is served meanwhile."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), max_pending_per_address=5,
                              max_waiting=10)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            idle = [await open_raw_tcp(port) for _ in range(40)]
            await trio.sleep(0.5)
            assert (s.snapshot().connections, s.waiting) == (5, 10)
            assert s.snapshot().refused["conn_closed"] == 25
            async with trio.open_nursery() as nursery:
                h1 = FakeRover("h1", "hider")
                await _tcp_rover(nursery, port, h1)
                await trio.sleep(2)
                assert h1.welcomed
                nursery.cancel_scope.cancel()
            await trio.sleep(config.hello_timeout_s)
            assert (s.snapshot().connections, s.waiting) == (0, 0)
            assert s.snapshot().refused["conn_closed"] == 40
            for st in idle:
                await st.aclose()

    run(main)


async def _welcome_after(port: int, line: bytes, source: str) -> tuple[float, bool]:
    """Connect from ``source``, send ``line``: (seconds to the welcome, closed by the
    server before one came)."""
    stream = await open_raw_tcp(port, source)
    t0 = trio.current_time()
    await stream.send_all(line)
    got = b""
    with trio.move_on_after(10):
        while b'"welcome"' not in got:
            data = await stream.receive_some(65536)
            if not data:
                await stream.aclose()
                return trio.current_time() - t0, True
            got += data
    await stream.aclose()
    return trio.current_time() - t0, b'"welcome"' not in got


def test_a_rover_with_its_token_gets_in_past_a_flood_from_its_own_address() -> None:
    """500 idle connections from 127.0.0.1 fill its budget of connections without hello
    and the waiting room; a rover from 127.0.0.1 with the right token is welcomed within
    1 s (it waits in the place of the oldest waiting one; its hello closes the address's
    oldest idle connection), the caps still hold, and a wrong token gets no such room."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "secret"})
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            idle = [await open_raw_tcp(port, "127.0.0.1") for _ in range(500)]
            await trio.sleep(2.0)
            assert (s.snapshot().connections, s.waiting) == (16, 64)
            took, closed = await _welcome_after(port, hello("h1", "hider", "wrong"),
                                                "127.0.0.1")
            assert closed and s.snapshot().refused["auth_failed"] == 1
            took, closed = await _welcome_after(port, hello("h1", "hider", "secret"),
                                                "127.0.0.1")
            assert not closed and took < 1.0
            assert s.snapshot().connections <= 16 and s.waiting <= 64
            for st in idle:
                await st.aclose()

    run(main)


def test_a_rovers_waiting_connection_outlasts_a_flood_from_other_addresses() -> None:
    """At the caps, a newer connection closes a waiting one of the address holding the
    most connections without hello: a rover slow to say hello is not pushed out by a
    flood from other addresses, and is welcomed when its hello comes."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "secret"},
                              max_connections=4, max_waiting=4)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            flood = [await open_raw_tcp(port, "127.1.0.1") for _ in range(8)]
            rover = await open_raw_tcp(port, "127.0.0.2")
            await trio.sleep(0.1)
            for k in range(50):
                flood.append(await open_raw_tcp(port, f"127.1.0.{k % 3 + 1}"))
            await trio.sleep(0.1)
            assert (s.snapshot().connections, s.waiting) == (4, 4)
            await rover.send_all(hello("h1", "hider", "secret"))
            got, closed = await read_until_closed(rover, 0.5)
            assert not closed and decode_line(got.split(b"\n")[0]).cmd == "welcome"
            for st in [rover, *flood]:
                await st.aclose()

    run(main)


def test_two_rovers_from_one_address_both_get_in_beyond_the_caps() -> None:
    """Two rovers behind one address, waiting beyond the caps, say hello at the same
    moment: each hello makes room among the flood's connections, not in place of the
    other rover's (a proven hello binds its rover at once)."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1", "s1"}),
                              tokens={"h1": "secret-h", "s1": "secret-s"},
                              max_connections=4, max_waiting=4)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            flood = [await open_raw_tcp(port, "127.1.0.1") for _ in range(8)]
            h1, s1 = [await open_raw_tcp(port, "127.0.0.2") for _ in range(2)]
            await trio.sleep(0.1)
            assert (s.snapshot().connections, s.waiting) == (4, 4)
            # both lines sent before the server runs again: at the same moment for it
            os.write(h1.socket.fileno(), hello("h1", "hider", "secret-h"))
            os.write(s1.socket.fileno(), hello("s1", "seeker", "secret-s"))
            for stream in (h1, s1):
                got, closed = await read_until_closed(stream, 0.5)
                assert not closed and decode_line(got.split(b"\n")[0]).cmd == "welcome"
            assert {v.id for v in s.snapshot().rovers} == {"h1", "s1"}
            for st in [h1, s1, *flood]:
                await st.aclose()

    run(main)


def test_a_hello_with_its_token_makes_room_at_the_connection_cap() -> None:
    """Idle connections from many addresses, reopened whenever the server closes them,
    keep the server at its cap; a rover with its token is welcomed at once, closing the
    oldest connection without hello; connections stay within the cap and the waiting
    room."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), tokens={"h1": "secret"},
                              max_connections=8, max_waiting=4)
        async with open_server(Store(":memory:"), config) as s, \
                trio.open_nursery() as nursery:
            port = await s.listen_tcp("127.0.0.1", 0)

            async def holder(source: str) -> None:
                while True:
                    stream = await open_raw_tcp(port, source)
                    await read_until_closed(stream, 60)
                    await stream.aclose()
                    await trio.sleep(0.05)

            for k in range(100):
                nursery.start_soon(holder, f"127.1.0.{k % 20 + 1}")
            await trio.sleep(1.0)
            assert (s.snapshot().connections, s.waiting) == (8, 4)
            for _ in range(3):
                took, closed = await _welcome_after(port, hello("h1", "hider", "secret"),
                                                    "127.0.0.2")
                assert not closed and took < 1.0
                assert s.snapshot().connections <= 8 and s.waiting <= 4
            nursery.cancel_scope.cancel()

    run(main)


def test_a_connection_without_hello_is_closed_after_the_hello_timeout() -> None:
    """Slowloris: a byte a second but never a hello; closed at hello_timeout_s while
    a rover on another connection is served throughout."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), hello_timeout_s=3.0)
        async with open_server(Store(":memory:"), config) as s, \
                trio.open_nursery() as nursery:
            port = await s.listen_tcp("127.0.0.1", 0)
            h1 = FakeRover("h1", "hider")
            await _tcp_rover(nursery, port, h1)
            stream = await open_raw_tcp(port)
            t0 = trio.current_time()
            closed = False
            for ch in b'{"cmd":"hel':
                await stream.send_all(bytes([ch]))
                _, closed = await read_until_closed(stream, 1.0)
                if closed:
                    break
            assert closed and 2.9 <= trio.current_time() - t0 <= 4.1
            assert s.snapshot().connections == 1  # the rover's
            await trio.sleep(5)
            assert h1.welcomed and s.snapshot().rovers[0].stats.up
            nursery.cancel_scope.cancel()

    run(main)


def test_a_silent_rover_link_is_closed_after_the_link_down_time() -> None:
    """An authenticated TCP link that stops talking is closed after down_after_s."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}))
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            stream = await open_raw_tcp(port)
            await stream.send_all(hello("h1", "hider"))
            t0 = trio.current_time()
            got, closed = await read_until_closed(stream, 20)
            assert b'"welcome"' in got and closed
            assert 4.9 <= trio.current_time() - t0 <= 6.1
            (view,) = s.snapshot().rovers
            assert view.link == ""  # the session stays, without a link

    run(main)


def test_bad_frame_budget_closes_a_garbage_spewing_link() -> None:
    """Garbage past the budget closes the link; each bad line before was answered."""
    async def main() -> None:
        config = ServerConfig(bad_frame_budget=20, bad_frame_rate=1.0)
        async with open_server(Store(":memory:"), config) as s:
            port = await s.listen_tcp("127.0.0.1", 0)
            stream = await open_raw_tcp(port)
            await stream.send_all(b"garbage\n" * 100)
            got, closed = await read_until_closed(stream, 3)
            assert closed
            errors = [decode_line(x) for x in got.splitlines()]
            assert 20 <= len(errors) <= 22 and all(f.cmd == "error" for f in errors)

    run(main)


def test_bad_frames_do_not_grow_storage() -> None:
    """20,000 bad frames on outside links and a rover's own: a handful of stored rows."""
    store = Store(":memory:")

    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"h1"}), summary_s=10.0)
        async with open_server(store, config) as s:
            rover = Outside(s)
            rover.send(hello("h1", "hider"))
            others = [Outside(s, name=f"fuzz{k}") for k in range(10)]
            rng = np.random.default_rng(3)
            good = encode_frame(make_frame("pose", {"x": 1, "y": 2, "heading": 3}))
            for i in range(20000):
                b = bytearray(good)
                b[int(rng.integers(0, len(b) - 1))] = int(rng.integers(0, 256))
                (rover if i % 11 == 0 else others[i % 10]).send(bytes(b))
                if i % 500 == 0:
                    await trio.sleep(1.0)
            await trio.sleep(1)
            counted["bad"] = s.snapshot().refused["bad_frame"]
            assert counted["bad"] > 15000
            assert s.snapshot().rovers[0].stats.bad_frames > 1000

    counted: dict[str, int] = {}
    run(main)
    rows = store.events()
    firsts = [k for _, k, _, _ in rows if k == "bad_frame"]
    summaries = [d for _, k, _, d in rows if k == "bad_frame_summary"]
    # 40 s of fuzzing: one event per burst and one summary per 10 s, not 20,000 rows
    assert len(firsts) == 1 and 1 <= len(summaries) <= 6
    assert len(firsts) + sum(d["count"] for d in summaries) == counted["bad"]
    assert store.size_bytes() < 200_000


def test_sessions_of_gone_rovers_are_reclaimed() -> None:
    """Open enrolment: 100 ids come and go; their sessions are reclaimed, never over the cap."""
    async def main() -> None:
        config = ServerConfig(open_enrolment=True, max_sessions=16, reclaim_after_s=30.0)
        async with open_server(Store(":memory:"), config) as s:
            for k in range(100):
                x = Outside(s, name=f"c{k}")
                x.send(hello(f"r{k}", "hider" if k % 2 else "seeker"))
                await trio.sleep(0.05)
                x.link.close()
                await trio.sleep(0.05)
                assert len(s.snapshot().rovers) <= 16
            await trio.sleep(31)
            # only the rovers that play a role (the last hider and seeker) are kept
            assert sorted(v.id for v in s.snapshot().rovers) == ["r98", "r99"]

    run(main)


class _StarvedListener:
    """A listener whose accept runs out of descriptors ``times`` times, then waits."""

    def __init__(self, times: int) -> None:
        self.times = times
        self.calls = 0

    async def accept(self):
        self.calls += 1
        await trio.lowlevel.checkpoint()
        if self.calls <= self.times:
            raise OSError(errno.EMFILE, "Too many open files")
        await trio.sleep_forever()

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        return False


def test_running_out_of_descriptors_slows_accepting_with_one_line() -> None:
    """EMFILE on accept: one event, retried with backoff, no traceback per retry."""
    async def main() -> None:
        async with open_server(Store(":memory:")) as s:
            events = s.subscribe()
            listener = _StarvedListener(times=30)
            s._nursery.start_soon(s._accept_loop, listener)
            await trio.sleep(30)
            assert listener.calls == 31  # it slowed down: 30 failures took seconds
            got = []
            while True:
                try:
                    got.append(events.receive_nowait())
                except trio.WouldBlock:
                    break
            errors = [e.data["error"] for e in got if e.kind == "accept_error"]
            assert len(errors) == 1
            assert errors[0].startswith("cannot accept: Too many open files; accepting slowed")

    run(main)


def test_a_map_too_big_to_download_is_refused_at_its_first_chunk() -> None:
    """An upload of more chunks than a download may have gets bad_data at once."""
    async def main() -> None:
        config = ServerConfig(rovers=frozenset({"m1"}))
        async with open_server(Store(":memory:"), config) as s:
            m = Outside(s)
            m.send(hello("m1", "mapper"))
            await trio.sleep(0.2)
            m.frames()
            rng = np.random.default_rng(1)
            cells = rng.choice(np.array([-1, 0, 100], np.int8), size=(600, 600))
            chunks = map_chunks(GridMap(cells, 5.0, (0.0, 0.0)), 1)
            assert len(chunks) > MAX_MAP_CHUNKS
            first = chunks[0]
            m.send(encode_frame(Frame(first.cmd, first.type, first.data, seq=1)))
            await trio.sleep(0.2)
            (err,) = [f for f in m.frames() if f.cmd == "error"]
            assert err.data["fault"] == "bad_data" and err.data["seq"] == 1
            assert err.data["detail"] == (f"map: {len(chunks)} chunks, a map may have at most "
                                          f"{MAX_MAP_CHUNKS} (send it coarser or smaller)")

    run(main)
