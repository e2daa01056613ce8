"""The seeker's IR reflectance sensor, its timer (Int D) and ADC (Int C).

The hider is reflective on all sides. The reading is high when the hider's
body is within ``ir_range_cm`` of the seeker's nose and its centre lies within
``+-ir_fov_deg`` of the seeker's heading: it falls linearly from ``ir_high``
at contact to 2500 at the range limit; otherwise it is ``ir_low``. Gaussian
noise (``ir_noise``) is added and the result clipped to the 12-bit ADC range.
Walls do not occlude the beam (a simplification: the sensor's range is short).
"""

from __future__ import annotations

import math

from world.params import DeviceParams

ADC_MAX = 4095
#: reading at the edge of range [counts]
IR_EDGE = 2500.0
#: at most this many Int D per tick
MAX_TIMER_EVENTS_PER_TICK = 100


class IrSensor:
    """IR timer phase and ADC state."""

    def __init__(self, params: DeviceParams) -> None:
        self.p = params
        self.rate_hz = 0.0
        self._phase = 0.0
        self.adc_pending = False
        """A conversion was started and its Int C has not fired yet."""
        self.adc_overruns = 0
        """Conversions started while one was pending (ignored, as a busy ADC does)."""
        self._last: tuple[object, object, float] = (None, None, 0.0)
        # the poses of the last `reading` (the objects themselves) and their level

    def set_rate(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        if rate_hz == 0:
            self._phase = 0.0

    def start(self) -> None:
        if self.adc_pending:
            self.adc_overruns += 1
        self.adc_pending = True

    def idle(self) -> bool:
        """No conversion is pending and no Int D falls due in a tick of any length (the
        timer is stopped with less than one event accumulated): a tick does nothing."""
        return self.rate_hz == 0.0 and 0.0 <= self._phase < 1.0 and not self.adc_pending

    def timer_events(self, dt: float) -> int:
        """How many Int D fire in the next ``dt`` [s]."""
        self._phase += self.rate_hz * dt
        n = min(int(self._phase), MAX_TIMER_EVENTS_PER_TICK)
        self._phase -= int(self._phase)
        return n

    def reading(self, seeker: tuple[float, float, float], hider: tuple[float, float, float],
                noise: float) -> float:
        """Noise-free-plus-``noise`` analogue value before clipping [counts].

        The level of the last two poses given is kept: the samples of one world tick
        read the same poses (the world's tuples of that tick, the same objects), and
        only their noise differs.

        Args:
            seeker: the seeker's x, y [cm] and heading [rad].
            hider: the hider's x, y [cm] and heading [rad].
            noise: added to the level [counts].
        """
        last_seeker, last_hider, level = self._last
        if seeker is not last_seeker or hider is not last_hider:
            level = self.level(seeker, hider)
            self._last = (seeker, hider, level)
        return level + noise

    def level(self, seeker: tuple[float, float, float],
              hider: tuple[float, float, float]) -> float:
        """Noise-free analogue value before clipping [counts] (see the module docstring).

        Args:
            seeker: the seeker's x, y [cm] and heading [rad].
            hider: the hider's x, y [cm] and heading [rad].
        """
        p = self.p
        sx, sy, sa = seeker
        hx, hy, ha = hider
        nose_x = sx + math.cos(sa) * p.length_cm / 2
        nose_y = sy + math.sin(sa) * p.length_cm / 2
        dx, dy = hx - nose_x, hy - nose_y
        bearing = math.degrees(math.atan2(dy, dx) - sa)
        bearing = (bearing + 180.0) % 360.0 - 180.0
        level = p.ir_low
        if abs(bearing) <= p.ir_fov_deg:
            # distance from the nose to the hider's body: the nose in the body's frame
            c, s = math.cos(ha), math.sin(ha)
            along = abs(-dx * c - dy * s) - p.length_cm / 2
            across = abs(dx * s - dy * c) - p.width_cm / 2
            d = math.hypot(max(along, 0.0), max(across, 0.0))
            if d <= p.ir_range_cm:
                level = p.ir_high - (p.ir_high - IR_EDGE) * d / max(p.ir_range_cm, 1e-9)
        return level


def to_adc(value: float) -> int:
    """Clip an analogue value to a 12-bit sample."""
    return int(min(ADC_MAX, max(0, round(value))))
