"""The server's command line: serve argument checks, maps listing, export-map."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from server.links.spec import LISTEN, SERVE_ROVER
from server.protocol import GridMap, Pose
from server.store import Store
from tui import cmd_maps, cmd_serve, serve_console


def _args(module, prog: str, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=f"hideseek {prog}")
    module.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--listen", "tcp:0.0.0.0:7878"],
         "refusing to listen on 0.0.0.0: not loopback and no rover tokens (give --token)"),
        (["--rover", "m1=sim"], "--rover m1=sim: a simulated rover's ID is its role, one of "
                                "mapper, hider, seeker"),
        (["--rover", "hider=sim", "--rover", "hider=sim"], "--rover hider=sim given twice"),
        (["--rover", "hider=sim", "--scenario", "nowhere"],
         "nowhere: no such scenario file or built-in name (built-ins: empty, furniture, "
         "l_shaped, corridor, cluttered, hall, round, gap)"),
        (["--rover", "m1=udpout:1.2.3.4:5"],
         f"--rover ID=LINK must be {SERVE_ROVER.forms}, got 'udpout:1.2.3.4:5'"),
        (["--rover", "m1=udp", "--listen", "tcp:127.0.0.1:7878"],
         "a rover on udp needs --listen udp:HOST:PORT"),
        (["--rover", "m1=udp", "--listen", "udp:10.1.2.3:7878"],
         "refusing to listen on 10.1.2.3: not loopback and no rover tokens (give --token)"),
        (["--listen", "serial:/dev/ttyS0"],
         f"--listen must be {LISTEN.forms}, got 'serial:/dev/ttyS0'"),
        (["--listen", "udpout:127.0.0.1:7878"],
         f"--listen must be {LISTEN.forms}, got 'udpout:127.0.0.1:7878'"),
        (["--rover", "m1"], "--rover must be ID=VALUE, got 'm1'"),
        (["--rover", "m1=serial:"], f"--rover ID=LINK must be {SERVE_ROVER.forms}, got "
                                    "'serial:' (serial link must be serial:PORT[,BAUD])"),
        (["--origin", "h1=1,2"], "--origin must be ID=X,Y,HEADING with numbers, got 'h1=1,2'"),
    ],
)
def test_serve_refuses_bad_setups_with_a_message(argv, message, tmp_path, capsys) -> None:
    """Bad options end with exit status 2 and one readable line, no traceback."""
    args = _args(cmd_serve, "serve", argv + ["--db", str(tmp_path / "x.db")])
    assert cmd_serve.run(args) == 2
    assert capsys.readouterr().err == f"hideseek serve: {message}\n"


def test_operator_command_lines_parse() -> None:
    """The stdin command syntax of serve."""
    assert serve_console.parse_command_line("hide 10 20 90 room") == (
        "hide", {"x": 10.0, "y": 20.0, "heading": 90.0, "frame": "room"})
    assert serve_console.parse_command_line("seek 1 2") == ("seek", {"x": 1.0, "y": 2.0,
                                                                 "frame": "map"})
    with pytest.raises(ValueError, match=r"usage: hide X Y \[HEADING\] \[room\|map\]"):
        serve_console.parse_command_line("hide 1")
    assert serve_console.parse_command_line("seek 1 2 room within=120") == (
        "seek", {"within": 120.0, "x": 1.0, "y": 2.0, "frame": "room"})
    with pytest.raises(ValueError, match=r"within=CM must be a number"):
        serve_console.parse_command_line("seek 1 2 within=far")
    assert cmd_serve.parse_origin("h1=1,2,3") == ("h1", Pose(1.0, 2.0, 3.0))


def test_maps_lists_and_export_writes_files(tmp_path, capsys) -> None:
    """maps shows the stored game and map; export-map writes PGM + YAML or PNG."""
    db = tmp_path / "g.db"
    with Store(db) as store:
        gid = store.new_game(t=0)
        store.save_map(GridMap(np.zeros((3, 4), np.int8), 5.0, (0.0, 0.0)), game_id=gid, t=1)
    assert cmd_maps.run(_args(cmd_maps, "maps", ["--db", str(db)])) == 0
    out = capsys.readouterr().out
    # read-only: the game a (here: still open) server plays is not marked interrupted
    assert "    1 running      idle           1    1" in out and "4x3" in out
    assert out.rstrip().endswith("played")
    out_dir = tmp_path / "out"
    for fmt, names in (("pgm", ["game1.pgm", "game1.yaml"]), ("png", ["game1.png"])):
        args = _args(cmd_maps, "export-map", ["1", "--format", fmt, "--out", str(out_dir),
                                              "--db", str(db)])
        assert cmd_maps.run(args) == 0
        assert all((out_dir / n).exists() for n in names)
    args = _args(cmd_maps, "export-map", ["7", "--db", str(db)])
    assert cmd_maps.run(args) == 2
    assert capsys.readouterr().err.endswith(f"no game 7 in {db}\n")
