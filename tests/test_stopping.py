"""Every command stops on SIGINT and SIGTERM with one line and status 0, no traceback, and
its files complete (tui/stopping.py); each test signals the real process."""

from __future__ import annotations

import os
import pathlib
import pty
import re
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable

import pytest

from tests.test_shrink import _FAULTS, _ROOM
from tui.stopping import is_interrupt, stopped_line

CLI = [sys.executable, "-X", "faulthandler", "-m", "tui.cli"]  # SIGABRT prints its stacks
SIGNALS = pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
_ANSI = re.compile(r"\x1b(\[[0-9;?<>=]*[ -/]*[@-~]|\][^\x07\x1b]*(\x07|\x1b\\)|[@-_])")


class _Reader:
    """Everything a stream gives, collected by a thread (so the child never blocks on it)."""

    def __init__(self, read: Callable[[], bytes]) -> None:
        self.data = b""
        self._read = read
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            try:
                chunk = self._read()
            except OSError:  # the pty's other side closed
                return
            if not chunk:
                return
            self.data += chunk

    def text(self) -> str:
        self._thread.join(timeout=10)
        return self.data.decode("utf-8", "replace")


def _stop(argv: list[str], sig: signal.Signals, ready: Callable[[str], bool], *,
          terminal: bool = False, timeout: float = 60.0) -> tuple[int, str, str]:
    """Start ``hideseek ARGV``; once ``ready(output so far)``, send ``sig``; return the exit
    status, standard output and standard error. ``terminal``: standard input and error
    on a pty (a Textual console draws there), ANSI sequences taken out of the error text."""
    if terminal:
        master, slave = pty.openpty()
        os.set_blocking(master, True)
        proc = subprocess.Popen(CLI + argv, stdin=slave, stdout=subprocess.PIPE, stderr=slave,
                                env={**os.environ, "TERM": "xterm", "COLUMNS": "100",
                                     "LINES": "30"})
        os.close(slave)
        err = _Reader(lambda: os.read(master, 65536))
    else:
        proc = subprocess.Popen(CLI + argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)
        err = _Reader(proc.stderr.read1)
    out = _Reader(proc.stdout.read1)
    try:
        deadline = time.monotonic() + timeout
        while not ready(out.data.decode("utf-8", "replace") + err.data.decode("utf-8",
                                                                                "replace")):
            assert proc.poll() is None, (out.text(), err.text())
            assert time.monotonic() < deadline, (out.text(), err.text())
            time.sleep(0.05)
        proc.send_signal(sig)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:  # where it hangs: its threads' stacks
            proc.send_signal(signal.SIGABRT)
            proc.wait(timeout=10)
            raise AssertionError("no stop within 30 s of the signal; its stacks:\n"
                                 + err.text()[-8000:]) from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if terminal:
            err.text()
            os.close(master)
    error = err.text()
    if terminal:
        error = _ANSI.sub("", error).replace("\r", "")
    return proc.returncode, out.text(), error


def _after(seconds: float, marker: str) -> Callable[[str], bool]:
    """Ready ``seconds`` after ``marker`` first appears in the output."""
    seen: list[float] = []

    def ready(text: str) -> bool:
        if marker in text and not seen:
            seen.append(time.monotonic())
        return bool(seen) and time.monotonic() - seen[0] >= seconds

    return ready


def _one_stop_line(status: int, err: str, command: str, *, terminal: bool = False) -> None:
    """Status 0, no traceback, and the stop line last and once (after the console's screen,
    on a terminal)."""
    assert status == 0, err
    assert "Traceback" not in err and "Exception" not in err, err
    if terminal:
        assert err.rstrip().endswith(stopped_line(command)), err[-2000:]
    else:
        lines = [line for line in err.splitlines() if line.strip()]
        assert lines[-1:] == [stopped_line(command)], err
    assert err.count("hideseek ") == 1, err


def _statuses(db: pathlib.Path) -> list[str]:
    with sqlite3.connect(db) as conn:
        return [row[0] for row in conn.execute("SELECT status FROM games")]


def test_an_interrupt_inside_exception_groups_is_a_stop_and_a_failure_is_not() -> None:
    """What trio.run raises on Ctrl-C (the interrupt in groups, beside Cancelled) is a stop."""
    import trio

    group = BaseExceptionGroup("x", [BaseExceptionGroup("y", [KeyboardInterrupt()]),
                                     trio.Cancelled._create()])
    assert is_interrupt(group) and is_interrupt(KeyboardInterrupt())
    assert not is_interrupt(BaseExceptionGroup("x", [KeyboardInterrupt(), ValueError()]))
    assert not is_interrupt(ValueError())


@SIGNALS
def test_run_stops_with_one_line_and_its_recording_and_database_complete(sig, tmp_path) -> None:
    from supervisors.recording.reading import read_recording

    rec, db, trace = tmp_path / "g.mcap", tmp_path / "g.db", tmp_path / "t.jsonl"
    status, out, err = _stop(["run", "--scenario", "hall", "--record", str(rec), "--db",
                              str(db), "--trace", str(trace)], sig, _after(1.5, "running"))
    _one_stop_line(status, err, "run")
    assert out.startswith("running hall") and len(out.splitlines()) == 1
    assert read_recording(rec).summary  # written last: the file is complete
    assert _statuses(db) == ["interrupted"]
    assert trace.read_text().endswith("}\n")


@SIGNALS
def test_shrink_stops_with_one_line(sig, tmp_path) -> None:
    src = tmp_path / "three.toml"
    src.write_text(_ROOM + _FAULTS)
    status, out, err = _stop(["shrink", "--scenario", str(src), "--seed", "7", "--budget",
                              "120", "--out", str(tmp_path / "s.toml")], sig,
                             _after(2.0, "shrinking"))
    _one_stop_line(status, err, "shrink")
    assert not (tmp_path / "s.toml").exists()


@SIGNALS
def test_campaign_stops_with_one_line_and_stores_the_games_played(sig, tmp_path) -> None:
    db = tmp_path / "c.sqlite"
    status, out, err = _stop(["campaign", "--quick", "-n", "40", "--workers", "1", "--out",
                              str(db), "--no-progress"], sig, _after(2.0, "campaign seed"))
    assert status == 0, err
    assert "Traceback" not in err
    assert [line for line in err.splitlines() if line.strip()][-1].startswith(
        "hideseek campaign: interrupted after "), err
    with sqlite3.connect(db) as conn:
        (summary,) = conn.execute("SELECT summary FROM campaigns").fetchone()
    assert "interrupted" in summary


@SIGNALS
def test_serve_stops_with_one_line_and_keeps_its_game(sig, tmp_path) -> None:
    db = tmp_path / "s.db"
    status, out, err = _stop(["serve", "--listen", "tcp:127.0.0.1:0", "--db", str(db),
                              "--no-console"], sig, _after(0.2, "listening on"))
    _one_stop_line(status, err, "serve")
    assert _statuses(db) == ["interrupted"]


@SIGNALS
def test_rover_stops_with_one_line(sig) -> None:
    import socket

    with socket.socket() as free:  # a port nobody listens on: the rover retries
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    status, out, err = _stop(["rover", "--role", "mapper", "--scenario", "empty", "--link",
                              f"tcp:127.0.0.1:{port}"], sig, _after(0.0, "retrying"))
    _one_stop_line(status, err, "rover")


@SIGNALS
def test_play_stops_with_one_line_and_its_recording_and_database_complete(sig,
                                                                           tmp_path) -> None:
    from supervisors.recording.reading import read_recording

    rec, db = tmp_path / "p.mcap", tmp_path / "p.db"

    seen: list[float] = []

    def ready(_text: str) -> bool:  # a second after the game and its recording began
        if not seen and rec.exists() and db.exists() and _statuses(db) == ["running"]:
            seen.append(time.monotonic())
        return bool(seen) and time.monotonic() - seen[0] > 1.0

    status, out, err = _stop(["play", "--scenario", "empty", "--speed", "16", "--record",
                              str(rec), "--db", str(db)], sig, ready, terminal=True)
    _one_stop_line(status, err, "play", terminal=True)
    assert read_recording(rec).summary  # written last: the file is complete
    assert _statuses(db) == ["interrupted"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    rec = tmp_path_factory.mktemp("stopping") / "r.mcap"
    subprocess.run(CLI + ["run", "--scenario", "empty", "--budget", "60", "--record", str(rec)],
                   capture_output=True, check=False, timeout=120)
    return rec


@SIGNALS
def test_replay_stops_with_one_line(sig, recording: pathlib.Path) -> None:
    rec = recording
    status, out, err = _stop(["replay", str(rec)], sig, _after(0.5, "Quit"), terminal=True)
    _one_stop_line(status, err, "replay", terminal=True)
