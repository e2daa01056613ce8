"""Tread motors and quadrature encoders of one rover.

Motor model: PWM duty d in [-1, 1] sets a target tread speed
``d * max_speed_cm_s``; the actual commanded speed follows it with a
first-order lag ``tau`` (``v += (target - v) * (1 - exp(-dt / tau))``). The
physics then decides how far the tread really went (walls stop it).

Encoder model: each tread's travel in a tick [cm] (from the body's motion at
the tread's contact line) is counted with slip (`slipped_travel`): an error of
``slip_sigma * sqrt(|travel|) * N(0, 1)`` [cm], so the error's variance grows
with the distance travelled, not with the number of ticks it took: over a path
of ``D`` cm a tread's count errs by ``slip_sigma * sqrt(D)`` [cm] (standard
deviation) whatever the tick. The count is turned into quadrature ticks
(``ticks_per_cm``), and the motor counter timer raises Int E every
``ticks_per_interrupt`` ticks in either direction.
"""

from __future__ import annotations

import math

from actors.firmware.hardware import encode_counter

#: at most this many Int E per tread per tick (bounds a runaway encoder)
MAX_COUNTER_EVENTS_PER_TICK = 1000


class Tread:
    """One tread: motor lag state and encoder counter state."""

    __slots__ = ("side", "pwm", "speed", "ticks", "counter", "_fwd", "_back")

    def __init__(self, side: int) -> None:
        self.side = side
        self.pwm = 0.0
        self.speed = 0.0
        """Commanded tread speed after the motor lag [cm/s]."""
        self.ticks = 0.0
        """Encoder position [ticks], fractional part carried between ticks."""
        self.counter = 0
        """Whole ticks since the last Int E, signed."""
        self._fwd = encode_counter(side, True)
        self._back = encode_counter(side, False)

    def motor_step(self, max_speed: float, strength: float, alpha: float) -> float:
        """Advance the motor lag one tick; returns the new tread speed [cm/s].

        Args:
            max_speed: speed at full PWM [cm/s].
            strength: 1 normally, less for a weak tread, 0 when stalled.
            alpha: ``1 - exp(-dt / tau)``.
        """
        target = self.pwm * max_speed * strength
        self.speed += (target - self.speed) * alpha
        return self.speed

    def encode(self, travel_cm: float, ticks_per_cm: float, per_interrupt: int) -> list[int]:
        """Count encoder ticks for ``travel_cm`` and return the Int E payloads raised."""
        before = math.floor(self.ticks)
        self.ticks += travel_cm * ticks_per_cm
        self.counter += math.floor(self.ticks) - before
        out: list[int] = []
        if self.counter >= per_interrupt:
            n = min(self.counter // per_interrupt, MAX_COUNTER_EVENTS_PER_TICK)
            self.counter -= n * per_interrupt
            out = [self._fwd] * n
        elif self.counter <= -per_interrupt:
            n = min((-self.counter) // per_interrupt, MAX_COUNTER_EVENTS_PER_TICK)
            self.counter += n * per_interrupt
            out = [self._back] * n
        return out


def slipped_travel(travel_cm: float, z: float, slip_sigma: float) -> float:
    """The travel an encoder counts for a tread that really went ``travel_cm`` [cm].

    Args:
        travel_cm: the tread's true travel in one tick [cm], signed.
        z: a standard normal draw (from the run's generator).
        slip_sigma: slip noise [cm / sqrt(cm)].

    Returns:
        ``travel_cm + slip_sigma * sqrt(|travel_cm|) * z``: independent draws over the
        ticks of a path add up to a variance of ``slip_sigma**2 * D`` for ``D`` cm
        travelled, however the path is cut into ticks.
    """
    return travel_cm + slip_sigma * math.sqrt(abs(travel_cm)) * z


def lag_alpha(dt: float, tau: float) -> float:
    """Smoothing factor of a first-order lag for one step of ``dt`` [s]."""
    return 1.0 if tau <= 0 else 1.0 - math.exp(-dt / tau)
