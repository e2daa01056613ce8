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

Health (why: a faulty LIDAR leaves a wrong map, docs/faults.md)
    Every batch is judged before it is sent (`batch_health`): a batch collected
    while the ISR rejected many frames (garbled line), one whose samples all lie
    at one angle (stuck rotor), or one far rougher than the calibrated noise
    (noisy) is dropped, never integrated. ``FAULT_BATCHES`` bad batches in a row
    make the sensor faulty: every batch is dropped until ``RECOVER_BATCHES``
    good ones in a row, and navigation is told each change of verdict with
    ``NAV_LIDAR_HEALTH`` (a `LidarHealth`), so it can stop driving meanwhile. A
    dead LIDAR sends nothing to judge: navigation sees its scan count stop.

Restart: the state is the PWM duty and the latest pose. The duty is kept by
the hardware; the pose is asked again from Motor Control (``MOTOR_GET_POSE``).
"""

from __future__ import annotations

import contextlib
import enum
from dataclasses import dataclass

import numpy as np

from actors import Actor, BufferPool, ExitReason, Message
from actors.firmware.addresses import Addresses
from actors.firmware.arrays import wrap_angle
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import LidarSamples, LidarUartIsr
from actors.firmware.handles import post
from actors.firmware.hardware import LIDAR_SAMPLES_PER_REV, Interrupt, RoverHardware
from actors.firmware.origin_wire import CM, PoseHalves
from server.protocol.pose import Pose

__all__ = ["Scan", "LidarHealth", "HealthOptions", "roughness_cm", "batch_health",
           "LidarControl", "MIN_SAMPLES", "STUCK_SPAN_DEG", "MIN_TRIPLES", "GARBLED_SHARE",
           "GARBLED_MIN", "FAULT_BATCHES", "RECOVER_BATCHES"]


@dataclass(frozen=True, slots=True, eq=False)
class Scan:
    """One batch of LIDAR returns taken at ``pose`` (what ``MAP_SCAN`` points to).

    A batch is one world tick's samples, in the rotor's sweep order, stamped with the
    odometry pose Motor Control published for that tick (pose association, in the
    module docstring). Consecutive batches' stamps are in one odometry frame, so the
    odometry counted between two stamps (``relative(stamp_a, stamp_b)``) brings one
    batch into another's frame: Map Management de-skews windows of about a revolution
    of batches that way (`mapping.scan_window`), each batch keeping its own stamp.
    """

    pose: Pose
    """Rover pose in its own (odometry) frame when the batch was taken: its stamp."""
    angles_deg: np.ndarray
    """Ray angles from the rover heading, counter-clockwise [deg], float32 (n,), in the
    rotor's sweep order."""
    ranges_cm: np.ndarray
    """Ranges [cm], float32 (n,); 0 means no return."""

    @property
    def sweep_deg(self) -> float:
        """The rotor's sweep the batch covers [deg]: from its first sample to its last,
        plus one mean step between samples (each sample stands for one step of the
        sweep), so n samples 1 deg apart sweep n deg. At the mapping duty a batch is
        about a hundred samples; a batch of a whole revolution sweeps 360 deg."""
        a = self.angles_deg
        n = a.size
        if n < 2:
            return 0.0
        return float((a[-1] - a[0]) % 360.0) * n / (n - 1)


class LidarHealth(enum.IntEnum):
    """What LIDAR Control makes of its sensor (the value of ``NAV_LIDAR_HEALTH``)."""

    OK = 0
    """Samples sweep the circle with the calibrated noise: scans are sent."""
    SILENT = 1
    """No scans while spinning (dead, or only garbage on the line): navigation's verdict,
    from the scan count not rising; LIDAR Control itself gets no message to judge."""
    GARBLED = 2
    """The UART carries mostly undecodable bytes (the ISR's bad frames outnumber samples)."""
    STUCK = 3
    """Every sample at one angle: the rotor does not turn."""
    NOISY = 4
    """Ranges rougher than any surface gives with the calibrated noise."""


@dataclass(frozen=True, slots=True)
class HealthOptions:
    """The noise limit of the batch checks (see `batch_health`).

    The calibrated sensor: 360 samples per revolution (1 deg apart), 0.5 cm range noise on
    a 2 cm quantum. Measured over whole games in every built-in room (docs/mapping.md):
    healthy batches have a median roughness (`roughness_cm`) of 0-4 cm; 5 cm of added
    noise gives about 8, 10 cm about 16. The counts and shares of the checks and of the
    fault state are module constants (`MIN_SAMPLES` ... `RECOVER_BATCHES`).
    """

    noise_limit_cm: float = 5.0
    """A median roughness (`roughness_cm`) above this is noise, not surfaces [cm]."""


_DEFAULT_HEALTH = HealthOptions()

# Counts and spans of the batch checks and of the fault state: fixed by the calibrated
# sensor (360 samples a revolution, 1 deg apart) and by how many batches tell a fault
# from a stray one; none is a property a rover team sets.
MIN_SAMPLES = 8
"""Batches with fewer samples are not judged for rotor or noise (too little to tell)."""
STUCK_SPAN_DEG = 360.0 / LIDAR_SAMPLES_PER_REV
"""A batch whose angles all lie within this (one sample step: a revolution over
`hardware.LIDAR_SAMPLES_PER_REV`) is from a rotor that does not turn [deg]."""
MIN_TRIPLES = 12
"""Roughness needs at least this many triples of neighbouring returns."""
GARBLED_SHARE = 0.25
"""A batch during which the ISR dropped more bad frames than this share of its samples
(and at least ``GARBLED_MIN``) came over a garbled line."""
GARBLED_MIN = 1
"""Fewest bad frames that can make a batch garbled (a healthy line has none)."""
FAULT_BATCHES = 2
"""Bad batches in a row that make the sensor faulty (one alone is only dropped)."""
RECOVER_BATCHES = 20
"""Good batches in a row that make a faulty sensor healthy again (about 1 s)."""


def roughness_cm(angles_deg: np.ndarray, ranges_cm: np.ndarray, *,
                 max_step_deg: float = 1.5) -> tuple[float, int]:
    """The median second difference of range along the sweep [cm]: how rough the scan is.

    Why this measure: neighbouring returns 1 deg apart on a surface have ranges that
    change smoothly, so ``|r[i-1] - 2 r[i] + r[i+1]|`` is the 2 cm quantum or less
    (measured in every built-in room: medians of 0-4 cm per batch, also along a hall's
    grazing walls), while range noise of sigma adds about ``0.67 * 2.45 * sigma`` to it;
    a corner or an edge bends only a few triples, which the median ignores.

    Args:
        angles_deg: ray angles in sample order [deg] (the rotor's sweep order).
        ranges_cm: ranges [cm], 0 = no return.
        max_step_deg: neighbours further apart in angle are not a triple [deg].

    Returns:
        (median [cm], triples used); (0.0, 0) when there is no triple.
    """
    a = np.asarray(angles_deg, dtype=np.float64)
    r = np.asarray(ranges_cm, dtype=np.float64)
    if a.size < 3:
        return 0.0, 0
    # per batch (a hundred values, so the count of numpy calls is the cost): slices and
    # ufuncs, not np.diff's wrapper; the neighbours' conditions are and-ed per pair
    # first (``pair[i]``: step i usable, returns i and i + 1 valid, i.e. the smaller > 0)
    step = np.abs(wrap_angle(a[1:] - a[:-1], 360.0))
    pair = (step > 0.0) & (step <= max_step_deg)
    pair &= np.minimum(r[:-1], r[1:]) > 0.0
    use = pair[:-1] & pair[1:]
    n = int(np.count_nonzero(use))
    if n == 0:
        return 0.0, 0
    # the second difference as the difference of the first ones (the same value on the
    # sensor's whole centimetres; one numpy call fewer than r[i-1] - 2 r[i] + r[i+1])
    dr = r[1:] - r[:-1]
    d2 = np.abs(dr[1:] - dr[:-1]).compress(use)
    d2.sort()
    # np.median's value (the middle one, or the mean of the middle two) at a tenth of
    # its cost on a hundred values (it is per batch)
    k = n // 2
    return (float(d2[k]) if n % 2 else float((d2[k - 1] + d2[k]) / 2.0)), n


def _may_be_stuck(a: np.ndarray) -> bool:
    """False when the angles ``a`` [deg] surely do not all lie within `STUCK_SPAN_DEG` of the
    first one (around the circle): the usual sweep, told by its extent alone (two
    reductions, where the circular spread of every sample costs five calls).

    Angles in [0, 360) that all lie within ``s`` of one of them span at most ``2 s`` or,
    across 0 deg, at least ``360 - 2 s``; a span between (with half a degree to spare)
    rules the rotor stuck out.
    """
    lo, hi = float(np.minimum.reduce(a)), float(np.maximum.reduce(a))
    margin = 2.0 * STUCK_SPAN_DEG + 0.5
    return not (lo >= 0.0 and hi < 360.0 and margin < hi - lo < 360.0 - margin)


def batch_health(angles_deg: np.ndarray, ranges_cm: np.ndarray, bad_frames: int,
                 options: HealthOptions = _DEFAULT_HEALTH) -> LidarHealth:
    """The verdict on one batch: OK, or the fault it shows (never SILENT).

    Args:
        angles_deg: ray angles in sample order [deg].
        ranges_cm: ranges [cm], 0 = no return.
        bad_frames: frames the UART ISR rejected while the batch was collected.
        options: the noise limit.
    """
    o = options
    n = int(np.asarray(angles_deg).size)
    if bad_frames >= max(GARBLED_MIN, GARBLED_SHARE * n):
        return LidarHealth.GARBLED
    if n < MIN_SAMPLES:
        return LidarHealth.OK
    a = np.asarray(angles_deg, dtype=np.float64)
    if _may_be_stuck(a):
        spread = np.abs(wrap_angle(a - a[0], 360.0))
        if float(np.maximum.reduce(spread)) <= STUCK_SPAN_DEG:
            return LidarHealth.STUCK
    rough, triples = roughness_cm(a, ranges_cm)
    if triples >= MIN_TRIPLES and rough > o.noise_limit_cm:
        return LidarHealth.NOISY
    return LidarHealth.OK


class LidarControl(Actor):
    """The ``mapper/lidar`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (LIDAR PWM, Int A).
        pool: the rover's buffer pool for scans.
        isr: the LIDAR UART ISR (its counters survive restarts); made here when None.
        max_pending: samples held at most before a batch is sent regardless.
    """

    def __init__(self, hardware: RoverHardware, pool: BufferPool, *,
                 isr: LidarUartIsr | None = None, max_pending: int = 4096,
                 health: HealthOptions = _DEFAULT_HEALTH,
                 addresses: Addresses | None = None) -> None:
        self.hw = hardware
        self._addresses = addresses
        self.pool = pool
        self._isr = isr
        self.max_pending = max_pending
        self._pose = Pose()  # the odometry pose pending samples are stamped with
        self._pose_halves = PoseHalves(CM)  # LIDAR_POSE_XY waiting for its heading
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
        self.health_options = health
        self.health = LidarHealth.OK
        """The verdict on the sensor (see the module docstring)."""
        self.withheld = 0
        """Batches not sent because they or the sensor were judged faulty."""
        self._told = LidarHealth.OK  # the verdict navigation has
        self._bad = 0  # bad batches in a row
        self._good = 0  # good batches in a row
        self._bad_frames_seen = 0  # the ISR's bad frame count at the last flush

    async def on_start(self) -> None:
        names = self._addresses or Addresses.beside(self.ctx.name)
        self._map = names.map
        motor = names.motor
        if self._isr is None:
            self._isr = LidarUartIsr(self._post)
        self._isr.use_pool(self.pool)  # whole interrupts by handle: one message, not ~100
        self._bad_frames_seen = self._isr.bad_frames
        self._nav = names.nav
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
                self._pose_halves.take_xy(m)
            elif cmd == Cmd.LIDAR_POSE_HEADING:
                self._pose = self._pose_halves.take_heading(m, self._pose) or self._pose
                self._flush()  # pending samples were taken at this pose
                had_pending = False
            elif cmd in (Cmd.LIDAR_START, Cmd.LIDAR_RATE):
                duty = float(m.value)
                if not 0.0 < duty <= 1.0:
                    raise ValueError(f"LIDAR duty must be in (0, 1], got {duty!r}")
                if cmd == Cmd.LIDAR_START:
                    self._set_health(LidarHealth.OK)  # judged afresh from the new sweep
                    self._bad = self._good = 0
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
        if len(self._chunks) == 1 and not self._angles:  # one interrupt's run: no joining
            angles = self._chunks[0].angles.astype(np.float32)
            ranges = self._chunks[0].distances.astype(np.float32)
        else:
            parts_a = [c.angles for c in self._chunks]
            parts_d = [c.distances for c in self._chunks]
            if self._angles:
                parts_a.append(np.asarray(self._angles, dtype=np.int32))
                parts_d.append(np.asarray(self._ranges, dtype=np.int32))
            angles = np.concatenate(parts_a).astype(np.float32)
            ranges = np.concatenate(parts_d).astype(np.float32)
        angles *= np.float32(0.1)  # [0.1 deg] -> [deg]
        self._angles, self._ranges, self._chunks, self._pending = [], [], [], 0
        if not self._healthy(angles, ranges):
            self.withheld += 1
            return
        scan = Scan(self._pose, angles, ranges)
        if post(self.pool, lambda m: self._send(self._map, m), Cmd.MAP_SCAN, scan):
            self.scans += 1
        else:
            self.dropped_scans += 1

    def _healthy(self, angles: np.ndarray, ranges: np.ndarray) -> bool:
        """Judge a batch, update the verdict on the sensor; True when the batch may be sent."""
        o = self.health_options
        bad_frames = 0
        if self._isr is not None:
            bad_frames = self._isr.bad_frames - self._bad_frames_seen
            self._bad_frames_seen = self._isr.bad_frames
        verdict = batch_health(angles, ranges, bad_frames, o)
        if verdict == LidarHealth.OK and angles.size < MIN_SAMPLES:
            # too few to judge (a stray frame among garbage?): not evidence of recovery
            return self.health == LidarHealth.OK
        if verdict == LidarHealth.OK:
            self._good += 1
            self._bad = 0
            if self.health != LidarHealth.OK and self._good >= RECOVER_BATCHES:
                self._set_health(LidarHealth.OK)
        else:
            self._bad += 1
            self._good = 0
            if self._bad >= FAULT_BATCHES:
                self._set_health(verdict)
        if self._told != self.health:  # navigation's queue was full: tell it again
            self._tell()
        return verdict == LidarHealth.OK and self.health == LidarHealth.OK

    def _set_health(self, health: LidarHealth) -> None:
        if health != self.health:
            self.health = health
            self._tell()

    def _tell(self) -> None:
        if self._send(self._nav, Message.int(Cmd.NAV_LIDAR_HEALTH, int(self.health))):
            self._told = self.health
