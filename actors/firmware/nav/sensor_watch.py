"""The mapper's watch on its sensors: it holds still while the LIDAR or the
odometry cannot be trusted, since a map drawn from them would be wrong.

A faulty LIDAR (a map drawn while it fails has phantom or missing obstacles)
    LIDAR Control withholds the scans of a sensor it judges faulty and says so
    (``NAV_LIDAR_HEALTH``: garbled, stuck, noisy); a dead one sends nothing, which
    shows here as a scan count that stops rising for ``LIDAR_SILENT_S`` while
    the LIDAR should be scanning. Either way navigation holds still (MOTOR_STOP;
    driving blind is what distorted the maps: no obstacle check, no scan matching)
    and reports ``lidar_fault`` in its status. It goes on once the verdict is
    healthy again and scans are counted again, with a fresh route and a fresh
    stable window; a fault that outlasts ``lidar_pause_s`` is driven through
    (once per ``lidar_pause_s``): the budget, not the fault, ends mapping.

Odometry in doubt (a stuck or slipping encoder draws the map from a wrong pose)
    A tread whose encoder stops counting while it is driven makes the rover
    spin or veer where dead reckoning sees it stand or go straight, and the map
    would be drawn from a wrong pose. Motor Control sees it first: its
    ``NAV_TREAD_FAULT`` (a driven tread that does not count) stops the motor at
    once and holds still (the LIDAR scanning, so matching can settle the pose)
    for ``ODO_HOLD_S``, doubled for each repeat within a minute up to
    ``ODO_HOLD_MAX_S``, reporting ``odometry_fault`` in its status; the fault
    cannot be seen from standing still, so it drives on after the hold. One
    saying a tread, or both, count short (a slipping encoder, or a weak motor)
    stops the motion too and holds ``SHORT_HOLD_S`` (see `on_tread_fault`).
    What Motor Control does not see, Map Management's pose belief weighs: its
    "odometry broke unseen" hypothesis (`localisation.odometry_fault`).
    Every report is relayed to Map Management when the motion ends
    (``MAP_TREAD_FAULT``, `relay_tread_driven`) with the travel Motor Control's
    drive model says each reported tread went beyond its count (``NAV_TREAD_DRIVEN``;
    a turn that ended blocked, reported or not, has both treads so relayed): its pose
    belief widens by what the motion model makes of it, and while the belief is
    wider than the local match reaches, only the wide search places batches.

A motion that ended blocked in the open (both encoders stuck)
    Motor Control ends a command blocked when neither tread counts: a rover pushing
    a wall reads the same as one whose two encoders stopped while it drives on, and
    it reports only a turn whose model caught it (`TreadFault.BOTH_SILENT`). The map
    tells them apart: a move that ended blocked with no mapped obstacle within
    ``CONTACT_CELLS`` of its leading edge, on known free floor, met nothing the LIDAR
    sees, and a turn that counted nothing at all is most likely two stuck encoders
    (as Motor Control judges one its model caught); the odometry is in doubt
    (`blocked_in_the_open`). Exploring or going home, the mapper then holds as for
    a tread that does not count instead of backing off: a back-off or a turn on
    stuck encoders is driven blind (a few cm, or tens of degrees, per try, unseen,
    in a corridor 30 cm wide), and going home, counting such blocks as the way home
    being blocked would upload the map from where the rover stands, maybe in the
    passage the hider needs. Holds count as strikes; once the hold has doubled to
    ``ODO_HOLD_MAX_S`` (the fault outlasted about 45 s), such a block counts as a
    block again.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import trio

from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import LidarHealth
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.localisation.odometry import tread_travel
from actors.firmware.origin_wire import MM, length_pair
from actors.firmware.planning.clearance import occupied_near
from server.protocol.grid_map import UNKNOWN
from server.protocol.pose import Pose

if TYPE_CHECKING:
    from actors.firmware.nav.mapper import MappingNav

__all__ = ["SensorWatch", "uncounted_travel", "LIDAR_SILENT_S", "ODO_HOLD_S", "ODO_HOLD_MAX_S",
           "SHORT_HOLD_S", "CONTACT_CELLS"]

# The thresholds and holds of the two watches, fixed beside them: they judge and wait for
# scan matching (which owns the mapper's pose), not a property of the rover.
LIDAR_SILENT_S = 1.5
"""No scan counted for this long while scanning: the LIDAR is silent (dead or garbled),
and navigation holds still [s]: six of Map Management's 0.25 s count reports."""
ODO_HOLD_S = 3.0
"""Hold still this long after a tread that does not count [s]; doubled for each repeat
within 60 s, up to ``ODO_HOLD_MAX_S``."""
ODO_HOLD_MAX_S = ODO_HOLD_S * 2 ** 3
"""Longest hold for odometry in doubt: ``ODO_HOLD_S`` doubled three times [s]."""
SHORT_HOLD_S = 2.0
"""Hold still this long after Motor Control saw a tread (or both) count short [s]: about
eight scan batches for scan matching to catch up with what was not counted."""
CONTACT_CELLS = 2
"""A move that ended blocked met a mapped obstacle when one lies within this many cells of
its leading edge (ahead, across the body's width and a cell either side) [cells]: a
mapped face lies up to a cell in front of the wall's, and the pose is a cell or so off."""


def _odo_hold_s(strikes: int) -> float:
    """The odometry hold of the ``strikes``-th strike in a row, before its cap [s]:
    ``ODO_HOLD_S`` doubled for each strike after the first."""
    return ODO_HOLD_S * 2.0 ** (strikes - 1)


def uncounted_travel(reported: tuple[bool, bool], counted: tuple[float, float],
                     driven: tuple[float, float]) -> tuple[float, float]:
    """The (left, right) travel [cm] Motor Control drove each reported tread beyond its
    count in a motion (0 for a tread not reported), signed as the tread was driven.

    ``counted`` is each tread's count over the motion [cm]; ``driven`` Motor Control's
    drive model of it (``NAV_TREAD_DRIVEN``), which a tread that does not count (or
    counts short) goes as far as, at most."""
    return tuple(math.copysign(max(0.0, abs(d) - abs(c)), d) if r else 0.0
                 for r, c, d in zip(reported, counted, driven, strict=True))  # type: ignore[return-value]


class SensorWatch:
    """The mapper's sensor holds, a part of its navigation actor.

    Args:
        nav: the mapper's navigation actor, whose state and motions it watches.
    """

    def __init__(self, nav: MappingNav) -> None:
        self.nav = nav
        self._lidar_verdict = LidarHealth.OK  # LIDAR Control's last verdict
        self._pause_started = -math.inf
        self._pause_off_until = -math.inf  # a fault that outlasted lidar_pause_s: drive on
        self._scans_at_pause = 0
        self._odo_hold_until = -math.inf  # holding still for odometry until then
        self._odo_last = -math.inf  # when the last counted odometry hold began
        self._odo_strikes = 0  # counted holds in a row, each within 60 s of the last
        self._relayed = (False, False)  # treads reported in this motion, to relay at its end

    async def on_lidar_health(self, value: int) -> None:
        """LIDAR Control's verdict changed (``NAV_LIDAR_HEALTH``): hold still at once."""
        try:
            self._lidar_verdict = LidarHealth(value)
        except ValueError:
            self.nav.counters["bad_frames"] += 1
            return
        await self.lidar_watch(trio.current_time())

    async def lidar_watch(self, now: float) -> bool:
        """Begin or end holding still for a faulty LIDAR; True while holding.

        See "A faulty LIDAR" in the module docstring."""
        if self.nav.state not in ("scanning", "exploring", "homing"):
            self.nav.lidar_fault = None
            return False
        m = self.nav.m
        silent = now - self.nav.scan_rise_at >= LIDAR_SILENT_S
        if self.nav.lidar_fault is None:
            fault = self._lidar_verdict if self._lidar_verdict != LidarHealth.OK else (
                LidarHealth.SILENT if silent else None)
            if fault is None or now < self._pause_off_until:
                return False
            self.nav.lidar_fault = fault
            self.nav.lidar_faults += 1
            self._pause_started = now
            self._scans_at_pause = self.nav.scans
            if self.nav.moving:
                await self.nav.stop_motor()
            await self.nav.status("lidar_fault",
                              f"LIDAR {fault.name.lower()}: holding still until it recovers")
            return True
        healthy = (self._lidar_verdict == LidarHealth.OK and not silent
                   and self.nav.scans > self._scans_at_pause)
        if not healthy and now - self._pause_started < m.lidar_pause_s:
            return True
        if healthy:
            why = f"LIDAR recovered after {now - self._pause_started:.1f} s"
        else:
            why = f"LIDAR still faulty after {m.lidar_pause_s:.0f} s: driving on"
            self._pause_off_until = now + m.lidar_pause_s
        self.nav.lidar_fault = None
        # what was planned before may have been planned on a map the fault spoiled
        self.nav.changed_at = now
        self.nav.ex.follower = None
        self.nav.wait_map = True
        self.nav.last_wait_decide = -math.inf
        await self.nav.status(self.nav.state, why)
        return False

    @property
    def holding(self) -> bool:
        """Holding still: the LIDAR is faulty, or odometry is in doubt."""
        return self.nav.lidar_fault is not None or trio.current_time() < self._odo_hold_until

    async def odometry_watch(self, now: float) -> bool:
        """True while holding for odometry; at the end of a hold, drive on with a fresh
        route and a fresh stable window.

        See "Odometry in doubt" in the module docstring."""
        if self.nav.state not in ("exploring", "homing"):
            return False
        if self._odo_hold_until > -math.inf and now >= self._odo_hold_until:
            self._odo_hold_until = -math.inf
            self.nav.changed_at = now
            self.nav.ex.follower = None
            self.nav.wait_map = True
            self.nav.last_wait_decide = -math.inf
            await self.nav.status(self.nav.state, "odometry hold over: driving on")
            return False
        return now < self._odo_hold_until

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control saw a driven tread that does not count (``NAV_TREAD_FAULT``): its
        odometry is wrong from now on, so stop at once and hold.

        A tread (or both) that counts short stops the motion too, with a
        short hold (``SHORT_HOLD_S``, not doubled): a slipping encoder makes every
        motion turn (one tread) or go (both) further than counted, and driving on let
        the heading get 40-130 deg off, beyond what scan matching recovers. A weak
        motor reads the same and its odometry is right, so the hold is short: it costs a
        weak motor a pause per motion, not the game."""
        now = trio.current_time()
        if self.nav.state not in ("exploring", "homing") or not self.nav.moving:
            return
        treads = fault.treads
        self._relayed = (self._relayed[0] or treads[0], self._relayed[1] or treads[1])
        if now < self._odo_hold_until:
            return
        if fault.both:
            if fault.counts_short:
                await self.odometry_hold(now, "both treads count short", SHORT_HOLD_S)
            else:
                # both silent: a turn that ended blocked without one Int E. Backing off
                # and turning again drives it on blind: with both encoders stuck for
                # 9 s the mapper spins about five turns unseen in such blocks, and the
                # map comes out at half accuracy
                await self.odometry_hold(now, "both treads are driven but do not count")
            return
        side = fault.side
        if fault.counts_short:
            await self.odometry_hold(now, f"the {side} tread counts short", SHORT_HOLD_S)
            return
        await self.odometry_hold(now, f"the {side} tread is driven but does not count")

    async def relay_tread_driven(self, left_cm: float, right_cm: float) -> None:
        """Motor Control's drive model of the motion that is ending (``NAV_TREAD_DRIVEN``):
        tell Map Management how far it drove each tread reported in it beyond the count
        (``MAP_TREAD_FAULT``, `uncounted_travel`), so its pose belief widens by it. A turn
        that ended blocked without a report has both treads in doubt (a jammed rover
        and two stuck encoders read the same)."""
        reported, self._relayed = self._relayed, (False, False)
        # counted in the own frame: the map-frame pose also moves by the origin's
        # corrections, which are no tread's travel
        motion, start = self.nav.last_motion, self.nav.odometry_from
        if motion is None or start is None:
            return
        if reported == (False, False):
            if motion.kind != "turn":
                return
            reported = (True, True)
        counted = tread_travel(start, self.nav.pose, self.nav.spec.track_width_cm)
        left, right = uncounted_travel(reported, counted, (left_cm, right_cm))
        await self.nav.post(self.nav.map_name, length_pair(Cmd.MAP_TREAD_FAULT, left, right, MM))

    def blocked_in_the_open(self, done: float) -> bool:
        """Whether the last motion, which ended blocked having counted ``done`` [cm or
        deg], met nothing the map holds: a turn that counted nothing (both encoders stuck,
        as Motor Control's `TreadFault.BOTH_SILENT` says of one its model caught), or a
        move with no occupied cell within ``CONTACT_CELLS`` of its leading edge (across the
        body's width and a cell either side) and the cells there known free (an unknown
        cell may hide what stopped it). See "A motion that ended blocked in the open" in
        the module docstring."""
        motion, grid = self.nav.last_motion, self.nav.grid
        if motion is None or grid is None:
            return False
        if motion.kind == "turn":
            return done == 0.0
        p = self.nav.map_pose
        lead = p if motion.amount >= 0 else Pose(p.x, p.y, p.heading_deg + 180.0)
        res = grid.resolution_cm
        front = 0.5 * self.nav.length_cm
        reach = front + CONTACT_CELLS * res
        side = 0.5 * self.nav.width_cm + res
        near = occupied_near(grid, lead, math.hypot(reach, side))
        if near is not None:
            _, _, fwd, lat = near
            if bool(np.any((fwd > 0.0) & (fwd <= reach) & (np.abs(lat) <= side))):
                return False
        h = lead.heading_rad
        ch, sh = math.cos(h), math.sin(h)
        half = 0.5 * self.nav.width_cm
        for f in np.arange(front, reach + 1e-9, 0.5 * res):
            for s in np.arange(-half, half + 1e-9, 0.5 * res):
                r, c = grid.world_to_cell(p.x + f * ch - s * sh, p.y + f * sh + s * ch)
                if not (0 <= r < grid.shape[0] and 0 <= c < grid.shape[1]) or (
                        grid.cells[r, c] == UNKNOWN):
                    return False
        return True

    async def hold_if_blocked_in_the_open(self, done: float) -> bool:
        """After a motion that ended blocked having counted ``done``: hold for odometry
        when it met nothing the map holds (`blocked_in_the_open`) and the hold has not
        yet doubled to its longest; True when holding (the block is not the route's)."""
        now = trio.current_time()
        if now - self._odo_last <= 60.0 and _odo_hold_s(self._odo_strikes) >= ODO_HOLD_MAX_S:
            return False  # held the longest already: a fault this long, or a real block
        if not self.blocked_in_the_open(done):
            return False
        await self.odometry_hold(
            now, "a motion ended blocked with nothing mapped in its way: both encoders "
            "may be stuck")
        return True

    async def odometry_hold(self, now: float, what: str, hold: float | None = None) -> None:
        """Stop the motor and hold still for odometry (see the module docstring); ``hold``
        [s] given: that long, not counted as a strike."""
        if hold is None:
            self._odo_strikes = self._odo_strikes + 1 if now - self._odo_last <= 60.0 else 1
            self._odo_last = now
            hold = min(ODO_HOLD_MAX_S, _odo_hold_s(self._odo_strikes))
        self._odo_hold_until = now + hold
        self.nav.odometry_faults += 1
        await self.nav.stop_motor()
        await self.nav.status("odometry_fault", f"{what}; holding {hold:.0f} s")

