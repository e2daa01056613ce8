"""Device-side encoder of Data Packet A, vectorised for the simulated LIDAR.

The format (sync byte, little-endian angle and distance, XOR checksum) is
defined once, in the device contract ``actors/firmware/hardware.py``;
``tests/test_world_devices_contract.py`` checks that what is encoded here
decodes in the firmware's ISR.
"""

from __future__ import annotations

import numpy as np

from actors.firmware.hardware import LIDAR_PACKET_SIZE, LIDAR_SYNC


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
        # one frame per index with the distance still 0: sync, angle, the angle's share of
        # the checksum; repeated so that any run of up to max_samples indices is one slice
        reps = -(-(max_samples + spr) // spr)
        angle = np.tile(self.centideg, reps).astype("<u2")
        rows = np.zeros((len(angle), LIDAR_PACKET_SIZE), dtype=np.uint8)
        rows[:, 0] = LIDAR_SYNC
        rows[:, 1:3] = angle.view(np.uint8).reshape(-1, 2)
        rows[:, 5] = (angle ^ (angle >> 8)) & 0xFF
        self._rows = rows
        self._spr = spr
        self._max = max_samples
        words = np.arange(65536)
        self._word_check = ((words ^ (words >> 8)) & 0xFF).astype(np.uint8)
        """The checksum's share of each 16-bit distance (its two bytes XORed)."""

    def frames(self, first: int, distances_cm: np.ndarray, same_angle: bool = False) -> bytes:
        """Frames for samples at indices ``first, first + 1, ...`` (or all at ``first``).

        Args:
            first: angle index of the first sample.
            distances_cm: one distance per sample [cm], >= 0 (capped at 65535; a
                fractional part is dropped).
            same_angle: every sample is at ``first`` (a stuck rotor).

        Raises:
            ValueError: more than ``max_samples`` distances.
        """
        n = len(distances_cm)
        if n == 0:
            return b""
        if n > self._max:
            raise ValueError(f"at most {self._max} samples per call, got {n}")
        first %= self._spr
        if same_angle:
            buf = np.repeat(self._rows[first:first + 1], n, axis=0)
        else:
            buf = self._rows[first:first + n].copy()
        d = np.minimum(distances_cm, 65535).astype("<u2")
        buf[:, 3:5] = d.view(np.uint8).reshape(n, 2)
        buf[:, 5] ^= self._word_check[d]
        return buf.tobytes()


_PACKET = np.dtype([("sync", "u1"), ("angle", "<u2"), ("dist", "<u2"), ("check", "u1")])
