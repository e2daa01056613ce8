"""LIDAR Control (mapper): Command B, and Data Packet A samples batched into scans.

The seed's LIDAR Control thread. ``LIDAR_START`` / ``LIDAR_RATE`` set the
rotation PWM, ``LIDAR_STOP`` stops it (Command B). The LIDAR UART ISR (Int A)
posts each interrupt's run of Data Packet A frames as one ``LIDAR_SAMPLES``
pool handle (angles [0.1 deg] from the rover's heading, distances [cm], 0 =
no return), like a DMA receive buffer handed over by pointer: one message per
world tick instead of one per sample. Bytes that are not a clean run of frames
(garbage on the line, a frame split across interrupts) come as one
``LIDAR_SAMPLE`` per frame instead. Motor Control posts the dead-reckoned
pose (``LIDAR_POSE_XY`` [cm], ``LIDAR_POSE_HEADING`` [deg]) after every batch
of encoder ticks.

Pose association
    The world delivers a tick's encoder ticks and LIDAR packets together and
    the packets were measured at the pose reached at the end of that tick;
    Motor Control publishes that pose after it counted the ticks. So samples
    wait here until the next pose arrives and are stamped with it; if no pose
    comes before the next samples (the rover stands still, so the pose did
    not change) they are stamped with the current pose. Either way a batch is
    sent as one ``MAP_SCAN``: a handle in the rover's `BufferPool` to a `Scan`.
    A full Map Management queue or a dry pool drops the batch (counted in
    `dropped_scans`): scans are a stream and the next revolution covers it.

Restart: the state is the PWM duty and the latest pose. The duty is kept by
the hardware; the pose is asked again from Motor Control (``MOTOR_GET_POSE``).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np

from actors import Actor, BufferPool, ExitReason, Message, PoolExhausted

from .commands import Cmd
from .devices import Interrupt, RoverHardware
from .isr import LidarSamples, LidarUartIsr
from .odometry import Pose

__all__ = ["Scan", "LidarControl"]


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One batch of LIDAR returns taken at ``pose`` (what ``MAP_SCAN`` points to)."""

    pose: Pose
    """Rover pose in its own frame when the batch was taken."""
    angles_deg: np.ndarray
    """Ray angles from the rover heading, counter-clockwise [deg], float32 (n,)."""
    ranges_cm: np.ndarray
    """Ranges [cm], float32 (n,); 0 means no return."""


class LidarControl(Actor):
    """The ``mapper/lidar`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (LIDAR PWM, Int A).
        pool: the rover's buffer pool for scans.
        isr: the LIDAR UART ISR (its counters survive restarts); made here when None.
        max_pending: samples held at most before a batch is sent regardless.
    """

    def __init__(self, hardware: RoverHardware, pool: BufferPool, *,
                 isr: LidarUartIsr | None = None, max_pending: int = 4096) -> None:
        self.hw = hardware
        self.pool = pool
        self._isr = isr
        self.max_pending = max_pending
        self._xy = (0.0, 0.0)
        self._heading = 0.0
        self._angles: list[int] = []  # single samples [0.1 deg]
        self._ranges: list[int] = []  # [cm]
        self._chunks: list[LidarSamples] = []  # whole interrupts' samples (LIDAR_SAMPLES)
        self._pending = 0  # samples waiting (singles and chunks)
        self.duty = 0.0
        """The rotation PWM last commanded by this incarnation."""
        self.scans = 0
        """Batches sent to Map Management."""
        self.dropped_scans = 0
        """Batches dropped: Map Management's queue full or the pool dry."""

    async def on_start(self) -> None:
        prefix = self.ctx.name.rpartition("/")[0]
        self._map = f"{prefix}/map" if prefix else "map"
        motor = f"{prefix}/motor" if prefix else "motor"
        if self._isr is None:
            self._isr = LidarUartIsr(self._post)
        self._isr.use_pool(self.pool)  # whole interrupts by handle: one message, not ~100
        self.hw.attach(Interrupt.INT_A, self._isr)
        if self.ctx.system.whereis(motor) is not None:
            self._send(motor, Message.uint(Cmd.MOTOR_GET_POSE, 0))

    def _post(self, message: Message) -> bool:
        return self.ctx.system.send_nowait(self.ctx.name, message)

    async def on_stop(self, reason: ExitReason) -> None:
        self._flush()

    def _send(self, name: str, message: Message) -> bool:
        """``send_nowait`` to a neighbour; False when full or not registered (yet)."""
        system = self.ctx.system
        return system.whereis(name) is not None and system.send_nowait(name, message)

    async def handle(self, message: Message) -> None:
        await self.handle_burst([message])

    def discard(self, message: Message) -> None:
        """A dropped poison message gives its pool buffer back (the handler may have taken it)."""
        if message.command == Cmd.LIDAR_SAMPLES:
            with contextlib.suppress(KeyError):
                self.pool.take(int(message.value))

    async def handle_burst(self, messages: list[Message]) -> None:
        had_pending = self._pending > 0
        for m in messages:
            cmd = m.command
            if cmd == Cmd.LIDAR_SAMPLES or cmd == Cmd.LIDAR_SAMPLE:
                if had_pending:  # no pose came since the last samples: the rover stood still
                    self._flush()
                    had_pending = False
                if cmd == Cmd.LIDAR_SAMPLES:
                    chunk = self.pool.take(int(m.value))
                    self._chunks.append(chunk)
                    self._pending += len(chunk.angles)
                else:
                    a, d = m.as_pair()
                    self._angles.append(a)
                    self._ranges.append(d)
                    self._pending += 1
                if self._pending >= self.max_pending:
                    self._flush()
            elif cmd == Cmd.LIDAR_POSE_XY:
                x, y = m.as_pair()
                self._xy = (float(x), float(y))
            elif cmd == Cmd.LIDAR_POSE_HEADING:
                self._heading = float(m.value)
                self._flush()  # pending samples were taken at this pose
                had_pending = False
            elif cmd in (Cmd.LIDAR_START, Cmd.LIDAR_RATE):
                duty = float(m.value)
                if not 0.0 < duty <= 1.0:
                    raise ValueError(f"LIDAR duty must be in (0, 1], got {duty!r}")
                self.duty = duty
                self.hw.set_lidar_pwm(duty)
            elif cmd == Cmd.LIDAR_STOP:
                self.duty = 0.0
                self.hw.set_lidar_pwm(0.0)
                self._flush()
            elif cmd == Cmd.NOOP:
                pass  # a flood fault: costs a queue slot, never a restart
            else:
                raise ValueError(f"lidar got an unknown command 0x{cmd:04x}")

    def _flush(self) -> None:
        if not self._pending:
            return
        parts_a = [c.angles for c in self._chunks]
        parts_d = [c.distances for c in self._chunks]
        if self._angles:
            parts_a.append(np.asarray(self._angles, dtype=np.int32))
            parts_d.append(np.asarray(self._ranges, dtype=np.int32))
        angles = np.concatenate(parts_a).astype(np.float32) * np.float32(0.1)
        ranges = np.concatenate(parts_d).astype(np.float32)
        self._angles, self._ranges, self._chunks, self._pending = [], [], [], 0
        scan = Scan(Pose(self._xy[0], self._xy[1], self._heading), angles, ranges)
        try:
            handle = self.pool.put(scan)
        except PoolExhausted:
            self.dropped_scans += 1
            return
        if self._send(self._map, Message.handle(Cmd.MAP_SCAN, handle)):
            self.scans += 1
        else:
            self.pool.take(handle)
            self.dropped_scans += 1
