"""Map export: map_server PGM + YAML, and PNG in the console's colours (Pillow)."""

from __future__ import annotations

import numpy as np
from PIL import Image

from server.export import write_pgm
from server.protocol import GridMap
from server.store import Store
from tui.cli import main
from tui.pictures.map_image import DEFAULT_SCALE, export_png, hex_rgb
from tui.widgets.map_pixels import COLOURS, FREE_PX, OCCUPIED_PX, UNKNOWN_PX

GRID = GridMap(np.array([[0, 100, -1], [0, 0, 100]], dtype=np.int8), 5.0, (-100.0, 50.0))


def test_pgm_is_map_server_convention(tmp_path) -> None:
    """Free 254, occupied 0, unknown 205; top image row is the highest y; YAML in metres."""
    pgm, yml = write_pgm(GRID, tmp_path, "room")
    data = pgm.read_bytes()
    assert data.startswith(b"P5\n3 2\n255\n")
    assert list(data[len(b"P5\n3 2\n255\n"):]) == [254, 254, 0, 254, 0, 205]
    assert yml.read_text() == ("image: room.pgm\nresolution: 0.05\norigin: [-1, 0.5, 0.0]\n"
                               "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")


def test_png_is_the_map_in_the_consoles_colours_scaled(tmp_path) -> None:
    """Each cell is scale x scale pixels of its console colour; the top row is the highest y."""
    path = export_png(GRID, tmp_path, "room", scale=3)
    with Image.open(path) as img:
        assert img.format == "PNG" and img.size == (9, 6) and img.mode == "RGB"
        px = np.asarray(img)
    free, occ, unknown = (hex_rgb(COLOURS[c]) for c in (FREE_PX, OCCUPIED_PX, UNKNOWN_PX))
    top = [tuple(px[0, 3 * i]) for i in range(3)]  # cells of row 1 (the highest y)
    bottom = [tuple(px[5, 3 * i + 2]) for i in range(3)]
    assert top == [free, free, occ] and bottom == [free, occ, unknown]


def test_export_map_png_is_at_least_400_px_wide_for_a_4_by_3_m_room(tmp_path, capsys) -> None:
    """By default (``--scale`` left out) a 4 x 3 m room's map (86 x 66 cells) is >= 400 px wide."""
    db = tmp_path / "g.db"
    with Store(db) as store:
        gid = store.new_game(t=0)
        grid = GridMap(np.zeros((66, 86), np.int8), 5.0, (-30.0, -30.0))
        store.save_map(grid, game_id=gid, t=1)
    out = tmp_path / "out"
    assert main(["export-map", "1", "--db", str(db), "--format", "png", "--out", str(out)]) == 0
    with Image.open(out / "game1.png") as img:
        assert img.width >= 400 and img.size == (86 * DEFAULT_SCALE, 66 * DEFAULT_SCALE)
    assert main(["export-map", "1", "--db", str(db), "--format", "png", "--scale", "2",
                 "--out", str(out)]) == 0
    with Image.open(out / "game1.png") as img:
        assert img.size == (172, 132)
    capsys.readouterr()
    assert main(["export-map", "1", "--db", str(db), "--format", "png", "--scale", "0"]) == 2
    assert capsys.readouterr().err == "hideseek export-map: --scale must be within 1..32, got 0\n"
