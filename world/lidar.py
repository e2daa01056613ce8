"""The mapper's spinning LIDAR: samples, Data Packet A bytes and the UART.

Rotation: ``rev_s = pwm * lidar_rev_s_full_pwm``; ``lidar_samples_per_rev``
samples per revolution at whole multiples of 360/N degrees (1 deg by default),
angles counted counter-clockwise from the rover's heading. The samples of one
tick are cast together, from the rover's pose at the end of the tick, against
the walls, obstacles and the other rovers' bodies. Range noise is gaussian,
then the distance is quantised (2 cm); beyond range is 0 ("no return").

UART: ``lidar_baud / 10`` bytes/s; packets that do not fit in a tick's budget
are dropped whole and counted in ``dropped_bytes``.
"""

from __future__ import annotations

import numpy as np

from world.packets import LIDAR_PACKET_SIZE
from world.params import DeviceParams
from world.raycast import cast_rays, cull_to_wedge

#: at most this many samples in one tick (bounds a silly PWM or tick)
MAX_SAMPLES_PER_TICK = 4096


class Lidar:
    """LIDAR state: PWM, angle index, sample clock and UART budget."""

    def __init__(self, params: DeviceParams) -> None:
        self.p = params
        self.pwm = 0.0
        self.index = 0
        """Angle index of the next sample (angle = index * 360 / N)."""
        self._sample_acc = 0.0
        self._byte_budget = 0.0
        self.dropped_bytes = 0
        """Bytes the UART could not carry (cumulative)."""
        self.samples = 0
        """Samples taken (cumulative)."""

    def due(self, dt: float, stuck: bool) -> np.ndarray:
        """Angle indices sampled during the next ``dt`` [s]; advances the rotation.

        A stuck rotor keeps sampling at the commanded rate, all at one angle.
        """
        rate = self.pwm * self.p.lidar_rev_s_full_pwm * self.p.lidar_samples_per_rev
        self._sample_acc += rate * dt
        n = min(int(self._sample_acc), MAX_SAMPLES_PER_TICK)
        self._sample_acc -= n
        if self._sample_acc > MAX_SAMPLES_PER_TICK:
            self._sample_acc = 0.0
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        spr = self.p.lidar_samples_per_rev
        if stuck:
            idx = np.full(n, self.index % spr, dtype=np.int64)
        else:
            idx = (self.index + np.arange(n)) % spr
            self.index = (self.index + n) % spr
        self.samples += n
        return idx

    def measure(self, idx: np.ndarray, pose: tuple[float, float, float], segments: np.ndarray,
                noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cast the samples: (angles [0.01 deg], distances [cm], 0 = no return).

        Args:
            idx: angle indices from `due`.
            pose: x, y [cm], heading [rad] of the rover.
            segments: everything a ray can hit, (N, 4) [cm].
            noise: standard normal draws, one per sample (scaled here).
        """
        spr = self.p.lidar_samples_per_rev
        step = 2.0 * np.pi / spr
        x, y, heading = pose
        first = int(idx[0])
        span = ((int(idx[-1]) - first) % spr) * step
        if span < 0.9 * np.pi and (len(idx) < 2 or int(idx[1]) == (first + 1) % spr
                                 or span == 0.0):
            segments = cull_to_wedge((x, y), heading + first * step, span, segments)
        dist = cast_rays((x, y), heading + idx * step, segments, self.p.lidar_range_cm)
        q = self.p.lidar_quantum_cm
        hit = np.isfinite(dist)
        d = np.where(hit, np.maximum(q, np.round((dist + noise) / q) * q), 0.0)
        return idx * (36000 // spr) if 36000 % spr == 0 else np.round(
            idx * (36000.0 / spr)).astype(np.int64), d.astype(np.int64)

    def uart(self, frames: bytes, dt: float) -> bytes:
        """Pass a tick's bytes through the UART budget, dropping whole packets beyond it."""
        per_tick = self.p.lidar_baud / 10.0 * dt
        # unused budget carries over only up to one packet: a UART does not bank time
        self._byte_budget = min(self._byte_budget, LIDAR_PACKET_SIZE) + per_tick
        fit = int(self._byte_budget) // LIDAR_PACKET_SIZE * LIDAR_PACKET_SIZE
        if len(frames) > fit:
            self.dropped_bytes += len(frames) - fit
            frames = frames[:fit]
        self._byte_budget -= len(frames)
        return frames

