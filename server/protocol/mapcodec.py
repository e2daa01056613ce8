"""Occupancy maps on the wire: 2-bit cell codes, run-length coded, base64, in chunks.

A map is a grid of ``ny`` rows by ``nx`` columns, row 0 at the bottom (lowest
y), column 0 at the left (lowest x). Cell ``[i, j]`` covers
``x in [ox + j*r, ox + (j+1)*r)``, ``y in [oy + i*r, oy + (i+1)*r)`` where
``(ox, oy)`` is ``origin_cm`` (the lower-left corner of cell ``[0, 0]``) and
``r`` is ``resolution_cm``, all in the map frame [cm].

The map is a `GridMap` (``grid_map``): its cells are -1 unknown, 0 free, 100
occupied, classified once when the map was made.

Wire encoding (one byte string, then base64):

1. Cells in row-major order (row 0 first), each as a code: 0 unknown, 1 free,
   2 occupied.
2. Runs of equal codes, each run as a LEB128-style varint group: the first
   byte is ``code << 6 | more << 5 | (length & 0x1F)``; while ``more`` is set,
   further bytes carry the next 7 bits of ``length >> 5``, low bits first,
   with bit 7 set on every byte but the last. ``length >= 1``.
3. CRC-32 (zlib/IEEE) of the byte string goes in every chunk's ``crc``.
4. The base64 text is cut into pieces of `CHUNK_B64_CHARS`; piece ``k`` of
   ``n`` goes in chunk ``index=k, count=n`` together with ``nx, ny,
   resolution_cm, origin_cm`` so any chunk describes the whole map.

A frame carrying one chunk stays under `MAX_LINE_BYTES` whatever ``seq`` and
``ack`` it carries.
"""

from __future__ import annotations

import base64
import binascii
import zlib
from dataclasses import dataclass, field

import numpy as np

from .catalogue import MAP, MapChunk
from .frame import Frame
from .grid_map import FREE, MAX_CELLS, OCCUPIED, UNKNOWN, GridMap, MapError

__all__ = ["CHUNK_B64_CHARS", "encode_runs", "decode_runs", "map_chunks", "MapAssembler"]

CHUNK_B64_CHARS = 640
"""Base64 characters per chunk: keeps a chunk frame well under 1 KiB."""


def encode_runs(codes: np.ndarray) -> bytes:
    """Run-length code a flat array of 2-bit codes (step 2 of the module docstring)."""
    flat = np.ascontiguousarray(codes, dtype=np.uint8).ravel()
    if flat.size == 0:
        return b""
    if int(flat.max()) > 2:
        raise MapError("codes must be 0, 1 or 2")
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    starts = np.concatenate(([0], edges))
    lengths = np.diff(np.concatenate((starts, [flat.size])))
    values = flat[starts]
    out = bytearray()
    for code, length in zip(values.tolist(), lengths.tolist(), strict=True):
        rest = length >> 5
        out.append((code << 6) | (0x20 if rest else 0) | (length & 0x1F))
        while rest:
            b = rest & 0x7F
            rest >>= 7
            out.append(b | (0x80 if rest else 0))
    return bytes(out)


def decode_runs(data: bytes, n_cells: int) -> np.ndarray:
    """Inverse of `encode_runs`: a flat ``uint8`` array of exactly ``n_cells`` codes.

    Raises:
        MapError: bad code, truncated run, or a cell count other than ``n_cells``.
    """
    values: list[int] = []
    lengths: list[int] = []
    total = 0
    i, n = 0, len(data)
    while i < n:
        b = data[i]
        i += 1
        code = b >> 6
        if code > 2:
            raise MapError(f"bad cell code 3 at byte {i - 1}")
        length = b & 0x1F
        if b & 0x20:
            shift = 5
            while True:
                if i >= n:
                    raise MapError("run truncated")
                c = data[i]
                i += 1
                length |= (c & 0x7F) << shift
                shift += 7
                if not c & 0x80:
                    break
                if shift > 35:
                    raise MapError("run length too long")
        if length == 0:
            raise MapError(f"zero-length run at byte {i - 1}")
        total += length
        if total > n_cells:
            raise MapError(f"runs hold more than the {n_cells} cells of the map")
        values.append(code)
        lengths.append(length)
    if total != n_cells:
        raise MapError(f"runs hold {total} cells, the map has {n_cells}")
    return np.repeat(np.array(values, dtype=np.uint8), np.array(lengths, dtype=np.int64))


def map_chunks(grid: GridMap, map_id: int) -> list[Frame]:
    """The ``map`` frames (without ``seq``/``ack``) that carry ``grid``."""
    raw = encode_runs(grid.codes())
    crc = zlib.crc32(raw)
    text = base64.b64encode(raw).decode("ascii")
    pieces = [text[k:k + CHUNK_B64_CHARS] for k in range(0, len(text), CHUNK_B64_CHARS)]
    ny, nx = grid.shape
    ox, oy = (float(v) for v in grid.origin_cm)
    frames = []
    for k, piece in enumerate(pieces):
        chunk = MapChunk(map_id=map_id, index=k, count=len(pieces), nx=nx, ny=ny,
                         resolution_cm=float(grid.resolution_cm), origin_cm=(ox, oy),
                         crc=crc, b64=piece)
        frames.append(Frame(MAP, "chunk", _builtins(chunk)))
    return frames


def _builtins(chunk: MapChunk) -> dict:
    return {"map_id": chunk.map_id, "index": chunk.index, "count": chunk.count,
            "nx": chunk.nx, "ny": chunk.ny, "resolution_cm": chunk.resolution_cm,
            "origin_cm": list(chunk.origin_cm), "crc": chunk.crc, "b64": chunk.b64}


@dataclass
class MapAssembler:
    """Collects the chunks of one map and gives the `GridMap` when all arrived.

    A chunk of a different ``map_id`` (or with different dimensions) starts a
    new map and discards the old pieces, so memory stays bounded by one map.
    """

    map_id: int | None = None
    """Id of the map being assembled, None before the first chunk."""
    _header: tuple | None = None
    _pieces: dict[int, str] = field(default_factory=dict)

    def add(self, chunk: MapChunk) -> GridMap | None:
        """Take one chunk; return the whole map once every chunk is in.

        Raises:
            MapError: the chunk is inconsistent, or the assembled map fails its
                CRC or run check (the pieces are then discarded).
        """
        if chunk.index >= chunk.count:
            raise MapError(f"chunk index {chunk.index} is not below count {chunk.count}")
        if chunk.nx * chunk.ny > MAX_CELLS:
            raise MapError(f"map of {chunk.nx}x{chunk.ny} cells is over the limit")
        header = (chunk.count, chunk.nx, chunk.ny, chunk.resolution_cm,
                  tuple(chunk.origin_cm), chunk.crc)
        if chunk.map_id != self.map_id or header != self._header:
            self.map_id = chunk.map_id
            self._header = header
            self._pieces = {}
        self._pieces[chunk.index] = chunk.b64
        if len(self._pieces) < chunk.count:
            return None
        text = "".join(self._pieces[k] for k in range(chunk.count))
        self._pieces = {}
        self._header = None
        try:
            raw = base64.b64decode(text, validate=True)
        except (binascii.Error, ValueError):
            raise MapError("map chunks are not valid base64") from None
        if zlib.crc32(raw) != chunk.crc:
            raise MapError("map CRC mismatch")
        codes = decode_runs(raw, chunk.nx * chunk.ny)
        lut = np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8)
        cells = lut[codes].reshape(chunk.ny, chunk.nx)
        cells.flags.writeable = False
        return GridMap(cells, chunk.resolution_cm,
                       (float(chunk.origin_cm[0]), float(chunk.origin_cm[1])))

    def missing(self) -> list[int]:
        """Indices of the chunks of the current map not yet received."""
        if self._header is None:
            return []
        return [k for k in range(self._header[0]) if k not in self._pieces]
