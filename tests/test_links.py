"""Links: link strings, memory bounds, TCP, serial (loop://, pty), missing ports."""

from __future__ import annotations

import os
import tty

import pytest
import trio
import trio.testing

from server.links import MemoryLink, is_loopback, parse_link
from server.links.spec import LISTEN, PLAY_ROVER, ROVER_LINK, SERVE_ROVER, parse_link_for
from server.protocol import Pose, decode_line, encode_frame, make_frame
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover, memory_pipe


def run(fn) -> None:
    trio.run(fn, clock=trio.testing.MockClock(autojump_threshold=0))


@pytest.mark.parametrize(
    ("text", "kind", "fields"),
    [
        ("tcp:127.0.0.1:7878", "tcp_out", {"host": "127.0.0.1", "port": 7878,
                                           "url": "socket://127.0.0.1:7878"}),
        ("tcp:[::1]:7000", "tcp_out", {"host": "::1", "port": 7000}),
        ("serial:/dev/ttyUSB0,115200", "serial", {"url": "/dev/ttyUSB0", "baud": 115200}),
        ("serial:socket://host:5760,57600", "serial", {"url": "socket://host:5760",
                                                       "baud": 57600}),
        ("serial:loop://,9600", "serial", {"url": "loop://", "baud": 9600}),
        ("tcp", "tcp", {}),
        ("sim", "sim", {}),
    ],
)
def test_parse_link_accepts_the_documented_forms(text: str, kind: str, fields: dict) -> None:
    """Every documented link string parses into its parts."""
    spec = parse_link(text)
    assert spec.kind == kind
    for k, v in fields.items():
        assert getattr(spec, k) == v


@pytest.mark.parametrize(
    ("text", "kind", "where"),
    [
        ("/dev/ttyUSB0,57600", "serial", ("/dev/ttyUSB0", 57600)),
        ("/dev/ttyUSB0", "serial", ("/dev/ttyUSB0", 115200)),
        ("serial:/dev/ttyUSB0", "serial", ("/dev/ttyUSB0", 115200)),
        ("COM3,9600", "serial", ("COM3", 9600)),
        ("tcpin:0.0.0.0:7000", "tcp_in", ("0.0.0.0", 7000)),
        ("tcp:10.0.0.2:23", "tcp_out", ("10.0.0.2", 23)),
        ("udp:127.0.0.1:14550", "udp_in", ("127.0.0.1", 14550)),
        ("udpin:0.0.0.0:14550", "udp_in", ("0.0.0.0", 14550)),
        ("udpout:10.0.0.2:14550", "udp_out", ("10.0.0.2", 14550)),
        ("udp:[::1]:14550", "udp_in", ("::1", 14550)),
        ("/dev/serial/by-id/usb-FTDI_FT232R_A1-if00-port0,57600", "serial",
         ("/dev/serial/by-id/usb-FTDI_FT232R_A1-if00-port0", 57600)),
        ("udp", "udp", ("", 0)),
    ],
)
def test_link_strings_as_mavproxy_users_type_them(text: str, kind: str, where: tuple) -> None:
    spec = parse_link(text)
    assert spec.kind == kind
    got = (spec.url, spec.baud) if kind == "serial" else (spec.host, spec.port)
    assert got == where


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("ttyUSB0", "link must be tcp:HOST:PORT, tcpin:HOST:PORT, udp:HOST:PORT, "
                    "udpin:HOST:PORT, udpout:HOST:PORT, serial:PORT[,BAUD], a device "
                    "path[,BAUD], tcp, udp, sim or pty, got 'ttyUSB0'"),
        ("udpout:host", "udpout link must be udpout:HOST:PORT, got 'udpout:host'"),
        ("udp:7878", "udp link must be udp:HOST:PORT, got 'udp:7878'"),
        ("udpin:[]:7878", "udpin link must be udpin:HOST:PORT, got 'udpin:[]:7878'"),
        ("serial:", "serial link must be serial:PORT[,BAUD], got 'serial:'"),
        ("tcpin:5", "tcpin link must be tcpin:HOST:PORT, got 'tcpin:5'"),
        ("serial:/dev/ttyUSB0,fast", "serial baud must be a number, got 'fast' in "
                                     "'serial:/dev/ttyUSB0,fast'"),
        ("serial:/dev/ttyUSB0,10", "serial baud must be 50..4000000, got 10"),
        ("tcp:host:99999", "tcp port must be 0..65535, got 99999"),
        ("tcp:7878", "tcp link must be tcp:HOST:PORT, got 'tcp:7878'"),
    ],
)
def test_parse_link_errors_are_clear(text: str, message: str) -> None:
    """Bad link strings are refused with a message naming the rule and the value."""
    with pytest.raises(ValueError) as info:
        parse_link(text)
    assert str(info.value) == message


@pytest.mark.parametrize("use", [ROVER_LINK, LISTEN, SERVE_ROVER, PLAY_ROVER],
                         ids=lambda u: u.option)
def test_every_refusal_of_a_command_lists_the_forms_that_command_takes(use) -> None:
    """A form the option does not take, a malformed one and garbage: each refusal names
    the option and lists the same forms (MAVProxy's, as that command takes them)."""
    every = ["tcp:127.0.0.1:7878", "tcpin:127.0.0.1:7878", "udp:127.0.0.1:7878",
             "udpin:127.0.0.1:7878", "udpout:127.0.0.1:7878", "/dev/ttyUSB0,57600",
             "serial:/dev/ttyUSB0", "tcp", "udp", "sim", "pty"]
    taken = [t for t in every if parse_link(t).kind in use.kinds]
    refused = [t for t in every if t not in taken] + ["udp:7878", "serial:", "pigeon:1"]
    assert taken and len(refused) > 3
    for text in taken:
        assert parse_link_for(text, use).text == text
    for text in refused:
        with pytest.raises(ValueError) as info:
            parse_link_for(text, use)
        assert str(info.value).startswith(f"{use.option} must be {use.forms}, got {text!r}")


def test_link_strings_mean_what_they_mean_in_mavproxy() -> None:
    """tcp: connects, tcpin: listens, udp: and udpin: receive, udpout: sends; a rover
    sends with udpout: and is refused udp:/udpin: with the reason."""
    assert parse_link_for("tcp:10.0.0.2:7878", ROVER_LINK).kind == "tcp_out"
    assert parse_link_for("tcpin:0.0.0.0:7878", ROVER_LINK).kind == "tcp_in"
    assert parse_link_for("udpout:10.0.0.2:7878", ROVER_LINK).kind == "udp_out"
    assert {parse_link_for(t, LISTEN).kind for t in ("udp:127.0.0.1:1", "udpin:127.0.0.1:1")
            } == {"udp_in"}
    with pytest.raises(ValueError, match=r"udp: and udpin: receive \(listen\), as in MAVProxy"):
        parse_link_for("udp:10.0.0.2:7878", ROVER_LINK)
    with pytest.raises(ValueError, match=r"^--listen must be tcpin:HOST:PORT .*udpout:"):
        parse_link_for("udpout:10.0.0.2:7878", LISTEN)  # --listen receives


def test_loopback_detection() -> None:
    """Only loopback names count as loopback."""
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


def test_memory_link_is_bounded_and_counts_drops() -> None:
    """feed never blocks; bytes beyond capacity are dropped and counted."""
    async def main() -> None:
        link = MemoryLink(lambda b: None, capacity=10)
        link.feed(b"0123456789abc")
        assert link.dropped_bytes == 3
        assert await link.receive_some() == b"0123456789"
        link.close()
        assert await link.receive_some() == b""

    run(main)


def test_non_loopback_listen_without_tokens_is_refused() -> None:
    """Binding a public address without rover tokens raises a clear error."""
    async def main() -> None:
        async with open_server(Store(":memory:")) as server:
            with pytest.raises(ValueError, match="refusing to listen on 0.0.0.0: not loopback"):
                await server.listen_tcp("0.0.0.0", 0)

    run(main)


def test_tcp_rover_says_hello_and_gets_welcome() -> None:
    """A rover connecting over TCP loopback is welcomed and kept up by heartbeats."""
    async def main() -> None:
        async with open_server(Store(":memory:"), ServerConfig(rovers=frozenset({"m1"}))) as server:
            port = await server.listen_tcp("127.0.0.1", 0)
            stream = await trio.open_tcp_stream("127.0.0.1", port)
            rover = FakeRover("m1", "mapper")

            async def send(data: bytes) -> None:
                await stream.send_all(data)

            async with trio.open_nursery() as nursery:
                nursery.start_soon(rover.run, lambda: stream.receive_some(4096), send)
                await trio.sleep(8)
                nursery.cancel_scope.cancel()
            assert rover.welcomed
            (view,) = server.snapshot().rovers
            assert view.id == "m1" and view.stats.up and view.link.startswith("tcp:127.0.0.1:")
            assert view.stats.frames_in >= 5

    run(main)


def test_thread_transport_moves_bytes_and_cancels_promptly() -> None:
    """loop:// has no descriptor: the worker-thread stream echoes bytes and cancels fast."""
    from server.links import ThreadSerialStream, open_serial_stream

    async def main() -> None:
        stream = open_serial_stream("loop://", 115200)
        assert isinstance(stream, ThreadSerialStream)
        await stream.send_all(b"hello\n")
        got = b""
        while len(got) < 6:
            got += await stream.receive_some(64)
        assert got == b"hello\n"
        t0 = trio.current_time()
        with trio.move_on_after(0.2):
            await stream.receive_some(64)  # nothing will come
        assert trio.current_time() - t0 < 0.5
        await stream.aclose()

    trio.run(main)  # a worker thread needs the real clock; this takes about 0.2 s


async def _serial_link_errors(url: str, seconds: float) -> tuple[list, bool]:
    """Serve the serial port ``url`` for ``seconds``; its link_error events, and whether
    the server still answers a snapshot at the end."""
    config = ServerConfig(serial_retry_s=(1.0, 4.0))
    async with open_server(Store(":memory:"), config) as server:
        events = server.subscribe()
        server.start_serial(url, 115200)
        got = []
        with trio.move_on_after(seconds):
            while True:
                got.append(await events.receive())
        return [e for e in got if e.kind == "link_error"], server.snapshot() is not None


def test_missing_serial_port_is_reported_and_retried() -> None:
    """A missing port gives link_error events with a readable message, retried with backoff."""
    async def main() -> None:
        errors, _ = await _serial_link_errors("/dev/does-not-exist", 12)
        assert len(errors) >= 4
        assert errors[0].data["error"].startswith(
            "cannot open serial port /dev/does-not-exist at 115200 baud:")
        assert [e.data["retry_s"] for e in errors[:4]] == [1.0, 2.0, 4.0, 4.0]

    run(main)


def test_whole_game_with_mapper_on_pty_serial_and_others_in_memory() -> None:
    """A full game where the mapper talks over a pty serial link at 115200 baud."""
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    store = Store(":memory:")
    origins = {"mapper": Pose(0, 0, 0), "hider": Pose(0, 0, 0), "seeker": Pose(0, 0, 0)}

    async def main() -> None:
        config = ServerConfig(origins=origins, rovers=frozenset({"m1"}))
        async with open_server(store, config) as server:
            server.start_serial(path, 115200)
            pty = trio.lowlevel.FdStream(os.dup(master))
            mapper = FakeRover("m1", "mapper")
            hider = FakeRover("h1", "hider")
            seeker = FakeRover("s1", "seeker", hider_at=Pose(60.0, 10.0))
            async with trio.open_nursery() as nursery:
                nursery.start_soon(mapper.run, lambda: pty.receive_some(4096), pty.send_all)
                for r in (hider, seeker):
                    receive, send, _ = memory_pipe(server.attach_memory)
                    nursery.start_soon(r.run, receive, send)
                with trio.fail_after(60):
                    while len(server.snapshot().rovers) < 3:
                        await trio.sleep(0.5)
                    assert (await server.command("start_mapping")).ok
                    while server.snapshot().phase != "map_ready":
                        await trio.sleep(0.5)
                    assert (await server.command("hide", x=60, y=10)).ok
                    while server.snapshot().phase != "hidden":
                        await trio.sleep(0.5)
                    assert (await server.command("seek", x=60, y=10)).ok
                    while server.snapshot().phase != "found":
                        await trio.sleep(0.5)
                links = {v.id: v.link for v in server.snapshot().rovers}
                assert links["m1"] == f"serial:{path},115200"
                nursery.cancel_scope.cancel()
            await pty.aclose()
        assert store.games()[0].status == "finished"
        assert store.load_map(store.maps()[0].id).same_as(mapper.room)

    try:
        run(main)
    finally:
        os.close(master)
        os.close(slave)


def test_flood_of_random_frames_reconciles_every_frame_answered_counted_or_dropped() -> None:
    """2,000 frames with one byte mutated each, fed in bursts that sometimes overflow the
    link's buffer: every frame is accounted for. A frame that finds the buffer full is
    dropped whole and counted in bytes. Every line of a delivered frame (a mutated
    newline makes two) is, as decoding it here predicts: taken (``frames_in``) when it
    decodes and its payload checks; counted bad and answered with one ``error`` when it
    does not decode; taken, then refused (both counted, one ``error``) when it decodes
    but its payload does not check."""
    import numpy as np

    from server.protocol import FrameError, read_data
    from server.protocol.lines import LineBuffer

    good = encode_frame(make_frame("pose", {"x": 1, "y": 2, "heading": 3}))
    fit = 16  # frames the buffer holds: a longer burst drops the rest whole
    fates: list[str] = []  # per frame sent: "dropped", or "lines=N"

    async def main() -> None:
        async with open_server(Store(":memory:")) as server:
            out: list[bytes] = []
            link = server.attach_memory(out.append, capacity=fit * len(good))
            link.feed(encode_frame(make_frame("hello", {"id": "x1", "role": "seeker"})))
            await trio.testing.wait_all_tasks_blocked()

            def counts() -> tuple[int, int, int, int]:
                (view,) = server.snapshot().rovers
                errors = sum(decode_line(x).cmd == "error" for c in out for x in c.splitlines())
                return view.stats.frames_in, view.stats.bad_frames, errors, view.stats.dropped

            rng = np.random.default_rng(7)
            while len(fates) < 2000:
                burst = min(int(rng.integers(1, 25)), 2000 - len(fates))
                taken0, bad0, errors0, _ = counts()
                dropped0 = link.dropped_bytes
                lines = ok = undecodable = unchecked = 0
                for k in range(burst):
                    b = bytearray(good)
                    b[int(rng.integers(0, len(b) - 1))] = int(rng.integers(0, 256))
                    link.feed(bytes(b))
                    if k >= fit:
                        fates.append("dropped")
                        continue
                    mine = list(LineBuffer().feed(bytes(b)))
                    fates.append(f"lines={len(mine)}")
                    lines += len(mine)
                    for line in mine:
                        try:
                            frame = decode_line(line)
                        except FrameError:
                            undecodable += 1
                            continue
                        try:
                            read_data(frame)
                            ok += 1
                        except FrameError:
                            unchecked += 1
                await trio.testing.wait_all_tasks_blocked()
                taken, bad, errors, server_dropped = counts()
                assert link.dropped_bytes - dropped0 == max(0, burst - fit) * len(good)
                assert ok + undecodable + unchecked == lines
                assert taken - taken0 == ok + unchecked
                assert bad - bad0 == undecodable + unchecked
                assert errors - errors0 == bad - bad0 and server_dropped == 0
            (view,) = server.snapshot().rovers
            assert view.stats.up and view.stats.bad_frames > 1000

    run(main)
    assert len(fates) == 2000
    dropped = fates.count("dropped")
    assert 100 < dropped < 1900  # the overflow path was taken, and so was delivery
