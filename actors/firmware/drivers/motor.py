"""Motor Control: Command A with closed-loop PWM on both treads.

The seed's Motor Control thread. Navigation sends Command A (``MOTOR_MOVE``
[cm], ``MOTOR_TURN`` [deg], ``MOTOR_STOP``); the motor counter ISR (Int E)
posts ``MOTOR_TICK`` each time a tread went `HardwareSpec.cm_per_interrupt`;
a self-timer posts ``MOTOR_CONTROL`` every control period while there is
something to control (a command, an undelivered outcome, a pose to publish).

Control law (per control period, per tread)
    Each command sets a target travel per tread (move: both ``d``; turn:
    ``-+ theta * track / 2``). The commanded tread speed follows a braking
    profile ``min(cruise, sqrt(2 * decel * remaining), gain * remaining)``
    with a floor so the rover never creeps to a halt short of the target, and a
    cross-coupling term keeps the two treads' progress equal in magnitude (a
    straight move stays straight, a turn stays in place). A tread within
    ``tolerance`` of its target stops; when both are there (or a tread
    overshot and was pulled back) the command is done. The world's motors lag
    (first order, ~80 ms), which is why braking starts early.

Blocked
    A command whose treads do not count ends with ``NAV_MOTION_BLOCKED``: after
    ``blocked_after_s`` without an Int E, or sooner, once the lagged model of
    the treads (`tread_monitor.TreadMonitor.both_silent`) says one went
    ``blocked_cm`` since either tread's last Int E. Both encoders stuck look
    exactly like a rover against a wall, and nothing counts to compare with;
    the model bounds what the rover drives unseen to about 3 cm instead of a
    second's travel. A turn ended so without a single Int E is also reported
    as ``NAV_TREAD_FAULT`` `TreadFault.BOTH_SILENT` just before: a rover
    pressed against a wall still turns a little before it jams, while backing
    off and turning again on two stuck encoders drives the rover on unseen;
    navigation holds instead for a tread fault during a turn.

Driven travel (``NAV_TREAD_DRIVEN``)
    After a command with a tread report, or a turn that ended blocked, Motor
    Control tells navigation how far its model says each tread went (to rest,
    the coast behind the lag included), just before the command's end: the
    counts of such a command are not its travel, and the treads went on past
    the command (the model gives a silent tread up only after ``blocked_cm``).

Dead reckoning
    This actor owns the pose: every tread increment goes through an
    `odometry.Odometer` (one `odometry.advance` step per burst of Int E, with
    the track width from the hardware spec). The pose, in the rover's own
    (odometry) frame, is published to navigation (``NAV_POSE_XY`` [mm] +
    ``NAV_POSE_HEADING`` [deg]) when it changed, at most once per control period;
    to the LIDAR on the mapper (``LIDAR_POSE_XY`` [cm] + ``LIDAR_POSE_HEADING``)
    once per change, as soon as the Int E that changed it are counted; to both at
    once on ``MOTOR_GET_POSE``. Motor Control knows nothing of the map frame:
    each navigation keeps its own map -> odometry transform (its ``origin``:
    from the server, from its pose belief, or on the mapper from Map
    Management's scan matching).

Tread faults (``NAV_TREAD_FAULT``)
    A `tread_monitor.TreadMonitor` models how far each driven tread should
    have gone and finds a tread that is driven but does not count, or counts
    short, or both counting short (see that module). Motor Control sends each
    finding as a `tread_monitor.TreadFault`; the command goes on (navigation
    decides: the mapper stops and holds). The pose stays what the counts say:
    whether a short tread slipped (the model is right) or was held back (the
    counts are right) is the pose belief's question, whose motion model samples
    between the two (`localisation.motion_model`). Both short in a move while
    lately counting hardly at all is a push: the move ends blocked.

Restarts
    The pose lives in a `PoseMemory` made by the rover tree: the model of a
    retained RAM section that survives a thread restart but not a rover reset
    (C firmware keeps statics across a task restart). Only this actor writes
    it. Encoder ticks waiting in the mailbox survive the restart too, so a
    restarted motor has lost at most the one message that was being handled
    when it crashed (reported as poison). A command that was running is not
    resumed: the treads are stopped and navigation gets ``NAV_MOTION_BLOCKED``
    with the distance done so far, so its ADP loop decides again from the
    published pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import trio

from actors import Actor, ExitReason, Message, Timer
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import MotorCounterIsr
from actors.firmware.drivers.tread_monitor import TreadFault, TreadMonitor, TreadVerdict
from actors.firmware.hardware import Interrupt, RoverHardware, decode_counter
from actors.firmware.localisation.odometry import Odometer
from actors.firmware.origin_wire import CM, MM, length_pair, pose_messages
from server.protocol.pose import Pose

__all__ = ["MotorTuning", "PoseMemory", "MotorControl"]

_CONTROL = Message.uint(Cmd.MOTOR_CONTROL, 0)  # the control period's tick
# the two commands of nearly every burst, as plain ints: an IntEnum member's lookup costs
# twice a module constant's, on each of a game's tens of thousands of messages
_TICK_CMD = int(Cmd.MOTOR_TICK)
_CONTROL_CMD = int(Cmd.MOTOR_CONTROL)


@dataclass(frozen=True, slots=True)
class MotorTuning:
    """Physical quantities of the control loop and of its blocked and silent-tread checks,
    tuned against the simulated world (tests/test_fw_motor.py).

    A tread counts as at its target within half an encoder interrupt
    (``HardwareSpec.cm_per_interrupt / 2``), so the counted travel stops at the
    interrupt nearest the target. The tread monitor's detection thresholds are
    constants of `tread_monitor`.
    """

    period_s: float = 0.05
    """Control period [s] (the world's tick)."""
    cruise_fraction: float = 0.8
    """Cruise speed as a fraction of the spec's full-PWM speed [1] (24 cm/s at 30 cm/s)."""
    decel_cm_s2: float = 40.0
    """Braking deceleration of the speed profile [cm/s^2]."""
    gain_per_s: float = 4.0
    """Proportional limit near the target: speed <= gain * remaining [1/s]."""
    min_speed_cm_s: float = 3.0
    """Speed floor while a tread is outside the tolerance [cm/s]."""
    coupling_per_s: float = 2.0
    """Cross-coupling gain on the difference of the treads' progress [1/s]."""
    blocked_after_s: float = 1.0
    """Treads commanded but no encoder progress for this long: blocked [s]."""
    blocked_cm: float = 3.0
    """...or no Int E from either tread while the model says a tread went this far [cm]:
    blocked sooner (a weak motor at strength 0.3 still counts every 1.7 cm modelled)."""
    settle_s: float = 0.15
    """After both treads arrive, wait this long for coasting ticks before reporting [s]."""
    motor_tau_s: float = 0.08
    """The treads' first-order lag behind their PWM, as modelled for the silent-tread check [s]."""


class PoseMemory:
    """Retained memory of the motor: the dead-reckoned pose and the running command.

    Made once per rover by the tree builder and handed to every incarnation of
    `MotorControl`; it models a retained RAM section, not shared state (no
    other actor reads it).
    """

    __slots__ = ("pose", "active")

    def __init__(self, pose: Pose | None = None) -> None:
        self.pose: Pose = pose or Pose()
        """The dead-reckoned pose in the rover's own (odometry) frame."""
        self.active: bool = False
        """True while a Command A was running (a restart reports it blocked)."""

    def __repr__(self) -> str:
        p = self.pose
        return f"<PoseMemory ({p.x:.1f}, {p.y:.1f}) @ {p.heading_deg:.1f} active={self.active}>"


class MotorControl(Actor):
    """The ``<rover>/motor`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (tread PWM, Int E).
        memory: retained pose memory (survives restarts).
        isr: the motor counter ISR object (its counters survive restarts);
            made here when None.
        lidar: also publish the pose to the rover's LIDAR actor (mapper).
        tuning: control constants.
        addresses: the rover's actor names (default: those beside this actor's own).
    """

    def __init__(self, hardware: RoverHardware, memory: PoseMemory, *,
                 isr: MotorCounterIsr | None = None, lidar: bool = False,
                 tuning: MotorTuning | None = None, addresses: Addresses | None = None) -> None:
        self.hw = hardware
        self._addresses = addresses
        self.memory = memory
        self.tuning = tuning or MotorTuning()
        self._isr = isr
        self._lidar = lidar
        spec = hardware.spec
        self._unit = float(spec.cm_per_interrupt)
        self._track = float(spec.track_width_cm)
        self._vmax = float(spec.max_speed_cm_s)
        self._tolerance = 0.5 * self._unit  # a tread this close to its target is there [cm]
        # the running command (None when idle)
        self._kind: int | None = None       # Cmd.MOTOR_MOVE or Cmd.MOTOR_TURN
        self._target = (0.0, 0.0)           # per tread [cm], signed
        self._progress = [0.0, 0.0]         # per tread since the command began [cm]
        self._last_progress_t = 0.0         # last time a tick arrived during a command [s]
        self._arrived_t: float | None = None  # when both treads reached the target [s]
        self._started_t = 0.0
        self._deadline = math.inf           # give up (blocked) after this [s]
        self._pose_dirty = True
        self._lidar_dirty = True  # the LIDAR gets the pose at start, with navigation
        self._outcome: Message | None = None  # a DONE/BLOCKED report navigation refused
        self._odometer = Odometer(self._unit, self._track)
        self._monitor = TreadMonitor(self.tuning, self._unit, self._vmax, mapper=lidar)
        self._ticked = False            # an Int E was in the burst being handled
        self._signs = (1.0, 1.0)           # direction each tread is driven in
        self._reported = False              # a NAV_TREAD_FAULT was sent in this command
        self.tread_faults = 0
        """NAV_TREAD_FAULT reports sent (this incarnation)."""
        self._period: Timer | Any = None  # the control period's timer while it runs, else None
        self.commands = 0
        """Command A received (this incarnation)."""

    # ------------------------------------------------------------------ lifetime
    async def on_start(self) -> None:
        ctx = self.ctx
        names = self._addresses or Addresses.beside(ctx.name)
        self._nav = names.nav
        self._lidar_name = names.lidar if self._lidar else None
        if self._isr is None:
            self._isr = MotorCounterIsr(self._post)
        self.hw.attach(Interrupt.INT_E, self._isr)
        self.hw.set_tread_pwm(0.0, 0.0)
        if self.memory.active:  # a command was cut short by a crash or hang
            self.memory.active = False
            self._send(self._nav, Message.float(Cmd.NAV_MOTION_BLOCKED, 0.0))
        self._publish()
        self._pace()

    def _post(self, message: Message) -> bool:
        return self.ctx.system.send_nowait(self.ctx.name, message)

    async def on_stop(self, reason: ExitReason) -> None:
        self.hw.set_tread_pwm(0.0, 0.0)  # never leave the treads running unsupervised

    # ------------------------------------------------------------------ messages
    def _send(self, name: str, message: Message) -> bool:
        """``send_nowait`` to a neighbour; False when full or not registered (yet)."""
        system = self.ctx.system
        return system.whereis(name) is not None and system.send_nowait(name, message)

    async def handle(self, message: Message) -> None:
        self._dispatch(message)

    def _dispatch(self, message: Message) -> None:
        """One message's work (none of it waits: `handle_burst` calls it directly, without
        a coroutine per message)."""
        cmd = message.command
        if cmd == _TICK_CMD:
            self._tick(int(message.value))
        elif cmd == _CONTROL_CMD:
            self._control()
        elif cmd == Cmd.MOTOR_MOVE:
            self._begin(Cmd.MOTOR_MOVE, float(message.value))
        elif cmd == Cmd.MOTOR_TURN:
            self._begin(Cmd.MOTOR_TURN, float(message.value))
        elif cmd == Cmd.MOTOR_STOP:
            if self._kind is not None:
                self._finish(Cmd.NAV_MOTION_DONE)
            self._set_pwm(0.0, 0.0)
        elif cmd == Cmd.MOTOR_GET_POSE:  # asked (a restarted neighbour): to both again
            self._lidar_dirty = True
            self._publish()
        elif cmd == Cmd.NOOP:
            pass  # a flood fault: costs a queue slot, never a restart
        else:
            raise ValueError(f"motor got an unknown command 0x{cmd:04x}")

    # ------------------------------------------------------------------ dead reckoning
    def _tick(self, payload: int) -> None:
        tread, forward = decode_counter(payload)
        d = self._odometer.count(tread, forward)
        self._ticked = True
        now = self._now()
        self._monitor.tick(tread, now)
        if self._kind is not None:
            self._progress[tread] += d
            self._last_progress_t = now

    def _integrate(self) -> None:
        pose = self._odometer.integrate(self.memory.pose)
        if pose is not None:
            self.memory.pose = pose
            self._pose_dirty = self._lidar_dirty = True

    async def handle_burst(self, messages: list[Message]) -> None:
        self._ticked = False
        for message in messages:
            self._dispatch(message)
        if self._ticked and self._kind is not None:  # this step's Int E are all in
            self._watch_treads(period_pending=False)
        self._integrate()
        if self._lidar_dirty:
            self._publish_lidar()
        self._pace()

    def _pace(self) -> None:
        """Run the control period only while there is something to do: a command, an
        outcome to deliver, or a pose to publish.

        Why: an idle rover's motor ticking every period (the hider and the seeker
        through all of mapping) made a fifth of a whole game's actor wake-ups. A
        tick that arrives while idle (coasting, or pushed) starts the period again,
        so the new pose is published one period later, as before.
        """
        busy = self._kind is not None or self._outcome is not None or self._pose_dirty
        if busy and self._period is None:
            period = self.tuning.period_s
            self._period = self.ctx.start_timer(period, _CONTROL, interval=period)
        elif not busy and self._period is not None:
            self._period.cancel()
            self._period = None

    def _publish(self) -> None:
        self._integrate()
        p = self.memory.pose
        send = self._send  # pose is superseded by the next one: drop when full
        xy, heading = pose_messages(Cmd.NAV_POSE_XY, Cmd.NAV_POSE_HEADING, p, MM)
        send(self._nav, xy)
        send(self._nav, heading)
        self._pose_dirty = False
        if self._lidar_dirty:
            self._publish_lidar()

    def _publish_lidar(self) -> None:
        # The LIDAR gets every new pose at once (not once per control period), and once:
        # it stamps the samples of the same world tick with it (see lidar.py), and a pose
        # it already has stamps nothing differently (its own restart asks MOTOR_GET_POSE).
        if self._lidar_name is None:
            return
        xy, heading = pose_messages(Cmd.LIDAR_POSE_XY, Cmd.LIDAR_POSE_HEADING,
                                    self.memory.pose, CM)
        self._send(self._lidar_name, xy)
        self._send(self._lidar_name, heading)
        self._lidar_dirty = False

    # ------------------------------------------------------------------ Command A
    def _begin(self, kind: int, amount: float) -> None:
        if not math.isfinite(amount):
            raise ValueError(f"Command A amount must be finite, got {amount!r}")
        self.commands += 1
        forward = 1.0 if amount >= 0 else -1.0
        if kind == Cmd.MOTOR_MOVE:
            self._target = (amount, amount)
            self._signs = (forward, forward)
            length = abs(amount)
        else:
            self._signs = (-forward, forward)
            # quantise the turn to whole encoder interrupts on the *sum* of both treads
            # (one tread may go one interrupt further), halving the heading quantum
            n = round(math.radians(amount) * self._track / self._unit)
            half = int(math.copysign(abs(n) // 2, n))
            self._target = (-half * self._unit, (n - half) * self._unit)
            length = abs(n) * self._unit / 2
        now = self._now()
        self._kind = kind
        self._reported = False
        self._progress = [0.0, 0.0]
        self._monitor.begin(now)
        self._started_t = self._last_progress_t = now
        self._arrived_t = None
        cruise = self._vmax * self.tuning.cruise_fraction
        self._deadline = now + 3.0 * length / max(cruise, 1e-6) + 3.0
        self.memory.active = True
        if length <= self._tolerance:
            self._finish(Cmd.NAV_MOTION_DONE)
            return
        self._control()

    def _control(self) -> None:
        self._integrate()
        now = self._now()
        if self._outcome is not None and self._send(self._nav, self._outcome):
            self._outcome = None
        if self._kind is not None:
            self._drive(now)
        if self._pose_dirty:
            self._publish()

    def _drive(self, now: float) -> None:
        t = self.tuning
        self._monitor.advance(now)
        self._watch_treads(period_pending=True)
        pl, pr = self._progress
        tl, tr = self._target
        rl, rr = tl - pl, tr - pr
        tol = self._tolerance
        if abs(rl) <= tol and abs(rr) <= tol:
            self._set_pwm(0.0, 0.0)
            if self._arrived_t is None:
                self._arrived_t = now
            elif now - self._arrived_t >= t.settle_s:
                self._finish(Cmd.NAV_MOTION_DONE)
            return
        self._arrived_t = None
        if self._monitor.both_silent():
            if self._kind == Cmd.MOTOR_TURN and not any(self._monitor.counted):
                # a turn that never counted: both encoders stuck, most likely (see above)
                self._report(TreadFault.BOTH_SILENT)
            self._finish(Cmd.NAV_MOTION_BLOCKED)
            return
        if now >= self._deadline or now - self._last_progress_t >= t.blocked_after_s:
            self._finish(Cmd.NAV_MOTION_BLOCKED)
            return
        cruise = self._vmax * t.cruise_fraction
        vl = self._speed(rl, cruise)
        vr = self._speed(rr, cruise)
        # cross-coupling: equal progress magnitude (move: pl == pr; turn: pl == -pr)
        skew = (pl - pr) if self._kind == Cmd.MOTOR_MOVE else (pl + pr)
        corr = t.coupling_per_s * skew
        if self._kind == Cmd.MOTOR_MOVE:
            vl, vr = vl - corr, vr + corr
        else:
            vl, vr = vl - corr, vr - corr
        self._set_pwm(self._duty(vl), self._duty(vr))

    def _set_pwm(self, left: float, right: float) -> None:
        self._monitor.pwm = (left, right)
        self.hw.set_tread_pwm(left, right)

    def _watch_treads(self, period_pending: bool) -> None:
        """Act on the tread monitor's findings of this step, in order: report each tread
        fault, end a push blocked.

        The encoders of one world step arrive together, so at a control step whose
        step's Int E may not have arrived yet (``period_pending``) the last period's
        modelled travel does not count against a tread.
        """
        moving = self._kind == Cmd.MOTOR_MOVE
        for verdict, fault in self._monitor.watch(moving, period_pending):
            if verdict is TreadVerdict.PUSH:
                self._finish(Cmd.NAV_MOTION_BLOCKED)
                continue
            self._report(fault)

    def _report(self, fault: TreadFault) -> None:
        """Send ``NAV_TREAD_FAULT``; the command's end then carries ``NAV_TREAD_DRIVEN``."""
        self.tread_faults += 1
        self._reported = True
        self._send(self._nav, Message.uint(Cmd.NAV_TREAD_FAULT, int(fault)))

    def _speed(self, remaining: float, cruise: float) -> float:
        t = self.tuning
        r = abs(remaining)
        if r <= self._tolerance:
            return 0.0
        v = min(cruise, math.sqrt(2.0 * t.decel_cm_s2 * r), t.gain_per_s * r)
        return math.copysign(max(v, t.min_speed_cm_s), remaining)

    def _duty(self, v: float) -> float:
        return max(-1.0, min(1.0, v / self._vmax))

    def _finish(self, outcome: int) -> None:
        driven = None
        if self._reported or (self._kind == Cmd.MOTOR_TURN and outcome == Cmd.NAV_MOTION_BLOCKED):
            driven = self._driven_message()
        self._set_pwm(0.0, 0.0)
        pl, pr = self._progress
        if self._kind == Cmd.MOTOR_TURN:
            done = math.degrees((pr - pl) / self._track)
        else:
            done = (pl + pr) / 2
        self._kind = None
        self.memory.active = False
        if driven is not None:  # before the pose at rest, which the belief moves by
            self._send(self._nav, driven)
        if self._pose_dirty:
            self._publish()
        # must not be lost: when navigation's queue is full, retry every control period
        message = Message.float(outcome, done)
        self._outcome = None if self._send(self._nav, message) else message

    def _driven_message(self) -> Message:
        """``NAV_TREAD_DRIVEN``: each tread's travel in this command by the drive model,
        up to now and on through the coast to rest once the PWM is off (a first-order
        lag at speed ``v`` goes ``v * motor_tau_s`` further), signed as driven [mm].

        Why: a command ended by the counts drives a tread that does not count on until
        the model gives it up, well past what was commanded (a turn on two stuck
        encoders turns 40-65 deg for a 23-90 deg command), so the command's amount is
        not what the tread went; the model is the one estimate there is.
        """
        m = self._monitor
        m.advance(self._now())
        tau = self.tuning.motor_tau_s
        left, right = (sign * (travel + abs(v) * tau)
                       for sign, travel, v in zip(self._signs, m.modelled, m.model_v, strict=True))
        return length_pair(Cmd.NAV_TREAD_DRIVEN, left, right, MM)

    @staticmethod
    def _now() -> float:
        return trio.current_time()
