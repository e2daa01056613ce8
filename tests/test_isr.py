"""The five ISRs: payloads decoded into Messages, overflows counted, never blocking."""

from __future__ import annotations

from actors import BufferPool, Message
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import (
    IrAdcIsr,
    IrTimerIsr,
    LidarUartIsr,
    MotorCounterIsr,
    WiflyUartIsr,
)
from actors.firmware.hardware import encode_counter


def packet(angle_cdeg: int, dist: int) -> bytes:
    a0, a1, d0, d1 = angle_cdeg & 255, angle_cdeg >> 8, dist & 255, dist >> 8
    return bytes([0xA5, a0, a1, d0, d1, a0 ^ a1 ^ d0 ^ d1])


class Sink:
    def __init__(self, room: int = 1000) -> None:
        self.got: list[Message] = []
        self.room = room

    def __call__(self, m: Message) -> bool:
        if len(self.got) >= self.room:
            return False
        self.got.append(m)
        return True


def test_lidar_isr_reassembles_split_frames_and_skips_garbage() -> None:
    """Frames split anywhere and garbage between them give exactly the good samples."""
    sink = Sink()
    isr = LidarUartIsr(sink)
    data = b"\x00\x13" + packet(9000, 150) + b"\xa5\x01\x02\x03\x04\x00" + packet(35990, 4000)
    for i in range(0, len(data), 4):
        isr(data[i:i + 4])
    assert [m.as_pair() for m in sink.got] == [(900, 150), (3599, 4000)]
    assert isr.bad_frames >= 1 and isr.posted == 2


def test_lidar_isr_counts_a_full_queue() -> None:
    """When the queue refuses, samples are dropped and counted."""
    sink = Sink(room=1)
    isr = LidarUartIsr(sink)
    isr(packet(0, 10) + packet(10, 20))
    assert (isr.posted, isr.dropped) == (1, 1)


def test_motor_counter_isr_posts_the_raw_payload() -> None:
    sink = Sink()
    MotorCounterIsr(sink)(encode_counter(1, False))
    assert sink.got == [Message.int(Cmd.MOTOR_TICK, encode_counter(1, False))]


def test_wifly_isr_frees_the_buffer_when_the_queue_is_full() -> None:
    """A refused post releases the pool slot; a dry pool counts a drop."""
    pool = BufferPool(2)
    sink = Sink(room=1)
    isr = WiflyUartIsr(sink, pool)
    isr(b"one")
    isr(b"two")  # queue full: freed again
    assert pool.statistics().in_use == 1 and isr.dropped == 1
    assert pool.take(int(sink.got[0].value)) == b"one"
    pool.put(b"x")
    pool.put(b"y")
    isr(b"three")  # pool dry
    assert isr.dropped == 2


def test_ir_timer_starts_the_adc_and_adc_isr_clamps() -> None:
    class HW:
        adc = 0

        def start_adc(self) -> None:
            self.adc += 1
    hw = HW()
    IrTimerIsr(hw)(None)
    assert hw.adc == 1
    sink = Sink()
    adc = IrAdcIsr(sink)
    adc(5000)
    adc(-3)
    assert [m.value for m in sink.got] == [4095, 0]


def test_lidar_isr_with_a_pool_posts_a_clean_run_as_one_handle() -> None:
    """DMA-style: a whole interrupt of clean frames is one LIDAR_SAMPLES handle."""
    import numpy as np

    from actors.firmware.drivers.isr import LidarSamples

    pool = BufferPool(4)
    sink = Sink()
    isr = LidarUartIsr(sink, pool)
    isr(packet(9000, 150) + packet(9100, 0) + packet(35990, 4000))
    (m,) = sink.got
    assert m.command == Cmd.LIDAR_SAMPLES
    batch = pool.take(int(m.value))
    assert isinstance(batch, LidarSamples)
    assert np.array_equal(batch.angles, [900, 910, 3599])
    assert np.array_equal(batch.distances, [150, 0, 4000])
    assert isr.posted == 3 and isr.dropped == 0


def test_lidar_isr_with_a_pool_falls_back_to_single_samples_on_garbage() -> None:
    """Garbage or a split frame: the byte-by-byte path, one LIDAR_SAMPLE per good frame."""
    pool = BufferPool(4)
    sink = Sink()
    isr = LidarUartIsr(sink, pool)
    isr(b"\x00" + packet(100, 20) + packet(200, 30)[:5])  # garbage byte, then a split frame
    isr(packet(200, 30)[5:])
    assert [m.command for m in sink.got] == [Cmd.LIDAR_SAMPLE, Cmd.LIDAR_SAMPLE]
    assert [m.as_pair() for m in sink.got] == [(10, 20), (20, 30)]
    assert pool.statistics().in_use == 0


def test_lidar_isr_batch_drops_are_counted_and_free_the_slot() -> None:
    """A refused post frees the pool slot; a dry pool drops the run; both count samples."""
    pool = BufferPool(1)
    sink = Sink(room=0)
    isr = LidarUartIsr(sink, pool)
    isr(packet(0, 10) + packet(10, 20))
    assert isr.dropped == 2 and pool.statistics().in_use == 0
    pool.put("busy")
    isr(packet(0, 10))
    assert isr.dropped == 3
