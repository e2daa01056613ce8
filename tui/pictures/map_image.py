"""A map as a picture: one square of ``scale`` x ``scale`` pixels per cell, in the
console's colours (`tui.widgets.map_pixels.COLOURS`), drawn and written with Pillow.

Frame: the map frame of the grid [cm]; the image's top row is the highest y (as a
map is drawn on screen and in map_server's PGM). `MapCanvas` turns map-frame points
[cm] into image pixels, so trajectories and markers drawn on the map land on their
cells.
"""

from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass

import numpy as np
from PIL import Image

from server.protocol import GridMap
from tui.widgets.map_pixels import COLOURS, FREE_PX, OCCUPIED_PX, UNKNOWN_PX

__all__ = ["DEFAULT_SCALE", "MAX_SCALE", "MapCanvas", "check_scale", "codes_to_classes",
           "export_png", "hex_rgb", "map_canvas", "write_png"]

DEFAULT_SCALE = 5
"""Pixels per cell edge by default: 5 cm cells are then 1 px per cm, and a 4 x 3 m room
(86 x 66 cells with its margins) is 430 px wide."""
MAX_SCALE = 32
"""The largest ``scale`` [px per cell edge] (a 20 m map is then 12,800 px wide)."""


def check_scale(scale: object) -> int:
    """``scale`` as pixels per cell edge.

    Raises:
        ValueError: not an integer within 1..`MAX_SCALE`.
    """
    if isinstance(scale, bool) or not isinstance(scale, int) or not 1 <= scale <= MAX_SCALE:
        raise ValueError(f"scale must be an integer within 1..{MAX_SCALE}, got {scale!r}")
    return scale


def hex_rgb(colour: str) -> tuple[int, int, int]:
    """``#rrggbb`` -> (r, g, b)."""
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


_PALETTE = np.array([hex_rgb(c) for c in COLOURS], dtype=np.uint8)


@dataclass(frozen=True, slots=True)
class MapCanvas:
    """A map drawn as an RGB image, and where map-frame points fall on it."""

    image: Image.Image
    """The picture (RGB), ``scale`` pixels per cell edge, top row the highest y."""
    origin_cm: tuple[float, float]
    """Map-frame (x, y) of the image's lower-left corner [cm]."""
    px_per_cm: float
    """Pixels per centimetre."""

    def pixel(self, x_cm: float, y_cm: float) -> tuple[float, float]:
        """Image (column, row) [px] of a map-frame point [cm]."""
        return ((x_cm - self.origin_cm[0]) * self.px_per_cm,
                self.image.height - (y_cm - self.origin_cm[1]) * self.px_per_cm)


def map_canvas(classes: np.ndarray, resolution_cm: float, origin_cm: tuple[float, float], *,
               scale: int = DEFAULT_SCALE, margin_cells: int = 0) -> MapCanvas:
    """The map's picture from pixel classes per cell.

    Args:
        classes: (ny, nx) pixel classes of `tui.widgets.map_pixels` (``UNKNOWN_PX``,
            ``FREE_PX``, ``OCCUPIED_PX``, ...), row 0 the lowest y.
        resolution_cm: cell edge [cm].
        origin_cm: map-frame (x, y) of cell [0, 0]'s lower-left corner [cm].
        scale: pixels per cell edge.
        margin_cells: unknown cells added round the map (room for marks beyond it).

    Raises:
        ValueError: a bad ``scale``.
    """
    check_scale(scale)
    m = margin_cells
    grid = np.pad(np.asarray(classes, np.int64), m, constant_values=UNKNOWN_PX)
    rgb = _PALETTE[grid[::-1]]
    rgb = np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1)
    return MapCanvas(Image.fromarray(np.ascontiguousarray(rgb), "RGB"),
                     (origin_cm[0] - m * resolution_cm, origin_cm[1] - m * resolution_cm),
                     scale / resolution_cm)


def codes_to_classes(codes: np.ndarray) -> np.ndarray:
    """Wire codes (0 unknown, 1 free, 2 occupied; `GridMap.codes`) -> pixel classes."""
    return np.array([UNKNOWN_PX, FREE_PX, OCCUPIED_PX], np.int8)[codes]


def write_png(image: Image.Image, path: str | os.PathLike[str]) -> None:
    """Write ``image`` as PNG (raises OSError when the file cannot be written)."""
    image.save(os.fspath(path), format="PNG", optimize=True)


def export_png(grid: GridMap, out_dir: str | os.PathLike[str], name: str, *,
               scale: int = DEFAULT_SCALE) -> pathlib.Path:
    """Write the map as ``out_dir/name.png`` in the console's colours; return its path.

    Raises:
        ValueError: a bad ``scale``.
        OSError: the file cannot be written.
    """
    canvas = map_canvas(codes_to_classes(grid.codes()), grid.resolution_cm,
                        tuple(grid.origin_cm), scale=scale)
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    write_png(canvas.image, path)
    return path
