"""Map export: PGM + YAML in the ROS map_server convention, and PNG.

map_server images: one pixel per cell, the TOP row of the image is the
HIGHEST y, free 254, occupied 0, unknown 205; the YAML gives ``resolution``
[m/pixel], ``origin`` [m, m, rad] of the lower-left pixel, and the
thresholds. The PNG (8-bit grey, same pixel values and orientation) is
written with zlib and struct, no imaging library.
"""

from __future__ import annotations

import pathlib
import struct
import zlib

import numpy as np

from .protocol import GridMap

__all__ = ["FREE_PIXEL", "OCCUPIED_PIXEL", "UNKNOWN_PIXEL", "map_image", "write_pgm",
           "write_png", "png_bytes", "pgm_bytes"]

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


def png_bytes(grid: GridMap, scale: int = 1) -> bytes:
    """The map as an 8-bit greyscale PNG file, ``scale`` x ``scale`` pixels per cell.

    Raises:
        ValueError: ``scale`` is not within 1..32.
    """
    if isinstance(scale, bool) or not isinstance(scale, int) or not 1 <= scale <= 32:
        raise ValueError(f"scale must be an integer within 1..32, got {scale!r}")
    img = map_image(grid)
    if scale > 1:
        img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    ny, nx = img.shape
    raw = b"".join(b"\x00" + img[i].tobytes() for i in range(ny))  # filter 0 per row

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", nx, ny, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


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


def write_png(grid: GridMap, out_dir: pathlib.Path | str, name: str,
              scale: int = 1) -> pathlib.Path:
    """Write ``name.png`` into ``out_dir`` (``scale`` pixels per cell edge); return its path."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    path.write_bytes(png_bytes(grid, scale))
    return path
