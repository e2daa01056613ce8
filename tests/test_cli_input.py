"""The command line on bad input and signals: one clear line, exit status 2; SIGTERM
and SIGINT stop cleanly with status 0 and no traceback (run as subprocesses)."""

from __future__ import annotations

import ast
import socket
import subprocess
import sys

import pytest

CLI = [sys.executable, "-m", "tui.cli"]


def hideseek(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(CLI + list(args), capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.mark.parametrize(("args", "named"), [
    (("run", "--seed", "-5"), "--seed"),
    (("run", "--db", "/no/such/dir/x.db"), "/no/such/dir"),
    (("run", "--budget", "0"), "--budget"),
    (("play", "--seed", "x"), "--seed"),
    (("play", "--speed", "3"), "--speed"),
    (("play", "--json"), "--json"),
    (("campaign", "--out", "/no/such/dir/c.sqlite"), "/no/such/dir"),
    (("campaign", "--family", "mazes"), "--family"),
    (("run", "--generated", "mazes:1:2"), "mazes"),
    (("run", "--generated", "1"), "[FAMILY:]SEED:INDEX"),
    (("rover", "--role", "mapper", "--link", "carrier-pigeon:1"), "carrier-pigeon"),
])
def test_bad_option_is_one_line_naming_it_and_status_2(args, named) -> None:
    p = hideseek(*args)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0], p.stderr
    assert "Traceback" not in p.stderr


def test_version_is_printed() -> None:
    p = hideseek("--version")
    assert p.returncode == 0 and p.stdout.startswith("hideseek ")


_IMPORTS_OF = """
import sys
from tui import cli
try:
    cli.main(sys.argv[1:])
except SystemExit:
    pass
print(sorted(m for m in sys.modules if m.startswith("tui.cmd_") or m == "importlib.metadata"))
"""


@pytest.mark.parametrize(("args", "loaded"), [
    (("run", "--help"), ["tui.cmd_run"]),
    (("ports", "--help"), ["tui.cmd_ports"]),
    (("--help",), []),
    (("--version",), ["importlib.metadata"]),
])
def test_a_command_imports_only_its_own_module(args, loaded) -> None:
    """A game's process start pays only for its own command: the other commands' modules
    (campaign, shrink, the console) are not imported, nor, for the top level's help,
    the version lookup (a library of a command may import it for itself)."""
    p = subprocess.run([sys.executable, "-c", _IMPORTS_OF, *args], capture_output=True,
                       text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert p.returncode == 0, p.stderr
    found = ast.literal_eval(p.stdout.strip().splitlines()[-1])
    if args[0] not in ("--help", "--version"):
        found = [m for m in found if m.startswith("tui.")]
    assert found == loaded


def test_help_lists_every_command_without_importing_them() -> None:
    from tui.cli import COMMANDS  # noqa: PLC0415

    p = hideseek("--help")
    assert p.returncode == 0
    assert all(name in p.stdout for name in COMMANDS)


def test_busy_port_in_play_is_one_line_and_status_2() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        p = hideseek("play", "--scenario", "empty", "--rover", "mapper=tcp",
                     "--listen", f"tcp:127.0.0.1:{port}")
    assert p.returncode == 2
    assert f"cannot listen on tcp:127.0.0.1:{port}" in p.stderr
    assert "Traceback" not in p.stderr and "ExceptionGroup" not in p.stderr


def test_ports_lists_serial_ports_as_json() -> None:
    import json

    p = hideseek("ports", "--json")
    assert p.returncode == 0
    rows = json.loads(p.stdout)
    assert isinstance(rows, list)
    assert all({"device", "by_id", "description", "hwid"} <= set(r) for r in rows)


_FROZEN_AFTER = """
import gc, sys
from tui import cli
process, sys.argv = sys.argv[1] == "process", ["hideseek", "run", "--help"]
try:
    cli.main(None if process else sys.argv[1:])
except SystemExit:
    pass
print(gc.isenabled(), gc.get_freeze_count() > 1000)
"""


@pytest.mark.parametrize(("how", "frozen"), [("process", True), ("library", False)])
def test_the_process_command_line_freezes_what_its_imports_made(how: str, frozen: bool) -> None:
    """Run as the process's command line (no argv), the modules' objects leave the cyclic
    collector's generations; called with arguments (a library, a test) nothing is frozen;
    the collector runs again either way."""
    p = subprocess.run([sys.executable, "-c", _FROZEN_AFTER, how],
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split()[-2:] == ["True", str(frozen)]
