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


_PACKET = np.dtype([("sync", "u1"), ("angle", "<u2"), ("dist", "<u2"), ("check", "u1")])
