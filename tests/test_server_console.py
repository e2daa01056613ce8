"""serve's operator console: help, status for people, every command in the refusal,
and end of input stopping the server cleanly (the game kept, interrupted)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from server.protocol import LinkStats
from server.server import RoverView, ServerSnapshot
from server.store import Store
from tui.serve_console import CONSOLE_COMMANDS, format_status

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _serve(db: str, stdin) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tui.cli", "serve", "--db", db,
                             "--listen", "none"], cwd=ROOT, stdin=stdin,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def test_piped_commands_then_end_of_input_stop_the_server_cleanly(tmp_path) -> None:
    """help, status and a bad command answered; EOF stops with status 0; the game is
    recorded interrupted by a clean stop, not a crash."""
    db = str(tmp_path / "g.db")
    proc = _serve(db, subprocess.PIPE)
    out, _ = proc.communicate(b"help\nstatus\ndance\nhide 1\n", timeout=60)
    text = out.decode()
    assert proc.returncode == 0, text
    assert "ROVER/TARGET, new_game, status, help, quit" in text  # the banner
    assert "quit                               stop the server" in text  # help
    assert "game 1: idle\n  no rover has said hello yet\n" in text
    assert f"? unknown command 'dance'; commands: {', '.join(CONSOLE_COMMANDS)}" in text
    assert "? usage: hide X Y [HEADING] [room|map]" in text
    assert text.rstrip().endswith("end of input: stopping the server")
    with Store(db, readonly=True) as store:
        (game,) = store.games()
        assert (game.status, game.outcome) == ("interrupted", "interrupted: the server "
                                                              "stopped in phase idle")
    proc = _serve(db, subprocess.PIPE)  # the next start resumes it and says so
    out, _ = proc.communicate(b"quit\n", timeout=60)
    assert b"resuming game 1 in phase idle (its server stopped)" in out


def test_terminal_console_prompts_and_ctrl_d_stops(tmp_path) -> None:
    """On a terminal the console prompts; Ctrl-D stops the server as Ctrl-C does."""
    master, slave = os.openpty()
    try:
        proc = _serve(str(tmp_path / "g.db"), slave)
        os.close(slave)
        time.sleep(0.1)
        os.write(master, b"status\n")
        os.write(master, b"\x04")
        out, _ = proc.communicate(timeout=60)
    finally:
        os.close(master)
    assert proc.returncode == 0
    assert b"hideseek> " in out and b"game 1: idle" in out


def test_status_is_formatted_for_people() -> None:
    """One row per rover with its link, up, rtt in ms and counters."""
    stats = LinkStats(up=True, frames_in=12, frames_out=9, bytes_in=0, bytes_out=0, lost=1,
                      resent=2, duplicates=0, bad_frames=3, dropped=0, stalls=0,
                      rtt_s=0.0234, unacked=0, queued=0, last_heard=1.0)
    snap = ServerSnapshot(5.0, 3, "hiding", "", (RoverView("h1", "hider", "tcp:127.0.0.1:5",
                                                            stats, None, {}),),
                          None, None, (), 0, 2, {"bad_frame": 7})
    lines = format_status(snap).splitlines()
    assert lines[0] == "game 3: hiding"
    assert lines[2].split() == ["h1", "hider", "tcp:127.0.0.1:5", "yes", "23", "ms", "12",
                                "9", "1", "2", "3"]
    assert lines[3] == ("  connections 2; refused since start: 7 bad frames, "
                        "0 failed hellos, 0 links closed")
