"""Device parameters of the simulated rovers, with documented defaults.

Every field can be overridden per scenario in its ``[devices]`` table (same
names). `rover_spec` turns them into the device contract's ``HardwareSpec``,
the calibration record a rover's firmware is built with.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from actors.firmware.hardware import LIDAR_SAMPLES_PER_REV, ROLES, HardwareSpec

__all__ = ["DeviceParams", "LIMITS", "POSITIVE", "ROLES", "rover_spec"]
"""``ROLES`` is the contract's list, re-exported: the world steps the rovers in its order."""

#: parameters that divide or size something: 0 is refused
POSITIVE = frozenset({
    "length_cm", "width_cm", "track_width_cm", "ticks_per_cm", "ticks_per_interrupt",
    "lidar_samples_per_rev", "lidar_quantum_cm", "lidar_range_cm",
})
#: upper bounds: a LIDAR angle is sent in 0.01 deg, probabilities are at most 1
LIMITS = {"lidar_samples_per_rev": 36000, "wifly_loss": 1.0, "wifly_corrupt": 1.0}


@dataclass(frozen=True, slots=True)
class DeviceParams:
    """Physical constants of the simulated hardware (defaults in brackets' units)."""

    # -- body and drive ----------------------------------------------------
    length_cm: float = 20.0
    """Rover body length [cm]."""
    width_cm: float = 15.0
    """Rover body width [cm]."""
    track_width_cm: float = 13.0
    """Distance between the treads' contact lines [cm]."""
    max_speed_cm_s: float = 30.0
    """Tread speed at full PWM [cm/s]."""
    motor_tau_s: float = 0.08
    """First-order lag of the tread motors [s]."""
    slip_sigma: float = 0.022
    """Tread slip noise, the standard deviation of a tread's counted travel over 1 cm
    [cm / sqrt(cm)]: over ``D`` cm the count errs by ``slip_sigma * sqrt(D)`` (0.22 cm
    over 1 m), whatever the tick (`world.drive.slipped_travel`). 0.022 is what a
    relative noise of 0.02 per 50 ms tick gave at the cruise speed (24 cm/s)."""
    # -- encoders ----------------------------------------------------------
    ticks_per_cm: float = 8.0
    """Quadrature encoder ticks per cm of tread travel."""
    ticks_per_interrupt: int = 4
    """Encoder ticks per Int E (the motor counter timer's reload)."""
    # -- LIDAR (mapper) ----------------------------------------------------
    lidar_rev_s_full_pwm: float = 11.0
    """Rotation rate at PWM 1.0 [rev/s]; proportional to PWM (0.5 gives 5.5 rev/s)."""
    lidar_samples_per_rev: int = LIDAR_SAMPLES_PER_REV
    """Range samples per revolution."""
    lidar_range_cm: float = 4000.0
    """Maximum range; farther gives distance 0 ("no return") [cm]."""
    lidar_quantum_cm: float = 2.0
    """Distance resolution [cm]."""
    lidar_noise_cm: float = 0.5
    """Gaussian range noise, standard deviation [cm]."""
    lidar_baud: int = 460800
    """LIDAR UART rate [bit/s], 10 bits per byte; excess bytes in a tick are dropped."""
    # -- IR (seeker) -------------------------------------------------------
    ir_range_cm: float = 60.0
    """Range within which the hider reflects (from the seeker's nose) [cm]."""
    ir_fov_deg: float = 20.0
    """Half field of view [deg]."""
    ir_noise: float = 30.0
    """ADC noise, standard deviation [counts]."""
    ir_low: float = 200.0
    """ADC reading with nothing reflective in view [counts]."""
    ir_high: float = 3800.0
    """ADC reading with the hider at zero distance [counts]; falls to 2500 at range."""
    # -- WiFly -------------------------------------------------------------
    wifly_bytes_s: float = 11520.0
    """WiFly throughput each way (115200 baud) [bytes/s]."""
    wifly_latency_s: float = 0.005
    """One-way latency [s]."""
    wifly_loss: float = 0.0
    """Probability that one tick's chunk of bytes is lost [0..1]."""
    wifly_corrupt: float = 0.0
    """Probability that a byte is corrupted [0..1]."""
    wifly_buffer_bytes: int = 8192
    """Send buffer per direction; bytes written beyond it are dropped [bytes]."""

    def with_overrides(self, overrides: dict[str, Any]) -> DeviceParams:
        """A copy with some fields replaced.

        Raises:
            ValueError: a name is not a field, or a value has the wrong type or sign.
        """
        fields = {f.name: f for f in dataclasses.fields(self)}
        clean: dict[str, Any] = {}
        for name, value in overrides.items():
            if name not in fields:
                raise ValueError(f"unknown device parameter {name!r}")
            default = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{name} must be a number, got {value!r}")
            if isinstance(default, int) and not isinstance(value, int):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if value < 0:
                raise ValueError(f"{name} must not be negative, got {value!r}")
            if name in POSITIVE and value == 0:
                raise ValueError(f"{name} must be > 0, got {value!r}")
            if name in LIMITS and value > LIMITS[name]:
                raise ValueError(f"{name} must be at most {LIMITS[name]:g}, got {value!r}")
            clean[name] = type(default)(value)
        return dataclasses.replace(self, **clean)

    @property
    def cm_per_interrupt(self) -> float:
        """Tread travel per Int E [cm] (0.5 by default)."""
        return self.ticks_per_interrupt / self.ticks_per_cm


def rover_spec(role: str, p: DeviceParams) -> HardwareSpec:
    """The calibration record a rover's firmware is built with, from the device parameters."""
    return HardwareSpec(role, p.cm_per_interrupt, p.track_width_cm, p.length_cm, p.width_cm,
                        p.max_speed_cm_s)
