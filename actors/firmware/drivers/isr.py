"""Interrupt service routines: the firmware's side of the ISR boundary.

Each ISR is a small object whose ``__call__`` is attached to one interrupt line
of `RoverHardware` (see `devices`). The hardware calls it synchronously; it
unpacks the payload into internal `Message`s and posts them with ``post``, a
non-blocking send (``send_nowait``) that returns False when the queue is full.
An ISR never waits: a full queue or a dry buffer pool is an overflow, counted
here and in the mailbox, exactly as on a microcontroller.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from actors import BufferPool, Message
from actors.firmware.commands import Cmd
from actors.firmware.handles import post
from actors.firmware.hardware import LIDAR_PACKET_SIZE, LIDAR_SYNC, RoverHardware

__all__ = ["Post", "MotorCounterIsr", "LidarSamples", "LidarUartIsr", "WiflyUartIsr",
           "IrTimerIsr", "IrAdcIsr"]

Post = Callable[[Message], bool]
"""Non-blocking send into a mailbox; False when the message was dropped."""


class _Isr:
    """Counters shared by every ISR (a real one would keep them in a static)."""

    def __init__(self, post: Post) -> None:
        self.post = post
        """Posts one message to the actor the interrupt serves (False: the mailbox is full)."""
        self.posted = 0
        self.dropped = 0

    def send(self, message: Message) -> None:
        """Post ``message``, counting it as posted or dropped."""
        if self.post(message):
            self.posted += 1
        else:
            self.dropped += 1


class MotorCounterIsr(_Isr):
    """Int E: one tread went ``cm_per_interrupt``; forward the raw payload to Motor."""

    def __call__(self, payload: int) -> None:
        self.send(Message.int(Cmd.MOTOR_TICK, int(payload)))


@dataclass(frozen=True, slots=True, eq=False)
class LidarSamples:
    """The samples of one Int A, decoded (what ``LIDAR_SAMPLES`` points to)."""

    angles: np.ndarray
    """Angles from the rover heading [0.1 deg], int32 (n,)."""
    distances: np.ndarray
    """Distances [cm], int32 (n,); 0 = no return."""


_FRAME = np.dtype([("sync", "u1"), ("a", "<u2"), ("d", "<u2"), ("check", "u1")])


class LidarUartIsr(_Isr):
    """Int A: unpack Data Packet A frames from UART bytes into LIDAR samples.

    Bytes can arrive split anywhere; a partial frame waits in a 6-byte buffer
    for the rest. A bad checksum or a lost sync byte drops bytes until the next
    0xA5, so garbage on the line costs samples, never a crash.

    With a buffer pool (`use_pool`) the ISR works like a DMA receive: the
    interrupt's whole run of clean frames is decoded at once and posted as one
    ``LIDAR_SAMPLES`` handle (a pool that runs dry drops the run, counted in
    ``dropped`` per sample). Without one, or when the bytes are not a clean run
    of frames (garbage, a split frame), every sample is its own ``LIDAR_SAMPLE``.
    """

    def __init__(self, post: Post, pool: BufferPool | None = None) -> None:
        super().__init__(post)
        self._buf = bytearray()
        self._pool = pool
        self.bad_frames = 0

    def use_pool(self, pool: BufferPool) -> None:
        """Post whole runs of frames by handle from now on (see the class docstring)."""
        self._pool = pool

    def __call__(self, data: bytes) -> None:
        if self._pool is not None and not self._buf and self._batch(data):
            return
        buf = self._buf
        buf += data
        i, n = 0, len(buf)
        while n - i >= LIDAR_PACKET_SIZE:
            if buf[i] != LIDAR_SYNC:
                i += 1
                continue
            a0, a1, d0, d1, check = buf[i + 1 : i + LIDAR_PACKET_SIZE]
            if a0 ^ a1 ^ d0 ^ d1 != check:
                self.bad_frames += 1
                i += 1
                continue
            angle_cdeg = a0 | (a1 << 8)
            distance = d0 | (d1 << 8)
            i += LIDAR_PACKET_SIZE
            if angle_cdeg >= 36000 or distance > 32767:
                self.bad_frames += 1
                continue
            self.send(Message.pair(Cmd.LIDAR_SAMPLE, angle_cdeg // 10, distance))
        del buf[:i]
        if len(buf) > 4 * LIDAR_PACKET_SIZE:  # bound: never hoard a garbage stream
            del buf[: -LIDAR_PACKET_SIZE]


    def _batch(self, data: bytes) -> bool:
        """Decode ``data`` as one clean run of frames and post it; False when it is not."""
        n = len(data)
        if n == 0 or n % LIDAR_PACKET_SIZE:
            return False
        raw = np.frombuffer(data, dtype=np.uint8).reshape(-1, LIDAR_PACKET_SIZE)
        f = raw.reshape(-1).view(_FRAME)
        a, d = f["a"], f["d"]
        # sync bytes, checksums (a0 ^ a1 ^ d0 ^ d1 ^ check is 0) and ranges: one
        # reduction each (every world tick brings a batch)
        if not (np.logical_and.reduce(raw[:, 0] == LIDAR_SYNC)
                and not np.logical_or.reduce(np.bitwise_xor.reduce(raw[:, 1:], axis=1))
                and np.maximum.reduce(a) < 36000 and np.maximum.reduce(d) <= 32767):
            return False
        count = len(f)
        samples = LidarSamples((a // 10).astype(np.int32), d.astype(np.int32))
        if post(self._pool, self.post, Cmd.LIDAR_SAMPLES, samples):  # type: ignore[arg-type]
            self.posted += count
        else:
            self.dropped += count
        return True


class WiflyUartIsr(_Isr):
    """Int B: hand the received bytes (Data Packet B) to the WiFly queue by handle."""

    def __init__(self, post: Post, pool: BufferPool) -> None:
        super().__init__(post)
        self._pool = pool

    def __call__(self, data: bytes) -> None:
        if post(self._pool, self.post, Cmd.WIFLY_RX, bytes(data)):
            self.posted += 1
        else:
            self.dropped += 1


class IrTimerIsr:
    """Int D: the IR timer rolled over; start an ADC conversion and return."""

    def __init__(self, hardware: RoverHardware) -> None:
        self._hardware = hardware

    def __call__(self, _payload: object = None) -> None:
        self._hardware.start_adc()


class IrAdcIsr(_Isr):
    """Int C: the conversion finished; post the 12-bit sample to the IR queue."""

    def __call__(self, sample: int) -> None:
        self.send(Message.int(Cmd.IR_SAMPLE, max(0, min(4095, int(sample)))))
