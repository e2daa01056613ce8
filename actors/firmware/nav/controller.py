"""The controller of the ADP loop: the one motion in flight, and how it ends.

The seed's loop is "Command A, wait for distance travelled, update position".
`Controller` holds what that needs between messages, and nothing that talks to
another actor (the navigation actor sends and receives; see `base`): the
motion in flight and its watchdog, the wait for the pose at rest after it, and
a hold (standing still on purpose, after a tread report or a stall) that ends
in the same wait. Each of its methods is one event of the loop and returns
what the actor must do next.

Units: [s] of Trio time, [cm] and [deg] as in `route.Motion`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from actors.firmware.nav.route import Motion

__all__ = ["Controller", "MotionEnd", "Tick", "MOTION_TIMEOUT_S", "POSE_WAIT_S",
           "TURN_RATE_DEG_S"]

MOTION_TIMEOUT_S = 4.0
"""A motion reporting nothing after this plus its nominal duration is stopped [s]: a
watchdog on Motor Control, which reports every motion's end itself."""
POSE_WAIT_S = 0.3
"""How long to wait for the pose at rest after a motion [s] (Motor Control answers within
a control period or two)."""
TURN_RATE_DEG_S = 90.0
"""The turn rate a turn's nominal duration is reckoned at, for the watchdog [deg/s]."""


class Tick(Enum):
    """What a tick asks of the navigation actor (`Controller.tick`)."""

    NOTHING = 0
    """Nothing is due."""
    HOLD_OVER = 1
    """The hold ended: ask for the pose at rest."""
    TIMED_OUT = 2
    """The motion in flight reported nothing in time: stop the motor, ask for the pose."""
    POSE_LATE = 3
    """No pose at rest came: decide with the last one (`MotionEnd`)."""


@dataclass(frozen=True, slots=True)
class MotionEnd:
    """How the last motion ended, for the decision after it."""

    blocked: bool
    """Motor Control (or the watchdog, or a tread report) ended it as blocked."""
    done: float
    """How much of it was counted [cm or deg]."""


class Controller:
    """The motion in flight of one navigation actor (see the module docstring).

    Args:
        speed_cm_s: the travel speed a move's nominal duration is reckoned at [cm/s].
    """

    def __init__(self, speed_cm_s: float) -> None:
        self.speed_cm_s = speed_cm_s
        self.in_flight: Motion | None = None
        """The motion commanded and not yet ended (None between motions)."""
        self.deadline = math.inf
        """The watchdog's time for the motion in flight [s]."""
        self.end = MotionEnd(False, 0.0)
        """How the last motion ended (or the hold: not blocked)."""
        self.pose_deadline = math.inf
        """Waiting for the pose at rest until then [s]."""
        self.hold_until = math.inf
        """Holding still until then [s] (a tread report, a stall)."""
        self.blocked_at = -math.inf
        """When a motion last ended blocked [s]."""

    @property
    def busy(self) -> bool:
        """A motion is in flight, its pose at rest is awaited, or a hold is on."""
        return self.in_flight is not None or self.pose_deadline < math.inf or \
            self.hold_until < math.inf

    def begin(self, motion: Motion, now: float) -> None:
        """``motion`` was commanded at ``now``: watch it."""
        self.in_flight = motion
        nominal = abs(motion.amount) / self.speed_cm_s if motion.kind == "move" \
            else abs(motion.amount) / TURN_RATE_DEG_S
        self.deadline = now + MOTION_TIMEOUT_S + nominal

    def not_sent(self, now: float) -> None:
        """The command could not be sent: the next tick treats it as blocked."""
        self.deadline = now

    def forget(self) -> None:
        """The motor was stopped: the motion in flight, its wait and any hold are over."""
        self.in_flight = None
        self.deadline = math.inf
        self.pose_deadline = math.inf
        self.hold_until = math.inf

    def ended(self, blocked: bool, done: float, now: float) -> bool:
        """Motor Control reported the motion's end; False when nobody waits for it (a
        stopped motion, or a dead incarnation's). The pose at rest is awaited next."""
        if self.in_flight is None:
            return False
        self.in_flight = None
        self.deadline = math.inf
        self.end = MotionEnd(blocked, done)
        if blocked:
            self.blocked_at = now
        self.pose_deadline = now + POSE_WAIT_S
        return True

    def at_rest(self) -> bool:
        """The pose arrived: True when it is the pose at rest awaited (decide now)."""
        if self.pose_deadline < math.inf and self.in_flight is None and \
                self.hold_until == math.inf:
            self.pose_deadline = math.inf
            return True
        return False

    def hold(self, until: float) -> None:
        """Hold still until ``until`` [s]; the motion that ends meanwhile counts as not
        blocked, and the decision after the hold uses the pose at rest."""
        self.end = MotionEnd(False, 0.0)
        self.hold_until = until

    def stop_blocked(self, now: float, wait_s: float) -> None:
        """The motion was stopped for a tread report: it ends as blocked after ``wait_s``
        (its last pose and end arrive meanwhile and are ignored)."""
        self.end = MotionEnd(True, 0.0)
        self.hold_until = now + wait_s

    def tick(self, now: float) -> Tick:
        """The timer ticked at ``now``: what is due (see `Tick`)."""
        if self.hold_until < math.inf:
            if now >= self.hold_until:
                self.hold_until = math.inf
                self.pose_deadline = now + POSE_WAIT_S
                return Tick.HOLD_OVER
            return Tick.NOTHING
        if self.in_flight is not None and now >= self.deadline:
            self.in_flight = None
            self.deadline = math.inf
            self.end = MotionEnd(True, 0.0)
            self.pose_deadline = now + POSE_WAIT_S
            return Tick.TIMED_OUT
        if self.in_flight is None and now >= self.pose_deadline:
            self.pose_deadline = math.inf
            return Tick.POSE_LATE
        return Tick.NOTHING
