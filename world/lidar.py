"""The mapper's spinning LIDAR: samples, Data Packet A bytes and the UART.

Rotation: ``rev_s = pwm * lidar_rev_s_full_pwm``; ``lidar_samples_per_rev``
samples per revolution at whole multiples of 360/N degrees (1 deg by default),
angles counted counter-clockwise from the rover's heading. The samples of one
tick are cast together as one fan (`world.raycast.FanCaster`), from the
rover's pose at the end of the tick, against the walls, obstacles and the other
rovers' bodies, and framed from precomputed tables (`world.packets.LidarFramer`).
Range noise is gaussian, then the distance is quantised (2 cm); beyond range is
0 ("no return").

UART: ``lidar_baud / 10`` bytes/s; packets that do not fit in a tick's budget
are dropped whole and counted in ``dropped_bytes``.
"""

from __future__ import annotations

import numpy as np

from actors.firmware.hardware import LIDAR_PACKET_SIZE
from world.packets import LidarFramer
from world.params import DeviceParams
from world.raycast import TWO_PI, FanCaster

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
        self._framer = LidarFramer(params.lidar_samples_per_rev, MAX_SAMPLES_PER_TICK)

    def idle(self) -> bool:
        """No sample falls due in a tick of any length, and `due` would change nothing:
        the rotor is commanded still (PWM 0) with less than one sample accumulated."""
        return self.pwm == 0.0 and 0.0 <= self._sample_acc < 1.0

    def due(self, dt: float, stuck: bool) -> tuple[int, int]:
        """The samples taken during the next ``dt`` [s]: (first angle index, count).

        Advances the rotation; consecutive samples are one index apart. A stuck
        rotor keeps sampling at the commanded rate, all at index ``first``.
        """
        rate = self.pwm * self.p.lidar_rev_s_full_pwm * self.p.lidar_samples_per_rev
        self._sample_acc += rate * dt
        n = min(int(self._sample_acc), MAX_SAMPLES_PER_TICK)
        self._sample_acc -= n
        if self._sample_acc > MAX_SAMPLES_PER_TICK:
            self._sample_acc = 0.0
        first = self.index
        if n and not stuck:
            self.index = (self.index + n) % self.p.lidar_samples_per_rev
        self.samples += n
        return first, n

    def measure(self, first: int, n: int, stuck: bool, pose: tuple[float, float, float],
                caster: FanCaster, noise: np.ndarray) -> np.ndarray:
        """Cast ``n`` samples from angle index ``first``: distances [cm], 0 = no return.

        The distances are whole multiples of the quantum (float, as the framer takes them).

        Args:
            first: angle index of the first sample (from `due`).
            n: number of samples.
            stuck: all samples are at ``first`` (one ray is cast).
            pose: x, y [cm], heading [rad] of the rover.
            caster: the room's geometry with the other rovers' bodies placed.
            noise: standard normal draws, one per sample (scaled here).
        """
        step = TWO_PI / self.p.lidar_samples_per_rev
        x, y, heading = pose
        start = heading + first * step
        if stuck:
            dist = np.repeat(caster.cast_fan((x, y), start, step, 1, self.p.lidar_range_cm), n)
        else:
            dist = caster.cast_fan((x, y), start, step, n, self.p.lidar_range_cm)
        q = self.p.lidar_quantum_cm
        d = dist + noise
        d *= 1.0 / q
        np.rint(d, out=d)
        np.maximum(d, 1.0, out=d)  # a hit never reads 0 ("no return")
        d *= q
        d[np.isinf(dist)] = 0.0
        return d

    def frames(self, first: int, distances_cm: np.ndarray, stuck: bool) -> bytes:
        """Data Packet A bytes of the samples `measure` returned."""
        return self._framer.frames(first, distances_cm, same_angle=stuck)

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

