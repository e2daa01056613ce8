"""A game survives its server: stopped or killed at any phase, a restarted server on the
same database resumes it and it can be finished; labels say what happened."""

from __future__ import annotations

import functools
import os
import signal
import sqlite3
import subprocess
import sys

import pytest
import trio
import trio.testing

from server.protocol import GridMap, Pose
from server.server import ServerConfig, open_server
from server.store import Store
from tests.fake_rover import FakeRover, memory_pipe, room_map
from tests.raw_client import free_port
from tui import cmd_maps

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ORIGINS = {"m1": Pose(100.0, 100.0, 90.0), "h1": Pose(150.0, 100.0, 90.0),
           "s1": Pose(100.0, 50.0, 0.0)}
IDS = frozenset(ORIGINS)
# (operator command or None to wait, the phase it leads to)
SCRIPT = [("start_mapping", {}, "mapping"), (None, {}, "map_ready"),
          ("hide", {"x": 60.0, "y": 10.0}, "hiding"), (None, {}, "hidden"),
          ("seek", {"x": -20.0, "y": 60.0}, "seeking"), (None, {}, "not_found"),
          ("seek", {"x": 55.0, "y": 5.0}, "seeking"), (None, {}, "found")]
PHASES = ["idle", "mapping", "map_ready", "hiding", "hidden", "seeking", "not_found"]


def _rovers() -> dict[str, FakeRover]:
    return {"m1": FakeRover("m1", "mapper", map_after_s=3.0),
            "h1": FakeRover("h1", "hider", drive_s=2.0),
            "s1": FakeRover("s1", "seeker", hider_at=Pose(60.0, 10.0), drive_s=2.0)}


async def _attach(server, rovers: dict[str, FakeRover], nursery) -> None:
    """Run each rover on a new memory link to ``server``; give them a second to say hello."""
    for r in rovers.values():
        receive, send, _ = memory_pipe(server.attach_memory)
        nursery.start_soon(r.run, receive, send)
    await trio.sleep(1)


async def _wait_phase(server, phase: str, timeout: float = 60.0) -> None:
    with trio.fail_after(timeout):
        while server.snapshot().phase != phase:
            await trio.sleep(0.1)


async def _step(server, k: int) -> None:
    name, kw, phase = SCRIPT[k]
    if name is not None:
        result = await server.command(name, **kw)
        assert result.ok, result.reason
    await _wait_phase(server, phase)


def _what_kill_leaves(src: str, dst: str) -> None:
    """Copy the committed state of a live database: what a kill -9 leaves on disk."""
    a, b = sqlite3.connect(src), sqlite3.connect(dst)
    a.backup(b)
    a.close()
    b.close()


@pytest.mark.parametrize("crash_at", PHASES)
def test_killed_at_each_phase_the_game_resumes_and_can_be_finished(crash_at, tmp_path) -> None:
    """The database as a kill -9 leaves it at each phase: a new server resumes the
    game in that phase, the rovers reconnect (seq_base), and the game ends found."""
    live, left = str(tmp_path / "live.db"), str(tmp_path / "left.db")
    rovers = _rovers()
    seen: dict = {}

    async def main() -> None:
        config = ServerConfig(origins=ORIGINS, rovers=IDS, resume=True)
        with Store(live) as store:
            async with open_server(store, config) as a, trio.open_nursery() as n:
                await _attach(a, rovers, n)
                k = 0
                while a.snapshot().phase != crash_at:
                    await _step(a, k)
                    k += 1
                _what_kill_leaves(live, left)
                seen["game"] = a.game_id
                n.cancel_scope.cancel()
        for r in rovers.values():
            r.welcomed = False  # the link broke: each says hello again
        with Store(left) as store:
            assert store.interrupted == [seen["game"]]
            async with open_server(store, config) as b, trio.open_nursery() as n:
                assert (b.resumed, b.game_id) == (seen["game"], seen["game"])
                assert b.snapshot().phase == crash_at
                await _attach(b, rovers, n)
                while k < len(SCRIPT):
                    await _step(b, k)
                    k += 1
                n.cancel_scope.cancel()
            game = store.game(seen["game"])
            assert (game.status, game.outcome) == ("finished", "found after 2 guesses")
            assert store.game_map(game.id).same_as(room_map())
            assert len(store.games()) == 1

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_clean_stop_new_game_and_fresh_start_are_labelled(tmp_path) -> None:
    """A clean stop leaves the game interrupted (resumable); new_game after a win keeps
    it finished; new_game mid-game stops it; resume=False starts a new game."""
    db = str(tmp_path / "g.db")

    async def main() -> None:
        rovers = _rovers()
        config = ServerConfig(origins=ORIGINS, rovers=IDS, resume=True)
        with Store(db) as store:
            async with open_server(store, config) as s, trio.open_nursery() as n:
                await _attach(s, rovers, n)
                for k in range(len(SCRIPT)):
                    await _step(s, k)
                assert (await s.command("new_game")).ok
                await _step(s, 0)  # the second game is mapping
                n.cancel_scope.cancel()
            g1, g2 = store.games()
            assert (g1.status, g1.outcome) == ("finished", "found after 2 guesses")
            assert (g2.status, g2.outcome) == ("interrupted", "interrupted: the server "
                                                              "stopped in phase mapping")
        with Store(db) as store:
            async with open_server(store, config) as s:
                assert s.resumed == g2.id
                assert (await s.command("new_game")).ok
            assert store.game(g2.id).outcome == ("stopped by the operator (new game) in "
                                                 "phase mapping")
            assert store.game(g2.id).status == "stopped"
        with Store(db) as store:
            async with open_server(store, ServerConfig(resume=False)) as s:
                assert s.resumed is None and s.game_id == 4

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


def test_maps_on_a_live_database_changes_nothing_and_export_takes_the_played_map(
        tmp_path, capsys) -> None:
    """Read-only commands leave a live game running; an upload the game ignored is
    listed apart and export-map writes the map the game played on."""
    db = str(tmp_path / "live.db")

    async def main() -> None:
        rovers = _rovers()
        config = ServerConfig(origins=ORIGINS, rovers=IDS)
        with Store(db) as store:
            async with open_server(store, config) as s, trio.open_nursery() as n:
                await _attach(s, rovers, n)
                for k in range(4):  # hidden
                    await _step(s, k)
                base = room_map()
                cells = base.cells.copy()
                cells[5:8, 5:8] = 100
                other = GridMap(cells, base.resolution_cm, base.origin_cm)
                rovers["m1"].room = other
                rovers["m1"]._act("upload")  # the game is past mapping: ignored
                await trio.sleep(3)
                runs = len(list(store._db.execute("SELECT id FROM runs")))
                args = [cmd_maps.add_arguments, cmd_maps.run]
                assert _cli(args, "maps", ["--db", db]) == 0
                assert store.game(s.game_id).status == "running"
                assert len(list(store._db.execute("SELECT id FROM runs"))) == runs
                n.cancel_scope.cancel()

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    out = capsys.readouterr().out
    assert "played" in out and "ignored: map upload ignored in phase hidden" in out
    assert _cli([cmd_maps.add_arguments, cmd_maps.run], "export-map",
                ["1", "--db", db, "--out", str(tmp_path)]) == 0
    with Store(db, readonly=True) as store:
        played, ignored = store.maps()
        assert (played.accepted, ignored.accepted) == (True, False)
        assert store.game_map(1).same_as(room_map())
    pgm = (tmp_path / "game1.pgm").read_bytes()
    from server.export import pgm_bytes
    assert pgm == pgm_bytes(room_map())


def _cli(fns, prog: str, argv: list[str]) -> int:
    import argparse

    add, run = fns
    parser = argparse.ArgumentParser(prog=f"hideseek {prog}")
    add(parser)
    return run(parser.parse_args(argv))


async def _tcp_rover(rover: FakeRover, port: int) -> None:
    """Run a fake rover over TCP, reconnecting whenever the server goes away."""
    while True:
        try:
            stream = await trio.open_tcp_stream("127.0.0.1", port)
        except OSError:
            await trio.sleep(0.2)
            continue

        rover.welcomed = False
        try:
            await rover.run(functools.partial(_receive, stream), stream.send_all)
        except* (trio.BrokenResourceError, trio.ClosedResourceError, OSError):
            pass
        await trio.sleep(0.2)


async def _receive(stream: trio.SocketStream) -> bytes:
    data = await stream.receive_some(4096)
    if not data:
        raise trio.BrokenResourceError("server closed")
    return data


def _serve(db: str, port: int) -> subprocess.Popen:
    argv = [sys.executable, "-m", "tui.cli", "serve", "--db", db, "--listen",
            f"tcp:127.0.0.1:{port}"]
    for rid, p in ORIGINS.items():
        argv += ["--rover", f"{rid}=tcp", "--origin", f"{rid}={p.x},{p.y},{p.heading_deg}"]
    proc = subprocess.Popen(argv, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        if line.startswith("listening on"):
            break
    return proc


def _command(proc: subprocess.Popen, line: str) -> None:
    proc.stdin.write(line + "\n")
    proc.stdin.flush()


def test_hideseek_serve_killed_with_sigkill_at_every_phase_resumes_the_game(tmp_path) -> None:
    """The real thing: one game in which ``hideseek serve`` is killed with SIGKILL in
    every phase and restarted on the same database; each time it resumes the game in
    that phase, the rovers reconnect over TCP, and the game is won."""
    db, port = str(tmp_path / "g.db"), free_port()
    rovers = _rovers()
    procs: list[subprocess.Popen] = []
    resumed: list[str] = []

    def phase() -> str:
        with Store(db, readonly=True) as store:
            return store.games()[-1].phase

    async def until(want: str, limit: float = 30.0) -> None:
        with trio.fail_after(limit):
            while phase() != want:
                await trio.sleep(0.1)

    def kill_and_restart() -> None:
        before = phase()
        procs[-1].send_signal(signal.SIGKILL)
        procs[-1].wait(10)
        procs.append(_serve(db, port))
        assert phase() == before
        resumed.append(before)

    commands = {"start_mapping": "start_mapping", "hide": "hide 60 10",
                "seek": ["seek -20 60", "seek 55 5"]}

    async def main() -> None:
        async with trio.open_nursery() as n:
            procs.append(_serve(db, port))
            for r in rovers.values():
                n.start_soon(_tcp_rover, r, port)
            await trio.sleep(1.5)
            seeks = iter(commands["seek"])
            for name, _, want in SCRIPT:
                kill_and_restart()  # in the phase the game is in now
                await trio.sleep(1.5)  # the rovers reconnect
                if name is not None:
                    line = next(seeks) if name == "seek" else commands[name]
                    _command(procs[-1], line)
                await until(want)
            _command(procs[-1], "quit")
            procs[-1].wait(10)
            n.cancel_scope.cancel()

    try:
        trio.run(main)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait(5)
    assert resumed == ["idle", "mapping", "map_ready", "hiding", "hidden", "seeking",
                       "not_found", "seeking"]
    with Store(db, readonly=True) as store:
        (game,) = store.games()
        assert (game.status, game.outcome) == ("finished", "found after 2 guesses")
        assert store.game_map(game.id).same_as(room_map())
