"""What navigation does about Motor Control's tread-fault reports.

A `drivers.tread_monitor.TreadFault` report stops the motion and (in a turn, or
a short count in a move) holds still for a passing fault to clear; the doubt it
leaves about the pose is the localiser's (`note_tread_fault`: the hider's and
seeker's `localiser.BeliefLocaliser` widens the reported tread's travel in its
motion model). `TreadFaults` is a part of the hider's and seeker's navigation
actor (`route_nav.RouteNav`), which it reads through its public names.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import trio

from actors.firmware.drivers.tread_monitor import TreadFault, silent_reach_cm
from actors.firmware.nav.route import Motion

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["TreadFaults", "TREAD_HOLDS", "TREAD_CONTACT_S", "TREAD_STOP_S"]

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


class TreadFaults:
    """What the hider's and seeker's navigation does about tread reports.

    Args:
        nav: the navigation actor it stops, holds and commands.
    """

    def __init__(self, nav: RouteNav) -> None:
        self.nav = nav
        self.check_cm = silent_reach_cm(nav.spec.cm_per_interrupt)
        """The length of the straight move that checks the treads (`check_treads`) [cm]:
        the shortest over which Motor Control's tread monitor calls a tread that does
        not count silent, so a fault still on ends it within a couple of cm, under
        Motor Control's ``blocked_cm``."""
        self._reported: tuple[Motion, TreadFault] | None = None
        # the last report and the motion it came in: (motion, fault); see `reported_in`
        self._check_due = False  # a hold for a silent tread in a turn is on: check after it
        self._checking: Motion | None = None  # the check motion in flight (`check_treads`)
        self._check_holds = 0  # holds after a check that failed, since the last that passed
        self._strikes = 0  # reports in a row, each within a minute of the last
        self._last = -math.inf  # when the last report was acted on [s]

    def reported_in(self, motion: Motion | None) -> TreadFault | None:
        """The tread report Motor Control sent during ``motion``, if any (the last one,
        when it sent several): what tells a stalled tread from a wall
        (`recovery.BlockView.stalled`)."""
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
        (`route_nav.RouteNav.wall_within_drift`) are a slide along it: nothing is stopped or held.
        The error already made is not seen; the pose belief samples the reported
        tread's travel anywhere between its count and its drive, so its spread
        (`drift_cm`) widens (the seeker's search ring widens, the nudges step
        wider). After the hold, `after_motion` decides again from the pose, as
        after a motion that ended.
        """
        nav = self.nav
        motion = nav.controller.in_flight
        if motion is None:
            return  # standing (or holding) already: the report is of a motion given up
        self._reported = (motion, fault)
        now = trio.current_time()
        since_block = now - nav.controller.blocked_at
        if fault == TreadFault.BOTH_SHORT and motion.kind == "move" \
                and since_block > TREAD_CONTACT_S and nav.wall_within_drift():
            return  # a slide along a wall the rover may touch: the move goes on
        self._strikes = self._strikes + 1 if now - self._last <= 60.0 else 1
        self._last = now
        both = fault.both
        nav.tread_faults += 1
        turning = motion.kind == "turn"
        nav.localiser.note_tread_fault(fault)
        await nav.stop_motor()
        # a short count in a move holds, unless the rover was blocked just before: in
        # contact with a wall, scraping along it counts short as well
        held_move = fault.counts_short and since_block > TREAD_CONTACT_S
        if (not turning and not held_move) or self._strikes > TREAD_HOLDS:
            # a short hold all the same: the stopped motion's last pose and end arrive
            # meanwhile and are ignored, and the decision uses the pose at rest
            nav.stop_blocked(TREAD_STOP_S)
            return
        hold = nav.o.tread_hold_s * 2.0 ** (self._strikes - 1)
        self._check_due = turning and not fault.counts_short
        side = "both treads" if both else f"the {fault.side} tread"
        if fault.counts_short:
            kind = "count short" if both else "counts short"
        else:
            kind = "do not count" if both else "does not count"
        await nav.hold_still(now + hold, f"{side} {kind}; holding {hold:.0f} s")

    async def check_treads(self, blocked: bool, done: float) -> bool:
        """After a hold for a silent tread in a turn: check the treads with a short
        straight move (``check_cm``, away from the nearer mapped wall:
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
        nav = self.nav
        if self._checking is not None and self._checking is nav.last_motion:
            self._checking = None
            # counted under half its length: the fault is on (a block after the treads
            # counted is a wall's or an obstacle's, for the route's block handling)
            if blocked and abs(done) < 0.5 * self.check_cm and \
                    self._check_holds < TREAD_HOLDS:
                self._check_holds += 1
                hold = nav.o.tread_hold_s * 2.0 ** self._check_holds
                self._check_due = True
                await nav.hold_still(trio.current_time() + hold, f"the treads still do "
                                      f"not count; holding {hold:.0f} s")
                return True
            self._check_holds = 0
            return False
        if not self._check_due:
            return False
        self._check_due = False
        self._checking = Motion("move", nav.check_sign() * self.check_cm)
        await nav.command(self._checking)
        return True

    def forget_tread_check(self) -> None:
        """A new route: a check due from an earlier one is not this route's."""
        self._check_due, self._checking, self._check_holds = False, None, 0
