"""Tread-fault detection: a driven tread that does not count, or counts short.

Pure (no actor, no clock of its own): Motor Control feeds it the duties it
sets, each Int E and the time, and acts on what it finds (`TreadVerdict`).

Why
    A stuck encoder makes dead reckoning see a turn where the rover goes
    straight (or a spin where it turns a little), and a check against scan
    matching comes about a second late with the heading several degrees off.
    Motor Control knows sooner: it drives the tread, and the motors follow
    their PWM with a first-order lag (``motor_tau_s``), so the monitor models
    how far each tread should have gone since its last Int E.

A tread that is driven but does not count (silent)
    When the modelled travel since a tread's last Int E reaches
    ``silent_cm`` (2.5 interrupts) while the other tread counted at least
    ``silent_other`` interrupts in a row meanwhile and is that many ahead in
    the command (two treads slow alike keep level counts, their interrupts
    interleaved irregularly), the tread is silent. A stalled motor on one
    side looks the same as a stuck encoder here.

Both treads silent (blocked)
    No Int E from either tread while the model says one went ``blocked_cm``:
    nothing counts, so no tread is there to compare with. A rover against a
    wall reads the same; the command ends blocked, only sooner than the
    blocked timer (`TreadMonitor.both_silent`).

A tread that counts short
    Once a tread's modelled travel in the command reaches ``short_after_cm``,
    a count under ``short_ratio`` of it while the other tread counts at least
    ``short_other_ratio`` of its own is short (a slipping encoder counts
    about half). A weak motor on that side looks the same (it really goes
    half as far, and then its odometry is right).

Both treads counting short
    Both slipping alike keep the treads equal, so the comparison above says
    nothing, yet the rover turns more than it counts. Once both modelled
    travels reach ``short_after_cm`` and each tread counted under its share
    (``short_ratio`` in turns and on the mapper, ``both_move_ratio`` in the
    straight moves of the hider and seeker: a rover sliding along a wall
    counts 0.55-0.65), both count short. Two weak motors read the same. Both
    short in a move while lately counting hardly at all is a push, not a
    fault: the move ends blocked (`TreadMonitor.pushing`).

One tread driven harder for level counts
    In a straight move the cross-coupling keeps the counts level, so an
    encoder slipping at 0.8 shows only in the PWM its tread needs; a tread
    whose modelled travel runs ``uneven_cm`` further ahead of its count than
    the other's counts short too.

Each finding is sent at most once per tread per command (short is not sent
after silent).
"""

from __future__ import annotations

import enum
import math
from typing import Protocol

__all__ = ["MonitorTuning", "TreadFault", "TreadVerdict", "TreadMonitor"]


class TreadFault(enum.IntFlag):
    """The ``NAV_TREAD_FAULT`` payload: which tread, what kind, whether both.

    Bit 0 the tread (0 left, 1 right), bit 1 the kind (0 silent, 1 counts
    short), bit 2 both treads. The values sent are `silent` / `short` of a
    tread (0-3), `BOTH_SILENT` (4: a turn blocked without one Int E) and
    `BOTH_SHORT` (6).
    """

    LEFT_SILENT = 0
    RIGHT = 1
    SHORT = 2
    BOTH = 4
    BOTH_SILENT = 4
    BOTH_SHORT = 6

    @classmethod
    def silent(cls, tread: int) -> TreadFault:
        """One tread (0 left, 1 right) is driven but does not count."""
        return cls(tread & 1)

    @classmethod
    def short(cls, tread: int) -> TreadFault:
        """One tread (0 left, 1 right) counts short."""
        return cls.SHORT | cls(tread & 1)

    @property
    def both(self) -> bool:
        """Both treads."""
        return bool(self & TreadFault.BOTH)

    @property
    def counts_short(self) -> bool:
        """The tread(s) count short (else: do not count at all)."""
        return bool(self & TreadFault.SHORT)

    @property
    def side(self) -> str:
        """``left``, ``right`` or ``both``."""
        return "both" if self.both else "right" if self & TreadFault.RIGHT else "left"


class TreadVerdict(enum.Enum):
    """What Motor Control does about a finding, in the order found."""

    FAULT = "fault"
    """Report the `TreadFault` to navigation."""
    PUSH = "push"
    """Both treads short in a move, lately hardly counting: end the move blocked."""


class MonitorTuning(Protocol):
    """The constants the monitor reads: the fields of the same name of
    ``motor.MotorTuning``, documented there."""

    period_s: float
    motor_tau_s: float
    blocked_cm: float
    silent_cm: float
    silent_other: int
    short_after_cm: float
    short_ratio: float
    short_other_ratio: float
    both_move_ratio: float
    push_ratio: float
    push_window_cm: float
    uneven_cm: float


class TreadMonitor:
    """The lagged model of both treads and the counts, over one Command A.

    Args:
        tuning: the motor's tuning (``motor.MotorTuning``).
        unit_cm: tread travel per Int E [cm].
        vmax_cm_s: tread speed at full PWM [cm/s].
        mapper: the rover has its own LIDAR (both-short uses ``short_ratio`` in moves
            too, and a push is not judged: the mapper's scan matching sees it).
    """

    def __init__(self, tuning: MonitorTuning, unit_cm: float, vmax_cm_s: float,
                 mapper: bool) -> None:
        self.tuning = tuning
        self._unit = unit_cm
        self._vmax = vmax_cm_s
        self._mapper = mapper
        self.model_v = [0.0, 0.0]
        """Modelled tread speed (lagged PWM) [cm/s]."""
        self._unticked = [0.0, 0.0]    # modelled travel since the tread's last Int E [cm]
        self._since_any = 0.0          # most modelled travel since either tread's last Int E [cm]
        self.modelled = [0.0, 0.0]
        """Modelled travel in this command [cm]."""
        self.counted = [0.0, 0.0]
        """Counted travel in this command [cm]."""
        self._short_sent = [False, False]  # counts short found in this command
        self._marks = [(0.0, 0.0)]     # (modelled, counted) sums every push_window_cm, last two
        self._run = [0, 0]             # Int E in a row without one from the other tread
        self._silent_sent = [False, False]  # silent found in this command
        self.pwm = (0.0, 0.0)
        """The duties last set while driving."""
        self._model_t = 0.0            # when the model was last advanced [s]

    def begin(self, now: float) -> None:
        """A new Command A starts at ``now`` [s]: every count and finding starts over."""
        self._silent_sent = [False, False]
        self._unticked = [0.0, 0.0]
        self._since_any = 0.0
        self.modelled = [0.0, 0.0]
        self.counted = [0.0, 0.0]
        self._short_sent = [False, False]
        self._marks = [(0.0, 0.0)]
        self.model_v = [0.0, 0.0]
        self._run = [0, 0]
        self._model_t = now

    def tick(self, tread: int, now: float) -> None:
        """One Int E of ``tread`` at ``now`` [s]."""
        self.advance(now)
        self._unticked[tread] = 0.0
        self._since_any = 0.0
        self.counted[tread] += self._unit
        self._run[tread] += 1
        self._run[1 - tread] = 0

    def advance(self, now: float) -> None:
        """Advance the lagged tread model to ``now`` (travel since each tread's last Int E)."""
        dt = now - self._model_t
        if dt <= 0.0:
            return
        self._model_t = now
        k = 1.0 - math.exp(-dt / self.tuning.motor_tau_s)
        most = 0.0
        for tread in (0, 1):
            v0 = self.model_v[tread]
            v1 = v0 + (self.pwm[tread] * self._vmax - v0) * k
            self.model_v[tread] = v1
            travel = 0.5 * (abs(v0) + abs(v1)) * dt
            self._unticked[tread] += travel
            self.modelled[tread] += travel
            most = max(most, travel)
        self._since_any += most

    def both_silent(self) -> bool:
        """No Int E from either tread while the model says one went ``blocked_cm``.

        Called at a control step, whose world step's Int E may not have arrived
        yet: the last period's travel is not owed.
        """
        owed = self._since_any - max(abs(v) for v in self.model_v) * self.tuning.period_s
        return owed >= self.tuning.blocked_cm

    def watch(self, moving: bool, period_pending: bool) -> list[tuple[TreadVerdict, TreadFault]]:
        """The findings of this step, in the order Motor Control acts on them.

        Args:
            moving: the command is a straight move (else a turn).
            period_pending: called at a control step whose world step's Int E may
                not have arrived yet: the last period's modelled travel is not owed.
        """
        found: list[tuple[TreadVerdict, TreadFault]] = []
        if not period_pending:
            self._watch_counts(moving, found)
        t = self.tuning
        for tread in (0, 1):
            other = 1 - tread
            if self._silent_sent[tread] or self._run[other] < t.silent_other:
                continue
            if self.counted[other] - self.counted[tread] < t.silent_other * self._unit:
                continue  # counts level: slow alike (weak, pushing), interrupts interleaved
            owed = self._unticked[tread]
            if period_pending:
                owed -= abs(self.model_v[tread]) * t.period_s
            if owed >= t.silent_cm:
                self._silent_sent[tread] = True
                found.append((TreadVerdict.FAULT, TreadFault.silent(tread)))
        return found

    def _watch_counts(self, moving: bool, found: list[tuple[TreadVerdict, TreadFault]]) -> None:
        """Both treads counting short (a push in a move of the hider or seeker), or one
        counting short, or driven further for the same count in a move."""
        t = self.tuning
        modelled = sum(self.modelled)
        if modelled - self._marks[-1][0] >= t.push_window_cm:
            self._marks = [self._marks[-1], (modelled, sum(self.counted))]
        ratio = t.short_ratio if not moving or self._mapper else t.both_move_ratio
        if not (any(self._short_sent) or any(self._silent_sent)) \
                and min(self.modelled) >= t.short_after_cm \
                and all(self.counted[i] < ratio * self.modelled[i] for i in (0, 1)):
            self._short_sent = [True, True]
            if moving and not self._mapper and self.pushing():
                found.append((TreadVerdict.PUSH, TreadFault.BOTH_SHORT))
                return
            found.append((TreadVerdict.FAULT, TreadFault.BOTH_SHORT))
            return
        for tread in (0, 1):
            other = 1 - tread
            modelled, counted = self.modelled[tread], self.counted[tread]
            if self._short_sent[tread] or self._silent_sent[tread] or modelled < t.short_after_cm:
                continue
            short = counted < t.short_ratio * modelled and \
                self.counted[other] >= t.short_other_ratio * self.modelled[other]
            if not short and moving and counted > 0.0:
                # driven further than the other for the same count (see ``uneven_cm``)
                short = (modelled - counted) - (self.modelled[other] - self.counted[other]) \
                    >= t.uneven_cm
            if short:
                self._short_sent[tread] = True
                found.append((TreadVerdict.FAULT, TreadFault.short(tread)))

    def pushing(self) -> bool:
        """Both treads count short in a move, and lately hardly at all: the rover pushes
        against something (blocked), not two slipping encoders.

        Slipping encoders count 0.3-0.8 of the travel from the moment they slip; a
        rover that meets a wall counts right until then and next to nothing after, or
        a few % while it slides along a face it meets at an angle. Judged on the last
        ``push_window_cm`` to twice that of both treads' modelled travel, one
        interrupt's quantum granted (two weak motors at 0.3 must not read as a push).
        """
        modelled0, counted0 = self._marks[0]
        modelled = sum(self.modelled) - modelled0
        counted = sum(self.counted) - counted0
        return counted + self._unit < self.tuning.push_ratio * modelled  # an interrupt's grace
