"""What navigation does about Motor Control's tread-fault reports.

A `drivers.tread_monitor.TreadFault` report stops the motion and (in a turn, or
a short count in a move) holds still for a passing fault to clear; the doubt it
leaves about the pose is the pose belief's (`note_tread_fault`: the hider's and
seeker's `belief_tracking.BeliefTracking` widens the reported tread's travel in
its motion model). `TreadFaults` is a mixin of `base.NavBase`, working on its
state.
"""

from __future__ import annotations

import trio

from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.nav.route import Motion

__all__ = ["TreadFaults", "TREAD_HOLDS", "TREAD_CONTACT_S", "TREAD_STOP_S", "TREAD_CHECK_CM"]

TREAD_HOLDS = 2
"""Holds in a row (each report within a minute of the last), at most; a further report
ends the motion as blocked: a tread stalled against a wall looks the same as one that
does not count, and holding would not free it."""
TREAD_CONTACT_S = 15.0
"""A short count in a move this soon after a block ends it as blocked, not held [s]:
scraping along the wall it met counts short as well."""
TREAD_STOP_S = 1.0
"""A tread fault that ends its motion as blocked waits this long before deciding [s]: the
stopped motion's last pose and end arrive meanwhile and are ignored."""
TREAD_CHECK_CM = 2.0
"""After a hold for a silent tread in a turn, a straight move this long checks the treads
before the route turns again [cm] (`TreadFaults.check_treads`): four encoder interrupts,
under Motor Control's ``blocked_cm``, so a fault still on ends it within a few cm."""


class TreadFaults:
    """Tread-fault handling and the pose doubt (a mixin of `base.NavBase`)."""

    _reported: tuple[Motion, TreadFault] | None = None
    """The last report and the motion it came in: (motion, fault); see `reported_in`."""
    _check_due = False
    """A hold for a silent tread in a turn is on: the treads are checked after it."""
    _checking: Motion | None = None
    """The check motion in flight (`check_treads`)."""
    _check_holds = 0
    """Holds after a check that failed, since the last one that passed."""

    def reported_in(self, motion: Motion | None) -> TreadFault | None:
        """The tread report Motor Control sent during ``motion``, if any (the last one,
        when it sent several): what tells a stalled tread from a wall
        (`recovery.RouteRecovery._stalled`)."""
        if motion is None or self._reported is None or self._reported[0] is not motion:
            return None
        return self._reported[1]

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control saw a driven tread that does not count, or counts short
        (``NAV_TREAD_FAULT``, a `TreadFault`): dead reckoning
        is turning the heading where the rover does not, or the other way round.
        `TreadFault.BOTH_SILENT` (sent only for a turn that ended blocked without an Int E)
        is held for like any turn. Every report is passed to `note_tread_fault`.

        Why stop and hold: Motor Control ends a motion by the counts, so each
        motion driven on a faulty encoder turns the rover further off the
        heading it believes (90-100 deg after a 9 s slip). Stopping at the
        report keeps what one motion costs small; the hold
        (``tread_hold_s``, doubled for a repeat
        within a minute, at most ``TREAD_HOLDS`` in a row, then a report ends
        the motion as blocked) waits for a passing fault to clear, as nothing
        can tell that while standing still. Only turns are held for: in a
        straight move a tread scraping along a wall stalls and reports the
        same (holding for it costs tens of seconds for nothing), so a move ends as
        blocked and the route's block handling (contact fix, back-off) follows.
        Both treads short in a move where a mapped wall may touch the body
        (`_wall_within_drift`) are a slide along it: nothing is stopped or held.
        The error already made is not seen; the pose belief samples the reported
        tread's travel anywhere between its count and its drive, so its spread
        (`drift_cm`) widens (the seeker's search ring widens, the nudges step
        wider). After the hold, `after_motion` decides again from the pose, as
        after a motion that ended.
        """
        if self._motion is None:
            return  # standing (or holding) already: the report is of a motion given up
        self._reported = (self._motion, fault)
        now = trio.current_time()
        if fault == TreadFault.BOTH_SHORT and self._motion.kind == "move" \
                and now - self._blocked_t > TREAD_CONTACT_S and self._wall_within_drift():
            return  # a slide along a wall the rover may touch: the move goes on
        self._tread_strikes = self._tread_strikes + 1 if now - self._tread_last <= 60.0 else 1
        self._tread_last = now
        both = fault.both
        self.tread_faults += 1
        turning = self._motion.kind == "turn"
        self.note_tread_fault(fault)
        await self.stop_motor()
        # a short count in a move holds, unless the rover was blocked just before: in
        # contact with a wall, scraping along it counts short as well
        held_move = fault.counts_short and now - self._blocked_t > TREAD_CONTACT_S
        if (not turning and not held_move) or self._tread_strikes > TREAD_HOLDS:
            # a short hold all the same: the stopped motion's last pose and end arrive
            # meanwhile and are ignored, and the decision uses the pose at rest
            self._blocked, self._done = True, 0.0
            self.counters["blocked"] += 1
            self._hold_until = now + TREAD_STOP_S
            return
        hold = self.o.tread_hold_s * 2.0 ** (self._tread_strikes - 1)
        self._check_due = turning and not fault.counts_short
        side = "both treads" if both else f"the {fault.side} tread"
        if fault.counts_short:
            kind = "count short" if both else "counts short"
        else:
            kind = "do not count" if both else "does not count"
        await self.hold_still(now + hold, f"{side} {kind}; holding {hold:.0f} s")

    async def hold_still(self, until: float, detail: str) -> None:
        """Hold still until ``until`` [s] and say ``detail``: the motion that ends meanwhile
        counts as not blocked, and the decision after the hold uses the pose at rest."""
        self._blocked, self._done = False, 0.0
        self._hold_until = until
        await self.status(self.state, detail)

    async def check_treads(self, blocked: bool, done: float) -> bool:
        """After a hold for a silent tread in a turn: check the treads with a short
        straight move (``TREAD_CHECK_CM``, away from the nearer mapped wall:
        `check_sign`) before the route turns again, and hold once more while the check
        ends blocked having counted under half of it (``tread_hold_s`` doubled each
        time, at most ``TREAD_HOLDS`` times). True when it commanded or held (the
        caller waits).

        Why: a turn on a silent tread, or on two (a stalled motor and two stuck
        encoders report the same), turned the rover by nothing or by Motor Control's
        drive model, and the pose belief keeps both: each turn retried while the fault
        is still on turns the rover unseen once more on stuck encoders (tens of
        degrees) and sets the belief's two hypotheses as much further apart, which no
        contact gives back. A straight move on the same fault costs a few cm of length
        and no heading, so it is the motion that tells whether the fault is over. A
        check that ends blocked after the last hold goes to the route's block handling
        like any block.
        """
        if self._checking is not None and self._checking is self.last_motion:
            self._checking = None
            # counted under half its length: the fault is on (a block after the treads
            # counted is a wall's or an obstacle's, for the route's block handling)
            if blocked and abs(done) < 0.5 * TREAD_CHECK_CM and \
                    self._check_holds < TREAD_HOLDS:
                self._check_holds += 1
                hold = self.o.tread_hold_s * 2.0 ** self._check_holds
                self._check_due = True
                await self.hold_still(trio.current_time() + hold, f"the treads still do "
                                      f"not count; holding {hold:.0f} s")
                return True
            self._check_holds = 0
            return False
        if not self._check_due:
            return False
        self._check_due = False
        self._checking = Motion("move", self.check_sign() * TREAD_CHECK_CM)
        await self.command(self._checking)
        return True

    def check_sign(self) -> float:
        """Hook: +1 to check the treads forward, -1 in reverse (see
        `recovery.RouteRecovery.check_sign`)."""
        return 1.0

    def forget_tread_check(self) -> None:
        """A new route: a check due from an earlier one is not this route's."""
        self._check_due, self._checking, self._check_holds = False, None, 0

    def note_tread_fault(self, fault: TreadFault) -> None:
        """Hook: a tread was reported during the motion in flight (the pose belief's
        motion model widens that tread's travel). The mapper has no belief here."""

    def note_tread_driven(self, left_cm: float, right_cm: float) -> None:
        """Hook: Motor Control's drive model says how far each tread went [cm] in the
        motion that is ending (``NAV_TREAD_DRIVEN``: after a tread report, or a turn
        that ended blocked)."""

    def _wall_within_drift(self) -> bool:
        """Hook: a mapped wall may touch the body (see `recovery.RouteRecovery._wall_within_drift`).
        Without the server's map (the mapper) there is none to know of."""
        return False
