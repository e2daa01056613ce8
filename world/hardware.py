"""One simulated rover's hardware as firmware sees it (the ISR boundary).

`SimRoverHardware` implements the device contract's ``RoverHardware`` protocol
(``actors/firmware/hardware.py``): device commands are its methods, device events are the
interrupt handlers attached with `attach`, which the world calls synchronously
from `World.step` in tick batches (handlers must not block: they post with
``send_nowait`` and return). An exception from a handler propagates out of
``step``, as a fault in an ISR would halt a microcontroller.
"""

from __future__ import annotations

import math
from typing import Any

from actors.firmware.hardware import Handler, HardwareSpec, Interrupt
from world.ir import IrSensor
from world.lidar import Lidar
from world.wifly import WiflyLink

_LINES = frozenset(Interrupt)


def _duty(name: str, value: Any, low: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return min(1.0, max(low, float(value)))


class SimRoverHardware:
    """Device commands and interrupt attachment of one simulated rover.

    Attributes:
        spec: calibration constants the rover's firmware is built with.
        role: ``mapper``, ``hider`` or ``seeker``.
    """

    def __init__(self, role: str, spec: HardwareSpec, treads: tuple, link: WiflyLink,
                 lidar: Lidar | None, ir: IrSensor | None) -> None:
        self.role = role
        self.spec = spec
        self.handlers: dict[int, Handler] = {}
        self._treads = treads
        self._link = link
        self._lidar = lidar
        self._ir = ir

    def attach(self, line: int, handler: Handler | None) -> None:
        """Install (or with ``None`` remove) the ISR for an interrupt line.

        Raises:
            ValueError: ``line`` is not one of Int A..E.
            TypeError: ``handler`` is not callable.
        """
        if line not in _LINES:
            raise ValueError(f"interrupt line must be one of 0xA..0xE, got {line!r}")
        if handler is None:
            self.handlers.pop(int(line), None)
        elif not callable(handler):
            raise TypeError(f"handler must be callable or None, got {handler!r}")
        else:
            self.handlers[int(line)] = handler

    def set_tread_pwm(self, left: float, right: float) -> None:
        """PWM duty per tread, clipped to [-1, 1]; negative drives backwards.

        Raises:
            ValueError: a duty is not a finite number.
        """
        self._treads[0].pwm = _duty("left", left, -1.0)
        self._treads[1].pwm = _duty("right", right, -1.0)

    def set_lidar_pwm(self, duty: float) -> None:
        """LIDAR rotation PWM, clipped to [0, 1]; 0 stops it (no-op on rovers without one)."""
        d = _duty("duty", duty, 0.0)
        if self._lidar is not None:
            self._lidar.pwm = d

    def set_ir_timer(self, rate_hz: float) -> None:
        """IR timer rate [Hz], 0 stops it, at most 1000 Hz (no-op without an IR sensor).

        Raises:
            ValueError: the rate is not a finite number >= 0.
        """
        if (isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float))
                or not math.isfinite(rate_hz) or rate_hz < 0):
            raise ValueError(f"rate_hz must be a finite number >= 0, got {rate_hz!r}")
        if self._ir is not None:
            self._ir.set_rate(min(float(rate_hz), 1000.0))

    def start_adc(self) -> None:
        """Start one IR conversion; Int C follows within the current or next tick."""
        if self._ir is not None:
            self._ir.start()

    def wifly_write(self, data: bytes) -> None:
        """Bytes to the WiFly UART (towards the server).

        Raises:
            TypeError: ``data`` is not bytes-like.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise TypeError(f"data must be bytes, got {type(data).__name__}")
        self._link.rover_write(bytes(data))

    def __repr__(self) -> str:
        lines = ",".join(f"{k:X}" for k in sorted(self.handlers))
        return f"<SimRoverHardware {self.role} handlers=[{lines}]>"
