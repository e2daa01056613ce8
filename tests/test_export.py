"""Map export: map_server PGM + YAML, and PNG written without an imaging library."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from server.export import png_bytes, write_pgm, write_png
from server.protocol import GridMap

GRID = GridMap(np.array([[0, 100, -1], [0, 0, 100]], dtype=np.int8), 5.0, (-100.0, 50.0))


def test_pgm_is_map_server_convention(tmp_path) -> None:
    """Free 254, occupied 0, unknown 205; top image row is the highest y; YAML in metres."""
    pgm, yml = write_pgm(GRID, tmp_path, "room")
    data = pgm.read_bytes()
    assert data.startswith(b"P5\n3 2\n255\n")
    assert list(data[len(b"P5\n3 2\n255\n"):]) == [254, 254, 0, 254, 0, 205]
    assert yml.read_text() == ("image: room.pgm\nresolution: 0.05\norigin: [-1, 0.5, 0.0]\n"
                               "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")


def test_png_decodes_to_the_same_pixels(tmp_path) -> None:
    """The PNG's chunks check out and its pixels equal the PGM's."""
    path = write_png(GRID, tmp_path, "room")
    data = path.read_bytes()
    assert data == png_bytes(GRID) and data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, {}
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])
        assert crc == zlib.crc32(kind + body)
        chunks[kind] = body
        pos += 12 + n
    w, h, depth, colour = struct.unpack(">IIBB", chunks[b"IHDR"][:10])
    assert (w, h, depth, colour) == (3, 2, 8, 0)
    raw = zlib.decompress(chunks[b"IDAT"])
    rows = [list(raw[i * 4 + 1:(i + 1) * 4]) for i in range(2)]
    assert rows == [[254, 254, 0], [254, 0, 205]]
