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
    ``SILENT_INTERRUPTS`` (2.5) interrupts while the other tread counted at least
    ``SILENT_OTHER`` interrupts in a row meanwhile and is that many ahead in
    the command (two treads slow alike keep level counts, their interrupts
    interleaved irregularly), the tread is silent. A stalled motor on one
    side looks the same as a stuck encoder here.

Both treads silent (blocked)
    No Int E from either tread while the model says one went ``blocked_cm``:
    nothing counts, so no tread is there to compare with. A rover against a
    wall reads the same; the command ends blocked, only sooner than the
    blocked timer (`TreadMonitor.both_silent`).

A tread that counts short
    Once a tread's modelled travel in the command reaches ``SHORT_AFTER_CM``,
    a count under ``SHORT_RATIO`` of it while the other tread counts at least
    ``SHORT_OTHER_RATIO`` of its own is short (a slipping encoder counts
    about half). A weak motor on that side looks the same (it really goes
    half as far, and then its odometry is right).

Both treads counting short
    Both slipping alike keep the treads equal, so the comparison above says
    nothing, yet the rover turns more than it counts. Once both modelled
    travels reach ``SHORT_AFTER_CM`` and each tread counted under its share
    (``SHORT_RATIO`` in turns and on the mapper, ``BOTH_MOVE_RATIO`` in the
    straight moves of the hider and seeker: a rover sliding along a wall
    counts 0.55-0.65), both count short. Two weak motors read the same. Both
    short in a move while lately counting hardly at all is a push, not a
    fault: the move ends blocked (`TreadMonitor.pushing`).

One tread driven harder for level counts
    In a straight move the cross-coupling keeps the counts level, so an
    encoder slipping at 0.8 shows only in the PWM its tread needs; a tread
    whose modelled travel runs ``UNEVEN_CM`` further ahead of its count than
    the other's counts short too.

Turns too short to judge alone
    A seeker's look turns 20 deg at a time: 2.3 cm of each tread, under
    ``SHORT_AFTER_CM``, so encoders slipping at 0.5 would never be judged and
    the heading would drift by the uncounted half of every turn. The travel of
    a turn that ended unjudged (no finding, a tread under ``SHORT_AFTER_CM``)
    is carried into the next turn's judgement of counting short, the last
    ``SHORT_AFTER_CM`` of it per tread (the ratio kept), each carried turn's
    count granted one interrupt (the one a turn may end owing): a run of short
    turns is judged as one. A move, a judged turn or a finding clears the carry.

Each finding is sent at most once per tread per command (short is not sent
after silent).
"""

from __future__ import annotations

import enum
import math
from typing import Protocol

__all__ = ["MonitorTuning", "TreadFault", "TreadVerdict", "TreadMonitor", "SILENT_INTERRUPTS",
           "SILENT_OTHER", "SHORT_AFTER_CM", "SHORT_RATIO", "SHORT_OTHER_RATIO",
           "BOTH_MOVE_RATIO", "PUSH_RATIO", "PUSH_WINDOW_CM", "UNEVEN_CM"]


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

    @property
    def treads(self) -> tuple[bool, bool]:
        """Whether the (left, right) tread is reported."""
        if self.both:
            return True, True
        return (False, True) if self & TreadFault.RIGHT else (True, False)


class TreadVerdict(enum.Enum):
    """What Motor Control does about a finding, in the order found."""

    FAULT = "fault"
    """Report the `TreadFault` to navigation."""
    PUSH = "push"
    """Both treads short in a move, lately hardly counting: end the move blocked."""


class MonitorTuning(Protocol):
    """The physical quantities the monitor reads: the fields of the same name of
    ``motor.MotorTuning``, documented there."""

    period_s: float
    motor_tau_s: float
    blocked_cm: float


# The monitor's detection thresholds. Each is fixed by what the calibrated treads and
# encoders give, measured in the simulated world (tests/test_tread_monitor.py and the
# figures below), not a property a rover team sets: together they are the line between a
# healthy tread and a faulty one.
SILENT_INTERRUPTS = 2.5
"""A tread the model says went this many encoder interrupts since its last Int E is
silent (1.25 cm with 0.5 cm interrupts)."""
SILENT_OTHER = 2
"""...provided the other tread counted this many Int E in a row meanwhile, and has counted
this many more in the command: two treads going slow alike (two weak motors at 0.3, a rover
pushing against something) interleave their interrupts irregularly, and one could look
silent with the counts level (each false report costs the seeker a blocked move)."""
SHORT_AFTER_CM = 5.0
"""Judge a tread's count against its modelled travel once this far into a command [cm]."""
SHORT_RATIO = 0.65
"""A tread that counted less than this share of its modelled travel counts short (a
healthy tread counts 0.77 or more after 6 cm; a slipping encoder about 0.45), provided
the other counted at least ``SHORT_OTHER_RATIO`` of its own."""
SHORT_OTHER_RATIO = 0.8
"""See ``SHORT_RATIO``."""
BOTH_MOVE_RATIO = 0.5
"""Both treads counting short in a straight move of the hider or seeker: under this share
of their modelled travel (``SHORT_RATIO`` elsewhere). A rover sliding along a wall it meets
at an angle counts 0.55-0.65; encoders slipping at 0.3-0.5 go 2-3 times the counted
distance."""
PUSH_RATIO = 0.2
"""Both treads counting under this share of their modelled travel lately, in a move:
pushing against something, blocked (see `TreadMonitor.pushing`)."""
PUSH_WINDOW_CM = 2 * SHORT_AFTER_CM
""""Lately" is judged per this much of both treads' modelled travel together: each tread's
judging distance, ``SHORT_AFTER_CM``, for the two treads; a push is judged on the last one
to two of these, 10-20 cm [cm]."""
UNEVEN_CM = 2.0
"""In a straight move, a tread whose modelled travel exceeds its count by this much more
than the other's counts short too [cm]: the cross-coupling keeps the counts level, so an
encoder slipping at 0.8 shows only as the PWM its tread needs (25 % more than the
other's), while dead reckoning sees a straight line and the rover turns about 23 deg per
20 cm. Healthy 20 cm moves differ by 0.6 cm at most, an interrupt's quantum (0.5 cm)
either way included."""


_NO_CARRY = ((0.0, 0.0), (0.0, 0.0))  # no unjudged turn carried: (modelled, counted) per tread


class TreadMonitor:
    """The lagged model of both treads and the counts, over one Command A.

    Args:
        tuning: the motor's physical quantities (``motor.MotorTuning``).
        unit_cm: tread travel per Int E [cm].
        vmax_cm_s: tread speed at full PWM [cm/s].
        mapper: the rover has its own LIDAR (both-short uses ``SHORT_RATIO`` in moves
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
        self._marks = [(0.0, 0.0)]     # (modelled, counted) sums every PUSH_WINDOW_CM, last two
        self._run = [0, 0]             # Int E in a row without one from the other tread
        self._silent_sent = [False, False]  # silent found in this command
        self.pwm = (0.0, 0.0)
        """The duties last set while driving."""
        self._model_t = 0.0            # when the model was last advanced [s]
        self._turning = False          # the command is a turn (as `watch` was last told)
        self._carry = _NO_CARRY  # unjudged turns' (modelled, counted) per tread

    def begin(self, now: float) -> None:
        """A new Command A starts at ``now`` [s]: every count and finding starts over,
        save an unjudged turn's travel (see "Turns too short to judge alone")."""
        self._carry_over()
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
        self._turning = False

    def _carry_over(self) -> None:
        """Carry the command that ends into the next turn's judgement when it was a turn
        that ended unjudged; clear the carry otherwise."""
        found = any(self._short_sent) or any(self._silent_sent)
        if not self._turning or found or min(self.modelled) >= SHORT_AFTER_CM:
            self._carry = _NO_CARRY
            return
        carry: list[tuple[float, float]] = []
        for tread in (0, 1):
            m = self._carry[tread][0] + self.modelled[tread]
            # an interrupt's grace per carried turn: a turn that ends may owe up to one
            # interrupt its model already went (healthy short turns count 0.6-1.1 alone)
            c = self._carry[tread][1] + self.counted[tread] + self._unit
            keep = min(1.0, SHORT_AFTER_CM / m) if m > 0.0 else 1.0  # the last part, same ratio
            carry.append((m * keep, c * keep))
        self._carry = (carry[0], carry[1])

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
        self._turning = not moving
        if not period_pending:
            self._watch_counts(moving, found)
        t = self.tuning
        for tread in (0, 1):
            other = 1 - tread
            if self._silent_sent[tread] or self._run[other] < SILENT_OTHER:
                continue
            if self.counted[other] - self.counted[tread] < SILENT_OTHER * self._unit:
                continue  # counts level: slow alike (weak, pushing), interrupts interleaved
            owed = self._unticked[tread]
            if period_pending:
                owed -= abs(self.model_v[tread]) * t.period_s
            if owed >= SILENT_INTERRUPTS * self._unit:
                self._silent_sent[tread] = True
                found.append((TreadVerdict.FAULT, TreadFault.silent(tread)))
        return found

    def _watch_counts(self, moving: bool, found: list[tuple[TreadVerdict, TreadFault]]) -> None:
        """Both treads counting short (a push in a move of the hider or seeker), or one
        counting short, or driven further for the same count in a move."""
        modelled = sum(self.modelled)
        if modelled - self._marks[-1][0] >= PUSH_WINDOW_CM:
            self._marks = [self._marks[-1], (modelled, sum(self.counted))]
        ratio = SHORT_RATIO if not moving or self._mapper else BOTH_MOVE_RATIO
        # a turn is judged with the unjudged turns before it; a move on its own
        carry = _NO_CARRY if moving else self._carry
        judged_m = [self.modelled[i] + carry[i][0] for i in (0, 1)]
        judged_c = [self.counted[i] + carry[i][1] for i in (0, 1)]
        if not (any(self._short_sent) or any(self._silent_sent)) \
                and min(judged_m) >= SHORT_AFTER_CM \
                and all(judged_c[i] < ratio * judged_m[i] for i in (0, 1)):
            self._short_sent = [True, True]
            if moving and not self._mapper and self.pushing():
                found.append((TreadVerdict.PUSH, TreadFault.BOTH_SHORT))
                return
            found.append((TreadVerdict.FAULT, TreadFault.BOTH_SHORT))
            return
        for tread in (0, 1):
            other = 1 - tread
            modelled, counted = judged_m[tread], judged_c[tread]
            if self._short_sent[tread] or self._silent_sent[tread] or modelled < SHORT_AFTER_CM:
                continue
            short = counted < SHORT_RATIO * modelled and \
                judged_c[other] >= SHORT_OTHER_RATIO * judged_m[other]
            if not short and moving and counted > 0.0:
                # driven further than the other for the same count (see ``UNEVEN_CM``)
                short = (modelled - counted) - (judged_m[other] - judged_c[other]) \
                    >= UNEVEN_CM
            if short:
                self._short_sent[tread] = True
                found.append((TreadVerdict.FAULT, TreadFault.short(tread)))

    def pushing(self) -> bool:
        """Both treads count short in a move, and lately hardly at all: the rover pushes
        against something (blocked), not two slipping encoders.

        Slipping encoders count 0.3-0.8 of the travel from the moment they slip; a
        rover that meets a wall counts right until then and next to nothing after, or
        a few % while it slides along a face it meets at an angle. Judged on the last
        ``PUSH_WINDOW_CM`` to twice that of both treads' modelled travel, one
        interrupt's quantum granted (two weak motors at 0.3 must not read as a push).
        """
        modelled0, counted0 = self._marks[0]
        modelled = sum(self.modelled) - modelled0
        counted = sum(self.counted) - counted0
        return counted + self._unit < PUSH_RATIO * modelled  # an interrupt's grace
