"""Tread-fault detection: a driven tread that does not count, or counts short.

Pure (no actor, no clock of its own): Motor Control feeds it the duties it
sets, each Int E and the time, and acts on what it finds (`TreadVerdict`).

Why
    A stuck encoder makes dead reckoning see a turn where the rover goes
    straight (or a spin where it turns a little), and a check against scan
    matching comes about a second late with the heading several degrees off.
    Motor Control knows sooner: it drives the tread, and the motors follow
    their PWM with a first-order lag (``motor_tau_s``), so the monitor models
    how far each tread should have gone.

The healthy model
    Over a stretch of ``m`` cm of a tread's modelled travel, a healthy tread
    counts ``c`` with ``m - c`` normal of mean 0 and standard deviation
    ``hypot(MODEL_SIGMA * m, unit)``: the lag model's relative error, which is
    common to both treads (they are driven alike and share the model), and the
    count lagging the travel by up to one interrupt (``unit``, the encoder's
    ``cm_per_interrupt``). Every finding is one test of that model: the
    uncounted travel lies more than ``FAULT_Z`` standard deviations beyond it.
    Healthy treads of the simulated world stay within 2 standard deviations
    away from contacts.

A tread that counts short
    Over the command (with the turns carried, below), one tread's uncounted
    travel runs beyond the other's. A slipping encoder counts about half; a
    weak motor on that side looks the same (it really goes half as far, and
    then its odometry is right). Short travel says little: the interrupts'
    lag dominates, so a few cm are needed.

    The difference of the two treads' uncounted travel cancels the common
    relative error and leaves the two interrupts' lags: a difference beyond
    ``FAULT_Z`` times ``sqrt(2) * unit`` (about 2 cm; each carried turn adds
    its own two lags) is that tread counting short. This also finds one
    encoder slipping at 0.8 in a move, which the cross-coupling keeps level in
    its count: it shows only in the PWM its tread needs. A tread that counted
    more than its model (pushed round by something) is taken as level with it.

Both treads counting short
    Both treads' uncounted travel beyond the model: both encoders slipping
    alike, two weak motors, or a rover sliding along a face it met at an angle
    (a slide counts ``cos(a)^2`` of the travel driven): in a straight move of
    the hider or seeker, whose slides are common, both must also count under
    ``BOTH_MOVE_RATIO``. In such a move, both short while lately counting
    hardly at all (under ``PUSH_RATIO`` of ``PUSH_WINDOW_CM``) is a push, not a
    fault: the move ends blocked (`TreadMonitor.pushing`), also after a
    both-short report (a slide that ends against the face).

A tread that is driven but does not count (silent)
    The same test over the stretch since the tread's last Int E (its count
    there is 0), provided the other tread counted at least ``SILENT_OTHER``
    interrupts in a row meanwhile and is that many ahead in the command (two
    treads slow alike keep level counts, their interrupts interleaved
    irregularly). A stalled motor on one side looks the same as a stuck
    encoder here.

Both treads silent (blocked)
    No Int E from either tread while the model says one went ``blocked_cm``:
    nothing counts, so no tread is there to compare with. A rover against a
    wall reads the same; the command ends blocked, only sooner than the
    blocked timer (`TreadMonitor.both_silent`).

Turns too short to judge alone
    A seeker's look turns 20 deg at a time: 2.3 cm of each tread, too little
    for the test, so encoders slipping at 0.5 would never be found and the
    heading would drift by the uncounted half of every turn. A turn that ends
    without a finding is carried into the next turn's judgement: the travel
    adds up, the interrupts' lag does not (a turn that ends owing part of an
    interrupt has it counted early in the next), and each turn's relative
    error is its own (variances add). A move or a finding clears the carry.

Each finding is sent at most once per tread per command (short is not sent
after silent), a push at most once per command.
"""

from __future__ import annotations

import enum
import math
from typing import Protocol

__all__ = ["MonitorTuning", "TreadFault", "TreadVerdict", "TreadMonitor", "MODEL_SIGMA",
           "FAULT_Z", "BOTH_MOVE_RATIO", "SILENT_OTHER", "PUSH_RATIO",
           "PUSH_WINDOW_CM", "silent_reach_cm"]


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


MODEL_SIGMA = 0.1
"""Relative error of the lagged tread model: the standard deviation of a healthy tread's
travel against its modelled travel, common to both treads [1] (`localisation.motion_model`
samples a reported tread's driven travel with it)."""
FAULT_Z = 3.0
"""A tread's uncounted travel more than this many standard deviations of the healthy model
beyond 0 is a finding [1]."""
BOTH_MOVE_RATIO = 0.5
"""Both treads count short in a straight move of the hider or seeker only under this share
of their modelled travel as well [1]: a rover sliding along a face it meets at an angle
``a`` counts ``cos(a)^2`` of it (0.55-0.65 along most walls it meets), while encoders
slipping at 0.3-0.5 go 2-3 times the counted distance."""
SILENT_OTHER = 2
"""A silent tread needs the other tread to have counted this many Int E in a row meanwhile,
and this many more in the command: two treads going slow alike (two weak motors at 0.3, a
rover pushing against something) interleave their interrupts irregularly, and one could
look silent with the counts level (each false report costs the seeker a blocked move)."""
PUSH_RATIO = 0.2
"""Both treads counting under this share of their modelled travel lately, in a move:
pushing against something, blocked (see `TreadMonitor.pushing`)."""
PUSH_WINDOW_CM = 10.0
""""Lately" is judged per this much of both treads' modelled travel together: a push is
judged on the last one to two of these, 10-20 cm [cm]. Shorter, the interrupt granted
(`TreadMonitor.pushing`) hides a rover that slides on at 0.1 of its drive."""


def silent_reach_cm(unit_cm: float) -> float:
    """How far a tread that does not count must be driven for the healthy model to call
    it silent [cm]: the modelled travel ``u`` with no Int E for which
    ``u > FAULT_Z * hypot(MODEL_SIGMA * u, unit_cm)``. With 0.5 cm interrupts, 1.6 cm."""
    return FAULT_Z * unit_cm / math.sqrt(1.0 - (FAULT_Z * MODEL_SIGMA) ** 2)


_NO_CARRY = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
# no turn carried: (modelled, counted, variance of the relative error) per tread


class TreadMonitor:
    """The lagged model of both treads and the counts, over one Command A.

    Args:
        tuning: the motor's physical quantities (``motor.MotorTuning``).
        unit_cm: tread travel per Int E [cm].
        vmax_cm_s: tread speed at full PWM [cm/s].
        mapper: the rover has its own LIDAR (a push is not judged: the mapper's scan
            matching sees it).
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
        self._push_sent = False        # a push found in this command
        self._marks = [(0.0, 0.0)]     # (modelled, counted) sums every PUSH_WINDOW_CM, last two
        self._run = [0, 0]             # Int E in a row without one from the other tread
        self._silent_sent = [False, False]  # silent found in this command
        self.pwm = (0.0, 0.0)
        """The duties last set while driving."""
        self._model_t = 0.0            # when the model was last advanced [s]
        self._turning = False          # the command is a turn (as `watch` was last told)
        self._carry = _NO_CARRY        # earlier turns of the run, judged with this one
        self._carried_turns = 0        # how many

    def beyond(self, uncounted: float, modelled: float, variance: float = 0.0) -> bool:
        """Whether ``uncounted`` travel [cm] over a stretch of ``modelled`` travel [cm]
        lies beyond the healthy model (``FAULT_Z`` standard deviations); ``variance``
        [cm^2] is the relative error's of earlier stretches judged with it."""
        sd = math.sqrt((MODEL_SIGMA * modelled) ** 2 + variance + self._unit ** 2)
        return uncounted > FAULT_Z * sd

    def begin(self, now: float) -> None:
        """A new Command A starts at ``now`` [s]: every count and finding starts over,
        save the turns carried (see "Turns too short to judge alone")."""
        self._carry_over()
        self._silent_sent = [False, False]
        self._unticked = [0.0, 0.0]
        self._since_any = 0.0
        self.modelled = [0.0, 0.0]
        self.counted = [0.0, 0.0]
        self._short_sent = [False, False]
        self._push_sent = False
        self._marks = [(0.0, 0.0)]
        self.model_v = [0.0, 0.0]
        self._run = [0, 0]
        self._model_t = now
        self._turning = False

    def _carry_over(self) -> None:
        """Carry the command that ends into the next turn's judgement when it was a turn
        without a finding; clear the carry otherwise."""
        if not self._turning or any(self._short_sent) or any(self._silent_sent):
            self._carry, self._carried_turns = _NO_CARRY, 0
            return
        self._carried_turns += 1

        def grown(tread: int) -> tuple[float, float, float]:
            m, c, v = self._carry[tread]
            turn = self.modelled[tread]
            # an interrupt's grace per carried turn: a turn that ends may owe up to one
            # interrupt its model already went (healthy short turns count 0.6-1.1 alone)
            return m + turn, c + self.counted[tread] + self._unit, v + (MODEL_SIGMA * turn) ** 2

        self._carry = (grown(0), grown(1))

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
            if self.beyond(owed, owed):
                self._silent_sent[tread] = True
                found.append((TreadVerdict.FAULT, TreadFault.silent(tread)))
        if not period_pending:  # after silence: a tread that stopped counting is silent
            self._watch_counts(moving, found)
        return found

    def _watch_counts(self, moving: bool, found: list[tuple[TreadVerdict, TreadFault]]) -> None:
        """Both treads counting short (a push in a move of the hider or seeker), or one
        counting short, or driven further for the same count."""
        modelled = sum(self.modelled)
        if modelled - self._marks[-1][0] >= PUSH_WINDOW_CM:
            self._marks = [self._marks[-1], (modelled, sum(self.counted))]
        # a turn is judged with the turns carried before it; a move on its own
        carry = _NO_CARRY if moving else self._carry
        m = [self.modelled[i] + carry[i][0] for i in (0, 1)]
        c = [self.counted[i] + carry[i][1] for i in (0, 1)]
        contact_move = moving and not self._mapper  # slides and pushes are judged here
        both = all(self.beyond(m[i] - c[i], self.modelled[i], carry[i][2]) for i in (0, 1))
        if both and contact_move:  # a slide counts cos(a)^2 of the drive
            both = all(c[i] < BOTH_MOVE_RATIO * m[i] for i in (0, 1))
        if both:
            if contact_move and not self._push_sent and self.pushing():
                self._push_sent = self._short_sent[0] = self._short_sent[1] = True
                found.append((TreadVerdict.PUSH, TreadFault.BOTH_SHORT))
                return
            if not (any(self._short_sent) or any(self._silent_sent)):
                self._short_sent = [True, True]
                found.append((TreadVerdict.FAULT, TreadFault.BOTH_SHORT))
            return
        # one tread short: its uncounted travel beyond the other's, where the common
        # relative error cancels and the two interrupts' lags are left, each turn judged
        # adding its own (a turn ends owing part of an interrupt on each tread)
        turns = 0 if moving else self._carried_turns
        lag = FAULT_Z * math.sqrt(2.0 * (1 + turns)) * self._unit
        for tread in (0, 1):
            other = 1 - tread
            if self._short_sent[tread] or self._silent_sent[tread]:
                continue
            # a tread that counted more than its model was turned by something else
            # (pushed round): that says nothing about the other
            if (m[tread] - c[tread]) - max(m[other] - c[other], 0.0) > lag:
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
