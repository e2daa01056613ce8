"""Pictures (tui/pictures): a game drawn from its recording, a campaign's results as a page."""

from __future__ import annotations

import json
import pathlib

import numpy as np
from PIL import Image

from tests.test_shrink import _FAULTS, _ROOM
from tui.cli import main
from tui.pictures.game_image import FAULT_COLOUR
from tui.pictures.map_image import hex_rgb
from tui.widgets.map_pixels import ROVER_COLOURS


def _has_colour(px: np.ndarray, colour: str) -> bool:
    return bool((px == np.array(hex_rgb(colour), np.uint8)).all(axis=2).any())


def test_run_picture_draws_the_map_trajectories_and_fault_onsets(tmp_path: pathlib.Path,
                                                                  capsys) -> None:
    """A failing game with three faults: the picture holds the map, every rover's track and
    a fault mark; the game is the same one (its trace hash) as without the picture."""
    src = tmp_path / "three.toml"
    src.write_text(_ROOM + _FAULTS)
    game = ["run", "--scenario", str(src), "--seed", "7", "--budget", "120", "--json"]
    picture = tmp_path / "g.png"
    assert main([*game, "--picture", str(picture)]) == 1
    drawn = json.loads(capsys.readouterr().out)
    with Image.open(picture) as img:
        assert img.format == "PNG" and img.width >= 400 and img.height >= 300
        px = np.asarray(img.convert("RGB"))
    assert _has_colour(px, FAULT_COLOUR)
    assert all(_has_colour(px, ROVER_COLOURS[role]) for role in ("mapper", "hider", "seeker"))
    assert main(game) == 1
    assert json.loads(capsys.readouterr().out)["trace_hash"] == drawn["trace_hash"]


def test_a_picture_in_no_folder_is_one_line_and_status_2(tmp_path: pathlib.Path, capsys) -> None:
    assert main(["run", "--scenario", "empty", "--picture", str(tmp_path / "no" / "g.png")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("hideseek run: --picture must be a file in an existing folder")
