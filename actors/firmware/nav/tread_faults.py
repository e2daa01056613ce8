"""What navigation does about Motor Control's tread-fault reports, and the doubt
about the pose that tread faults leave.

A `drivers.tread_monitor.TreadFault` report stops the motion and (in a turn, or
a short count in a move) holds still for a passing fault to clear; the heading
error it may have left unseen widens `TreadFaults.drift_cm`, the sideways doubt
every navigation uses. `TreadFaults` is a mixin of `base.NavBase`, working on
its state.
"""

from __future__ import annotations

import math

import trio

from actors.firmware.drivers.tread_monitor import TreadFault
from server.protocol.pose import Pose

__all__ = ["TreadFaults"]


class TreadFaults:
    """Tread-fault handling and the pose doubt (a mixin of `base.NavBase`)."""

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control saw a driven tread that does not count, or counts short
        (``NAV_TREAD_FAULT``, a `TreadFault`): dead reckoning
        is turning the heading where the rover does not, or the other way round.
        `TreadFault.BOTH_SILENT` (sent only for a turn that ended blocked without an Int E)
        is held for like any turn, and doubts the heading by ``tread_both_deg``, not
        ``tread_fault_deg``: nothing counted, so the whole unseen turn is error.
        One tread silent in a turn also turns the believed heading by
        ``tread_turn_fix_deg`` in the turn's direction (a stuck encoder's unseen turn).

        Why stop and hold: Motor Control ends a motion by the counts, so each
        motion driven on a faulty encoder turns the rover further off the
        heading it believes (90-100 deg after a 9 s slip). Stopping at the
        report keeps what one motion costs to about ``tread_fault_deg``; the hold
        (``tread_hold_s``, doubled for a repeat
        within a minute, at most ``tread_holds`` in a row, then a report ends
        the motion as blocked) waits for a passing fault to clear, as nothing
        can tell that while standing still. Only turns are held for: in a
        straight move a tread scraping along a wall stalls and reports the
        same (holding for it costs tens of seconds for nothing), so a move ends as
        blocked and the route's block handling (contact fix, back-off) follows.
        Both treads short in a move where a mapped wall may touch the body
        (`_wall_within_drift`) are a slide along it: nothing is stopped or held.
        The error already made is not seen:
        ``heading_err_deg`` grows by ``tread_fault_deg``, so `drift_cm` grows
        with every cm driven afterwards (the seeker's search ring widens, the
        nudges step wider). After the hold, `after_motion` decides again from
        the pose, as after a motion that ended.
        """
        if self._motion is None:
            return  # standing (or holding) already: the report is of a motion given up
        now = trio.current_time()
        if fault == TreadFault.BOTH_SHORT and self._motion.kind == "move" \
                and now - self._blocked_t > self.o.tread_contact_s and self._wall_within_drift():
            return  # a slide along a wall the rover may touch: the move goes on
        self._tread_strikes = self._tread_strikes + 1 if now - self._tread_last <= 60.0 else 1
        self._tread_last = now
        both = fault.both
        self.tread_faults += 1
        turning = self._motion.kind == "turn"
        if turning or not both:  # both alike in a straight move turn nothing unseen
            self._fault_base_cm, self._fault_from = self.fault_drift_cm, (self.pose.x, self.pose.y)
            self.heading_err_deg += self.o.tread_both_deg if both else self.o.tread_fault_deg
        if turning and not (both or fault.counts_short):
            # one tread silent in a turn (see tread_turn_fix_deg)
            p = self.map_pose
            fix = math.copysign(self.o.tread_turn_fix_deg, self._motion.amount)
            self.correct_pose(Pose(p.x, p.y, p.heading_deg + fix), sideways_known=False)
        await self.stop_motor()
        # a short count in a move holds, unless the rover was blocked just before: in
        # contact with a wall, scraping along it counts short as well
        held_move = fault.counts_short and now - self._blocked_t > self.o.tread_contact_s
        if (not turning and not held_move) or self._tread_strikes > self.o.tread_holds:
            # a short hold all the same: the stopped motion's last pose and end arrive
            # meanwhile and are ignored, and the decision uses the pose at rest
            self._blocked, self._done = True, 0.0
            self.counters["blocked"] += 1
            self._hold_until = now + self.o.tread_stop_s
            return
        hold = self.o.tread_hold_s * 2.0 ** (self._tread_strikes - 1)
        self._blocked, self._done = False, 0.0
        self._hold_until = now + hold
        side = "both treads" if both else f"the {fault.side} tread"
        if fault.counts_short:
            kind = "count short" if both else "counts short"
        else:
            kind = "do not count" if both else "does not count"
        await self.status(self.state, f"{side} {kind}; holding {hold:.0f} s")

    def _wall_within_drift(self) -> bool:
        """Hook: a mapped wall may touch the body (see `recovery.RouteRecovery._wall_within_drift`).
        Without the server's map (the mapper) there is none to know of."""
        return False

    @property
    def fault_drift_cm(self) -> float:
        """Sideways error the doubted heading (``heading_err_deg``) may have made since
        the pose was last known [cm].

        A heading off by e turns everything driven after it about the point where
        it arose, so the position is off by at most e [rad] times the straight
        distance from that point, however the rover got there. Not the distance
        driven: a rover probing a gap goes back and forth at one place, and
        summing each move's length times sin(e) grew the doubt by about 7 cm a
        probe without end (one 10 deg report grew to about 3 m of believed drift
        after 2 m of probing). The pose is
        Motor Control's own-frame one, which a correction of the origin leaves
        continuous.
        """
        if self._fault_from is None:
            return self._fault_base_cm
        moved = math.dist(self._fault_from, (self.pose.x, self.pose.y))
        return self._fault_base_cm + moved * math.radians(min(90.0, self.heading_err_deg))

    def _forget_fault_drift(self) -> None:
        """The pose is known again: the doubted heading's sideways error starts from here."""
        self._fault_base_cm, self._fault_from = 0.0, (self.pose.x, self.pose.y)

    @property
    def drift_cm(self) -> float:
        """How far the dead-reckoned pose may be off sideways now [cm] (at least 3)."""
        return max(3.0, self.o.drift_per_cm * self.driven_cm + self.fault_drift_cm)
