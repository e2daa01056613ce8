"""One rover as its own process: `supervisors.remote` and ``hideseek rover``.

The whole-game test runs the mapper's own world and tree in the same Trio
run as the server, but its bytes cross two real pseudo-terminals, through
pyserial on both ends (the server's ``start_serial`` and the rover's
``serial:PORT,BAUD``), joined by a relay that plays the cable. The clock is
virtual but only jumps after 0.5 ms of real time with nothing runnable and no
byte arriving, so the pty traffic is never outrun by the clock.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time
import tty

import pytest
import trio
import trio.testing

from actors import scaled_clock
from server.links import parse_link
from server.links.spec import ROVER_LINK
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors.harness.headless import Budget, GameReport, play_game
from supervisors.remote import Uplink, open_remote_rover
from supervisors.rover import IdleNav
from supervisors.system import open_sim_system
from tests.raw_client import free_port
from tui import cmd_rover
from world.scenario import load_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent
PTY_CLOCK_THRESHOLD_S = 0.0005  # real time with nothing to do before the clock jumps [s]


def _idle_nav(role, *, pool, **_):
    return IdleNav(pool)


def _pty_pair() -> tuple[trio.lowlevel.FdStream, str, int]:
    master, slave = os.openpty()
    tty.setraw(slave)
    return trio.lowlevel.FdStream(master), os.ttyname(slave), slave


async def _relay(a, b) -> None:
    while data := await a.receive_some(4096):
        await b.send_all(data)


def test_uplink_is_bounded_and_drops_while_disconnected() -> None:
    """Bytes beyond capacity, and any byte while not connected, are dropped and counted."""
    up = Uplink(capacity=10)
    up.put(b"abc")
    assert up.dropped == 3
    up.connected = True
    up.put(b"0123456789xyz")
    assert up.dropped == 6

    async def take() -> bytes:
        return await up.get()
    assert trio.run(take) == b"0123456789"
    up.put(b"late")
    up.clear()
    assert up.dropped == 10


def test_unreachable_server_is_reported_and_retried_with_backoff() -> None:
    """No server on the port: one readable line per attempt, the waits doubling to the cap."""
    lines: list[str] = []
    port = free_port()

    async def main() -> None:
        scenario = load_scenario("empty")
        link = parse_link(f"tcp:127.0.0.1:{port}")
        async with open_remote_rover(scenario, "hider", link, report=lines.append,
                                     retry_s=(1.0, 4.0), nav_factory=_idle_nav) as rover:
            await trio.sleep(11.1)  # waits are jittered to 3/4..1 of each step
            assert rover.failures == 5 and rover.connects == 0 and not rover.connected

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert [ln.rsplit("retrying in ", 1)[1] for ln in lines] == ["1 s", "2 s", "4 s", "4 s",
                                                                 "4 s"]
    assert lines[0].startswith(f"cannot connect over tcp:127.0.0.1:{port}: ")


def test_udp_rover_without_a_server_says_no_answer_and_retries() -> None:
    """Over UDP nothing connects: the first datagram to a port nobody receives on comes
    back refused (ICMP), the rover says there was no answer, and tries again."""
    lines: list[str] = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]

    async def main() -> None:
        scenario = load_scenario("empty")
        link = parse_link(f"udpout:127.0.0.1:{port}")
        async with open_remote_rover(scenario, "hider", link, report=lines.append,
                                     retry_s=(1.0, 4.0), nav_factory=_idle_nav) as rover:
            await trio.sleep(8)
            assert rover.connects >= 2 and not any("connected" in ln for ln in lines)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert lines[0] == (f"no answer from udpout:127.0.0.1:{port}: Connection refused; "
                        "reconnecting in 1 s")


def test_rover_reconnects_after_the_server_restarts() -> None:
    """The server goes away and comes back on the same port: the rover says hello again."""
    port = free_port()
    lines: list[str] = []

    async def serve_until_hello(store: Store) -> None:
        async with open_server(store, ServerConfig(rovers=frozenset({"seeker"}))) as server:
            events = server.subscribe()
            await server.listen_tcp("127.0.0.1", port)
            async for e in events:
                if e.kind == "hello":
                    await trio.sleep(0.5)  # the welcome reaches the rover: it was answered
                    return

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_remote_rover(scenario, "seeker", parse_link(f"tcp:127.0.0.1:{port}"),
                                         report=lines.append, retry_s=(0.5, 2.0),
                                         nav_factory=_idle_nav) as rover:
                with trio.fail_after(30):
                    await serve_until_hello(store)
                    await serve_until_hello(store)
                assert rover.connects == 2

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert any(ln.startswith(f"lost the server at tcp:127.0.0.1:{port}: ") for ln in lines)


def test_rover_on_tcpin_waits_for_a_server_that_connects_out_and_then_says_connected() -> None:
    """``--link tcpin:HOST:PORT``: the rover listens; the server connects out to it (the
    console's ``--rover ROLE=tcp:HOST:PORT``, pyserial's ``socket://``); "connected" is
    said only once the server has answered."""
    port = free_port()
    lines: list[str] = []

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"hider"}))) as server, \
                    open_remote_rover(scenario, "hider", parse_link(f"tcpin:127.0.0.1:{port}"),
                                      report=lines.append, nav_factory=_idle_nav):
                await trio.sleep(0.5)
                assert not any("connected" in ln for ln in lines)  # nobody answered yet
                events = server.subscribe()
                server.start_serial(f"socket://127.0.0.1:{port}", 115200)
                with trio.fail_after(20):
                    async for e in events:
                        if e.kind == "hello":
                            assert e.rover == "hider"
                            break
                with trio.fail_after(5):
                    while not any("connected" in ln for ln in lines):
                        await trio.sleep(0.1)

    trio.run(main)  # real time: the server's serial link reads the socket in a thread
    assert f"connected to tcpin:127.0.0.1:{port}" in lines


def test_pty_link_gives_a_path_the_server_opens_as_a_serial_port() -> None:
    """``--link pty``: the rover reports a device path; the server's serial link reaches it."""
    lines: list[str] = []

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"hider"}))) as server, \
                    open_remote_rover(scenario, "hider", parse_link("pty"), report=lines.append,
                                      nav_factory=_idle_nav) as rover:
                assert rover.pty_path.startswith("/dev/")
                events = server.subscribe()
                server.start_serial(rover.pty_path, 115200)
                with trio.fail_after(20):
                    async for e in events:
                        if e.kind == "hello":
                            assert e.rover == "hider"
                            assert e.data["link"] == f"serial:{rover.pty_path},115200"
                            break

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=PTY_CLOCK_THRESHOLD_S))
    assert lines[0].startswith("pty ready: give the server serial:/dev/")


def test_pty_attach_is_answered_at_once_and_logs_no_error() -> None:
    """The mapper (its idle firmware sends status and pose) talks into its pty for 10 s
    before the server opens the port (pyserial flushes what waits there, its hellos
    too): the server asks for a hello, the rover says it within a second, and no error
    is logged on either side."""
    lines: list[str] = []
    seen: dict = {}

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_server(store, ServerConfig(rovers=frozenset({"mapper"}))) as server, \
                    open_remote_rover(scenario, "mapper", parse_link("pty"),
                                      report=lines.append) as rover:
                events = server.subscribe()
                await trio.sleep(10)  # hellos at 0, 1, 3 and 7 s wait in the pty; next at 15 s
                opened = trio.current_time()
                server.start_serial(rover.pty_path, 115200)
                kinds = []
                with trio.move_on_after(5):
                    async for e in events:
                        kinds.append(e.kind)
                        if e.kind == "hello":
                            seen["hello_after_s"] = trio.current_time() - opened
                seen["kinds"] = kinds
                seen["view"] = server.snapshot().rovers[0]

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=PTY_CLOCK_THRESHOLD_S))
    # answered, not the rover's own next hello (due 15 s in, 5 s after the port opened); the
    # pty's bytes move in real time under the autojump clock, so a loaded machine adds a
    # second or so of virtual time
    assert seen.get("hello_after_s", math.inf) < 4.0
    assert not {"bad_frame", "link_error", "peer_error", "refused"} & set(seen["kinds"])
    assert seen["view"].stats.up and seen["view"].stats.bad_frames == 0
    assert [ln for ln in lines if "error" in ln] == []


def test_whole_game_with_the_mapper_on_a_pty_serial_link() -> None:
    """Mapper over two ptys (pyserial on both ends), hider and seeker in memory: found."""
    scenario = load_scenario("empty")
    report = GameReport(scenario.name, 1)
    seen: dict = {}

    async def main() -> None:
        server_end, server_path, s1 = _pty_pair()
        rover_end, rover_path, s2 = _pty_pair()
        try:
            async with trio.open_nursery() as cable:
                cable.start_soon(_relay, server_end, rover_end)
                cable.start_soon(_relay, rover_end, server_end)
                with Store(":memory:") as store:
                    async with open_sim_system(scenario, seed=1, store=store,
                                               roles=("hider", "seeker")) as system:
                        system.server.start_serial(server_path, 115200)
                        async with open_remote_rover(scenario, "mapper",
                                                     parse_link(f"serial:{rover_path},115200"),
                                                     seed=1) as rover:
                            await play_game(system, report, Budget(hello=30))
                            seen["rovers"] = {r.id: r for r in system.server.snapshot().rovers}
                            seen["bytes"] = (rover.bytes_in, rover.bytes_out)
                cable.cancel_scope.cancel()
        finally:
            os.close(s1)
            os.close(s2)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=PTY_CLOCK_THRESHOLD_S))
    assert report.outcome == "found", (report.reason, report.events)
    mapper = seen["rovers"]["mapper"]
    assert mapper.link == f"serial:{mapper.link[7:]}" and mapper.link.endswith(",115200")
    assert mapper.stats.up and mapper.stats.bad_frames == 0
    assert seen["rovers"]["hider"].link == "sim:hider"
    assert report.coverage is not None and report.coverage > 0.9
    assert min(seen["bytes"]) > 1000


async def _game_over_udp(scenario, report: GameReport, budget: Budget, mapper) -> dict:
    """Play ``report``'s game: hider and seeker simulated beside a server receiving UDP on
    loopback, the mapper brought by ``mapper(port)`` (an async context for the game).
    Returns the server's rover views at the end."""
    with Store(":memory:") as store:
        async with open_sim_system(scenario, seed=1, store=store,
                                   roles=("hider", "seeker")) as system:
            port = await system.server.listen_udp("127.0.0.1", 0)
            async with mapper(port):
                await play_game(system, report, budget)
                return {r.id: r for r in system.server.snapshot().rovers}


def test_whole_game_with_the_mapper_on_udp() -> None:
    """Mapper over real UDP sockets on loopback (one frame per datagram), hider and
    seeker in memory: found, with no bad frame."""
    scenario = load_scenario("empty")
    report = GameReport(scenario.name, 1)
    seen: dict = {}

    def bring_mapper(port: int):
        return open_remote_rover(scenario, "mapper", parse_link(f"udpout:127.0.0.1:{port}"),
                                 seed=1)

    async def main() -> None:
        seen["rovers"] = await _game_over_udp(scenario, report, Budget(hello=30), bring_mapper)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=PTY_CLOCK_THRESHOLD_S))
    assert report.outcome == "found", (report.reason, report.events)
    mapper = seen["rovers"]["mapper"]
    assert mapper.link.startswith("udp:127.0.0.1:")
    assert mapper.stats.bad_frames == 0 and mapper.stats.frames_in > 100
    assert report.coverage is not None and report.coverage > 0.9


def test_hideseek_rover_over_udp_plays_a_whole_game() -> None:
    """The real command: ``hideseek rover --link udpout:`` in its own process (the mapper,
    at x8) plays a game against a server receiving UDP on loopback (hider and seeker
    simulated there, its clock at x8 too): found, no bad frame, stopped with status 0."""
    speed = 8.0
    scenario = load_scenario("empty")
    report = GameReport(scenario.name, 1)
    seen: dict = {}

    @contextlib.asynccontextmanager
    async def bring_mapper(port: int):
        seen["proc"] = subprocess.Popen(
            [sys.executable, "-m", "tui.cli", "rover", "--role", "mapper", "--scenario",
             "empty", "--link", f"udpout:127.0.0.1:{port}", "--speed", f"{speed:g}"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        yield

    async def main() -> None:
        # The default phase budgets: this game's first guess misses on purpose and its
        # search takes about 160-190 s, and at x8 on a real clock the game is not the
        # virtual-time one (each run's timing differs), so a tight budget fails by chance.
        seen["rovers"] = await _game_over_udp(scenario, report, Budget(hello=160),
                                              bring_mapper)

    try:
        trio.run(main, clock=scaled_clock(speed))
    finally:
        proc = seen.get("proc")
        if proc is not None:
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate(timeout=20)
    assert report.outcome == "found", "\n".join([report.reason, *report.events, out])
    mapper = seen["rovers"]["mapper"]
    assert mapper.link.startswith("udp:127.0.0.1:")
    assert mapper.stats.bad_frames == 0
    assert proc.returncode == 0, out
    assert "mapper: connected to udpout:127.0.0.1:" in out and "Traceback" not in out


def _rover_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="hideseek rover")
    cmd_rover.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--link", "tcp"], f"--link must be {ROVER_LINK.forms}, got 'tcp'"),
        (["--link", "sim"], f"--link must be {ROVER_LINK.forms}, got 'sim'"),
        (["--link", "udpin:0.0.0.0:7878"], f"--link must be {ROVER_LINK.forms}, got "
                                           "'udpin:0.0.0.0:7878' (udp: and udpin: receive "
                                           "(listen), as in MAVProxy; a rover sends with "
                                           "udpout:HOST:PORT)"),
        (["--link", "serial:"], f"--link must be {ROVER_LINK.forms}, got 'serial:' (serial "
                                "link must be serial:PORT[,BAUD])"),
        (["--link", "pty", "--speed", "0"], "--speed must be within 0..1000, got 0"),
        (["--link", "pty", "--scenario", "nowhere"],
         "nowhere: no such scenario file or built-in name (built-ins: empty, furniture, "
         "l_shaped, corridor, cluttered, hall, round, gap)"),
    ],
)
def test_rover_command_refuses_bad_options_with_a_message(argv, message, capsys) -> None:
    """Bad options: exit status 2 and one readable line, no traceback."""
    assert cmd_rover.run(_rover_args(["--role", "mapper", *argv])) == 2
    assert capsys.readouterr().err == f"hideseek rover: {message}\n"


def test_rover_is_welcomed_at_once_after_the_server_was_away_long() -> None:
    """The server is away 20 s (the rover's hello backoff grows meanwhile) and comes back:
    the rover's first hello on the new connection is accepted (no "no hello in time"),
    within 5 s of the server listening, as its reconnect backoff is capped."""
    port = free_port()
    seen: dict = {}

    async def serve_until_hello(store: Store, key: str) -> None:
        async with open_server(store, ServerConfig(rovers=frozenset({"seeker"}))) as server:
            events = server.subscribe()
            await server.listen_tcp("127.0.0.1", port)
            listening = trio.current_time()
            async for e in events:
                seen.setdefault(key + "_kinds", []).append(e.kind)
                if e.kind == "hello":
                    seen[key] = trio.current_time() - listening
                    await trio.sleep(0.5)
                    return

    async def main() -> None:
        scenario = load_scenario("empty")
        with Store(":memory:") as store:
            async with open_remote_rover(scenario, "seeker", parse_link(f"tcp:127.0.0.1:{port}"),
                                         nav_factory=_idle_nav):
                with trio.fail_after(60):
                    await serve_until_hello(store, "first")
                    await trio.sleep(20)
                    await serve_until_hello(store, "again")

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0.01))
    assert seen["again"] < 5.0
    assert "conn_closed" not in seen["again_kinds"]


class _Lines:
    """A process's output lines, read in a thread, waited for by pattern."""

    def __init__(self, proc: subprocess.Popen) -> None:
        import queue
        import threading

        self.seen: list[str] = []
        self._queue: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, args=(proc.stdout,), daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            self._queue.put(line.rstrip("\n"))
        self._queue.put(None)

    def wait_for(self, pattern: str, timeout: float) -> str:
        """The first line (from now on) matching ``pattern``."""
        import queue
        import re

        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self._queue.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                raise AssertionError(f"no line matching {pattern!r}:\n" + "\n".join(self.seen)
                                     ) from None
            if line is None:
                raise AssertionError(f"ended before {pattern!r}:\n" + "\n".join(self.seen))
            self.seen.append(line)
            if re.search(pattern, line):
                return line


def test_hideseek_rover_on_udpout_plays_a_whole_game_against_hideseek_serve_on_udpin(
        tmp_path) -> None:
    """MAVProxy's forms end to end, two real processes at x8: ``hideseek rover --link
    udpout:127.0.0.1:P`` (the mapper) and ``hideseek serve --listen udpin:127.0.0.1:P
    --rover mapper=udp`` (hider and seeker simulated there), driven from serve's console:
    found, and the status line says lost 0; both stop with status 0."""
    port = free_port(socket.SOCK_DGRAM)
    cli = [sys.executable, "-m", "tui.cli"]
    common = ["--scenario", "empty", "--speed", "8"]
    serve = subprocess.Popen(
        [*cli, "serve", "--db", str(tmp_path / "g.db"), "--listen", f"udpin:127.0.0.1:{port}",
         "--rover", "mapper=udp", "--rover", "hider=sim", "--rover", "seeker=sim", *common],
        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    rover = subprocess.Popen(
        [*cli, "rover", "--role", "mapper", "--link", f"udpout:127.0.0.1:{port}", *common],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = _Lines(serve)

    def say(line: str) -> None:
        serve.stdin.write(line + "\n")
        serve.stdin.flush()

    try:
        out.wait_for(f"listening on udp:127.0.0.1:{port}", 60)
        out.wait_for(r"\bhello\s+mapper\b.*link=udp:127.0.0.1:", 60)
        say("start_mapping")
        out.wait_for(r"\bphase\b.*phase=map_ready", 120)
        say("hide 330 240 90 room")
        out.wait_for(r"\bphase\b.*phase=hidden", 120)
        say("seek 330 240 room")
        out.wait_for(r"\bphase\b.*phase=(found|not_found)", 120)
        assert "phase=found" in out.seen[-1], "\n".join(out.seen)
        say("status")
        row = out.wait_for(r"^\s+mapper\s+mapper\s+udp:127.0.0.1:", 20).split()
        assert row[3] == "yes" and row[-3] == "0", row  # up, lost 0
        say("quit")
        assert serve.wait(timeout=30) == 0
    finally:
        for proc in (serve, rover):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        rover_out, _ = rover.communicate(timeout=30)
        serve.wait(timeout=30)
    assert rover.returncode == 0, rover_out
    assert f"mapper: connected to udpout:127.0.0.1:{port}" in rover_out
    assert "Traceback" not in rover_out + "\n".join(out.seen)
