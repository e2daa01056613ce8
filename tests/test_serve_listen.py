"""``hideseek serve`` checks every ``--listen`` address before it writes anything: a busy
one is one line naming it, status 2, and the database as it was."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from server.store import Store

CLI = [sys.executable, "-m", "tui.cli"]


@pytest.mark.parametrize("proto", ["tcp", "udp"])
def test_a_busy_listen_address_is_one_line_naming_it_and_leaves_the_database(proto,
                                                                           tmp_path) -> None:
    db = tmp_path / "s.db"
    with Store(str(db)):
        pass
    before = db.read_bytes()
    kind = socket.SOCK_STREAM if proto == "tcp" else socket.SOCK_DGRAM
    with socket.socket(socket.AF_INET, kind) as busy:
        busy.bind(("127.0.0.1", 0))
        if proto == "tcp":
            busy.listen()
        port = busy.getsockname()[1]
        p = subprocess.run(CLI + ["serve", "--listen", "tcp:127.0.0.1:0", "--listen",
                                  f"{proto}:127.0.0.1:{port}", "--db", str(db), "--no-console"],
                           capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert p.returncode == 2, p.stderr
    assert p.stdout == ""
    (line,) = p.stderr.splitlines()
    assert f"127.0.0.1:{port}" in line and "already in use" in line, line
    assert db.read_bytes() == before
