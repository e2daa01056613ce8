"""Map export: PGM + YAML in the ROS map_server convention.

map_server images: one pixel per cell, the TOP row of the image is the
HIGHEST y, free 254, occupied 0, unknown 205; the YAML gives ``resolution``
[m/pixel], ``origin`` [m, m, rad] of the lower-left pixel, and the
thresholds. A PNG in the console's colours is `tui.pictures.map_image`'s
(``hideseek export-map --format png``).
"""

from __future__ import annotations

import pathlib

import numpy as np

from .protocol import GridMap

__all__ = ["FREE_PIXEL", "OCCUPIED_PIXEL", "UNKNOWN_PIXEL", "map_image", "write_pgm",
           "pgm_bytes"]

FREE_PIXEL = 254
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 205


def map_image(grid: GridMap) -> np.ndarray:
    """Grey pixels (uint8, shape (ny, nx)) with the top row the highest y."""
    lut = np.array([UNKNOWN_PIXEL, FREE_PIXEL, OCCUPIED_PIXEL], dtype=np.uint8)
    return lut[grid.codes()][::-1].copy()


def pgm_bytes(grid: GridMap) -> bytes:
    """The map as a binary PGM (P5) file."""
    img = map_image(grid)
    ny, nx = img.shape
    return b"P5\n%d %d\n255\n" % (nx, ny) + img.tobytes()


def write_pgm(grid: GridMap, out_dir: pathlib.Path | str, name: str) -> tuple[pathlib.Path,
                                                                             pathlib.Path]:
    """Write ``name.pgm`` and ``name.yaml`` into ``out_dir``; return both paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    pgm = out / f"{name}.pgm"
    yml = out / f"{name}.yaml"
    pgm.write_bytes(pgm_bytes(grid))
    ox, oy = grid.origin_cm
    yml.write_text(
        f"image: {pgm.name}\n"
        f"resolution: {grid.resolution_cm / 100.0:.6g}\n"
        f"origin: [{ox / 100.0:.6g}, {oy / 100.0:.6g}, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    return pgm, yml
