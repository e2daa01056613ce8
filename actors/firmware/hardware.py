"""The rover's hardware as firmware sees it: the ISR boundary.

Firmware reaches the world only through this interface, exactly as C firmware
on the rover's microcontroller reaches its peripherals:

* **Device commands** (firmware -> hardware) are the methods of `RoverHardware`:
  PWM per tread, LIDAR rotation PWM, the IR timer, starting an ADC conversion,
  and bytes written to the WiFly UART.
* **Device events** (hardware -> firmware) are interrupts. Firmware attaches one
  handler per interrupt line with `RoverHardware.attach`; the hardware calls the
  handler synchronously, like an interrupt vector, with the line's payload.
  Handlers are ISRs: they must not block, so they post to a mailbox with
  `send_nowait` and return.

This module is the one written copy of the contract. The simulated world
(`world/`) imports it, and nothing else of the firmware, to implement the
protocol (firmware never imports the world); a serial bridge to a real rover's
peripherals can implement it too. The wire formats below are the devices'
datasheets: the device side encodes them (``world/packets.py``) and the
firmware's ISRs decode them (``drivers/isr.py``); ``tests/test_world_devices_contract.py``
round-trips both. Which rover a `HardwareSpec` is for is one of `ROLES`, the
message layer's list (a rover names its role in ``hello``), re-exported here so
that the world takes it from its one firmware import.

Interrupt lines and payloads
----------------------------
==========  ======================  =================================================
line        seed name               payload passed to the handler
==========  ======================  =================================================
``INT_A``   LIDAR UART              ``bytes``: raw UART bytes, zero or more whole or
                                    partial Data Packet A frames (see below)
``INT_B``   WiFly UART              ``bytes``: raw bytes received by the WiFly module
                                    (Data Packet B: JSON lines of the message layer)
``INT_C``   IR ADC complete         ``int``: ADC sample, 0..4095 (12 bit)
``INT_D``   IR timer rollover       ``None``
``INT_E``   motor counter timer     ``int``: tread and direction, see `encode_counter`
==========  ======================  =================================================

Data Packet A (LIDAR UART, 6 bytes, little-endian)::

    0xA5 | angle u16 [0.01 deg, 0..35999] | distance u16 [cm] | checksum u8

``checksum`` is the XOR of the four payload bytes. Distance 0 means "no
return" (out of range). Angles are the offset from the rover's heading,
counter-clockwise. A receiver resynchronises on 0xA5 after garbage.

Motor counter (Int E): the counter timer of each tread raises Int E every
``ticks_per_interrupt`` encoder ticks; the payload says which tread and which
way it turned. Distance per interrupt is a calibration constant of the rover
(`HardwareSpec.cm_per_interrupt`).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

# the role names are the message layer's (a rover names its role in ``hello``)
from server.protocol.catalogue import ROLES

MAPPER, HIDER, SEEKER = ROLES
"""The role names (`server.protocol.catalogue.ROLES`), as the firmware spells them."""

__all__ = [
    "ROLES",
    "MAPPER",
    "HIDER",
    "SEEKER",
    "Interrupt",
    "RoverHardware",
    "HardwareSpec",
    "Handler",
    "LIDAR_SYNC",
    "LIDAR_PACKET_SIZE",
    "LIDAR_SAMPLES_PER_REV",
    "TREAD_LEFT",
    "TREAD_RIGHT",
    "encode_counter",
    "decode_counter",
]


class Interrupt(enum.IntEnum):
    """Interrupt lines of the seed design (Int A..E)."""

    INT_A = 0xA  #: LIDAR UART: Data Packet A bytes
    INT_B = 0xB  #: WiFly UART: Data Packet B bytes
    INT_C = 0xC  #: IR ADC conversion complete: sample
    INT_D = 0xD  #: IR timer rollover
    INT_E = 0xE  #: motor counter timer: tread distance unit


LIDAR_SYNC = 0xA5
LIDAR_PACKET_SIZE = 6
LIDAR_SAMPLES_PER_REV = 360
"""Samples the LIDAR takes per revolution of its rotor, at whole multiples of
``360 / LIDAR_SAMPLES_PER_REV`` deg (1 deg) [1/rev]."""

TREAD_LEFT = 0
TREAD_RIGHT = 1


def encode_counter(tread: int, forward: bool) -> int:
    """Int E payload: bit 0 is the tread (0 left, 1 right), bit 1 set when backwards."""
    return (tread & 1) | (0 if forward else 2)


def decode_counter(payload: int) -> tuple[int, bool]:
    """Inverse of `encode_counter`: (tread, forward)."""
    return payload & 1, not (payload & 2)


@dataclass(frozen=True, slots=True)
class HardwareSpec:
    """Calibration constants a rover's firmware is built with.

    These are what the firmware author measured on the bench, not ground truth
    of the simulation (the world may add slip and noise on top).
    """

    role: str
    """One of `ROLES` (``mapper``, ``hider`` or ``seeker``)."""
    cm_per_interrupt: float
    """Tread distance per Int E [cm]."""
    track_width_cm: float
    """Distance between the two treads' contact lines [cm]."""
    length_cm: float = 20.0
    """Rover body length [cm]."""
    width_cm: float = 15.0
    """Rover body width [cm]."""
    max_speed_cm_s: float = 30.0
    """Tread speed at full PWM on level ground [cm/s]."""

    @classmethod
    def bench(cls, role: str) -> HardwareSpec:
        """The bench calibration of a ``role`` rover (0.5 cm per Int E, a 13 cm track, the
        20 x 15 cm body): what a firmware part is built with when the rover tree gives
        no spec of its own (a test, a tool). The one place these numbers are written."""
        return cls(role, cm_per_interrupt=0.5, track_width_cm=13.0)

    @property
    def heading_quantum_deg(self) -> float:
        """The dead-reckoned heading's quantum: one interrupt of one tread
        (``cm_per_interrupt``) over the track (``track_width_cm``) [deg]; 2.2 deg on the
        bench."""
        return math.degrees(self.cm_per_interrupt / self.track_width_cm)


Handler = Callable[[Any], None]
"""An ISR: called synchronously with the line's payload; must not block."""


@runtime_checkable
class RoverHardware(Protocol):
    """Device commands of one rover, and the attachment point for its ISRs."""

    spec: HardwareSpec

    def attach(self, line: Interrupt, handler: Handler | None) -> None:
        """Install (or with ``None`` remove) the ISR for ``line``."""

    def set_tread_pwm(self, left: float, right: float) -> None:
        """PWM duty per tread in [-1, 1]; negative drives backwards."""

    def set_lidar_pwm(self, duty: float) -> None:
        """LIDAR rotation motor PWM in [0, 1] (Command B); 0 stops the LIDAR."""

    def set_ir_timer(self, rate_hz: float) -> None:
        """IR timer rate [Hz]; 0 stops it (no more Int D)."""

    def start_adc(self) -> None:
        """Start one IR ADC conversion; Int C follows with the sample."""

    def wifly_write(self, data: bytes) -> None:
        """Write bytes to the WiFly module's UART (Data Packet C)."""
