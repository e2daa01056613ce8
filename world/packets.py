"""Device-side encoders of the wire formats firmware decodes.

Copies of the datasheet formats in ``actors/firmware/devices.py`` (the world
may not import firmware); ``tests/test_world_devices_contract.py`` checks both
sides agree.

Data Packet A (LIDAR UART, 6 bytes, little-endian)::

    0xA5 | angle u16 [0.01 deg, 0..35999] | distance u16 [cm] | checksum u8

``checksum`` is the XOR of the four payload bytes.

Int E payload: bit 0 is the tread (0 left, 1 right), bit 1 set when backwards.
"""

from __future__ import annotations

import numpy as np

LIDAR_SYNC = 0xA5
LIDAR_PACKET_SIZE = 6
TREAD_LEFT = 0
TREAD_RIGHT = 1


def encode_counter(tread: int, forward: bool) -> int:
    """Int E payload for one counter interrupt of ``tread``."""
    return (tread & 1) | (0 if forward else 2)


def encode_lidar_packets(angles_centideg: np.ndarray, distances_cm: np.ndarray) -> bytes:
    """Data Packet A frames for a batch of samples, concatenated.

    Args:
        angles_centideg: angle offsets [0.01 deg], taken modulo 36000.
        distances_cm: distances [cm], >= 0, capped at 65535 (0 = no return).
    """
    a = (np.asarray(angles_centideg, dtype=np.int64) % 36000).astype("<u2")
    d = np.minimum(np.abs(np.asarray(distances_cm, dtype=np.int64)), 65535).astype("<u2")
    out = np.empty(len(a), dtype=_PACKET)
    out["sync"] = LIDAR_SYNC
    out["angle"] = a
    out["dist"] = d
    x = a ^ d
    out["check"] = (x ^ (x >> 8)) & 0xFF
    return out.tobytes()


class LidarFramer:
    """Data Packet A frames for samples at whole angle indices, from precomputed tables.

    The LIDAR samples at angle indices ``0 .. samples_per_rev - 1``; the angle
    bytes and their share of the checksum are computed once per index, and the
    frames are written into one preallocated buffer, so a tick's frames cost a
    few numpy operations. Produces exactly the bytes of `encode_lidar_packets`.

    Args:
        samples_per_rev: angle indices per revolution (index ``i`` is at ``i * 360 / N`` deg).
        max_samples: most samples framed at once.
    """

    def __init__(self, samples_per_rev: int, max_samples: int) -> None:
        spr = samples_per_rev
        idx = np.arange(spr, dtype=np.int64)
        centideg = idx * (36000 // spr) if 36000 % spr == 0 else np.round(
            idx * (36000.0 / spr)).astype(np.int64)
        self.centideg = centideg % 36000
        """Angle offset of each index [0.01 deg]."""
        # repeated so that any run of up to max_samples consecutive indices is one slice
        reps = -(-(max_samples + spr) // spr)
        angle = np.tile(self.centideg, reps).astype("<u2")
        self._angle_bytes = angle.view(np.uint8).reshape(-1, 2)
        self._angle_check = ((angle ^ (angle >> 8)) & 0xFF).astype(np.uint8)
        self._spr = spr
        self._buf = np.empty((max_samples, LIDAR_PACKET_SIZE), dtype=np.uint8)
        self._buf[:, 0] = LIDAR_SYNC

    def frames(self, first: int, distances_cm: np.ndarray, same_angle: bool = False) -> bytes:
        """Frames for samples at indices ``first, first + 1, ...`` (or all at ``first``).

        Args:
            first: angle index of the first sample.
            distances_cm: one distance per sample [cm], integers >= 0 (capped at 65535).
            same_angle: every sample is at ``first`` (a stuck rotor).
        """
        n = len(distances_cm)
        if n == 0:
            return b""
        first %= self._spr
        buf = self._buf[:n]
        at = first if same_angle else slice(first, first + n)
        d = np.minimum(distances_cm, 65535).astype("<u2")
        buf[:, 1:3] = self._angle_bytes[at]
        buf[:, 3:5] = d.view(np.uint8).reshape(n, 2)
        check = buf[:, 5]
        np.bitwise_xor(d, d >> 8, out=check, casting="unsafe")
        check ^= self._angle_check[at]
        return buf.tobytes()


_PACKET = np.dtype([("sync", "u1"), ("angle", "<u2"), ("dist", "<u2"), ("check", "u1")])
