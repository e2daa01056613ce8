"""Mapping navigation: frontier exploration with the ADP loop, and knowing when it is done.

Flow
    idle --start--> scanning (LIDAR_START, wait for the first scans) -->
    exploring (frontier -> A* route -> ADP steps; re-choose every few steps as
    the map grows) --complete--> homing --> uploading; --stop | time budget-->
    uploading (MOTOR_STOP, LIDAR_STOP, MAP_GET, wait for the fresh snapshot) -->
    mapped (WIFLY_SEND_MAP with the map cropped to its known part).

Homing
    A mapper left where its last frontier was can block the only passage the
    hider needs (a corridor barely wider than a rover: the hider pushes it and
    gives up). So when mapping completes by itself, the mapper first drives
    back to its start pose, the LIDAR still scanning (scan matching keeps its
    pose honest), bounded by ``home_budget_s`` and ``home_blocks``; then it
    uploads. A stop from the server or the time budget uploads at once.

Choosing where to go
    `frontier.find_frontiers` + `frontier.choose_frontier` on the latest
    NAV_MAP_UPDATE (cost trades distance against frontier size and favours less
    explored areas; long frontiers come cut into 1 m pieces); `nav_common.plan_route`
    for the path, trying tiers of clearance from the turning radius plus a margin
    down to half the body width (a 30 cm corridor maps 25 cm wide on a 5 cm grid);
    reachability uses the narrowest tier. A frontier whose
    target cannot be planned to, which blocks the rover twice, which takes more
    ADP steps than its route deserves, or which is chosen again after being
    reached, is blacklisted (by its target point [cm], which survives
    map growth).

Obstacles ahead
    Before each straight move, `clearance.obstacle_ahead` looks ``move +
    stop_cm`` ahead on the map: the move is shortened to stop ``stop_cm``
    (20 cm: inside the seed's 15-30 cm) before the obstacle, and when that
    leaves nothing to drive the rover turns away from it and chooses again;
    after ``obstacle_turns`` such turns toward one target without a move between,
    the target is blacklisted (the route passes where the rover will not drive).

Complete when both hold (either alone can lie)
    * no reachable frontier of useful size remains (a stalled LIDAR would also
      give "no change"); after ``futile_trips`` trips in a row that made
      fewer than ``min_gain_cells`` cells known each on average (a window, so one
      trip just above the limit does not start the count over), only frontiers of at least
      ``futile_min_cells`` lying mostly in the open (``futile_open_share``)
      still count as useful (the rest are pockets nobody can see into, ragged
      edges along walls), and
    * the map's count of known cells has not moved for ``stable_window_s``
      while the scan count kept rising (a stalled LIDAR gives no scans, so it
      never reads as done).
    Or when the server says ``stop``, or after ``budget_s`` of mapping.

A faulty LIDAR (why: a map drawn while it fails has phantom or missing obstacles)
    LIDAR Control withholds the scans of a sensor it judges faulty and says so
    (``NAV_LIDAR_HEALTH``: garbled, stuck, noisy); a dead one sends nothing, which
    shows here as a scan count that stops rising for ``lidar_silent_s`` while
    the LIDAR should be scanning. Either way navigation holds still (MOTOR_STOP;
    driving blind is what distorted the maps: no obstacle check, no scan matching)
    and reports ``lidar_fault`` in its status. It goes on once the verdict is
    healthy again and scans are counted again, with a fresh route and a fresh
    stable window; a fault that outlasts ``lidar_pause_s`` is driven through
    (once per ``lidar_pause_s``): the budget, not the fault, ends mapping.

Odometry that scan matching contradicts (why: a stuck encoder drew a round room at 0.56 accuracy)
    A tread whose encoder stops counting while it is driven makes the rover
    spin or veer where dead reckoning sees it stand or go straight; scan
    matching drags the pose after it, batch by batch, and the map is drawn
    from a wrong pose. Navigation sees the contradiction in its map-frame pose:
    an in-place turn that moved it more than ``odo_turn_shift_cm``, or a
    straight move that turned it more than ``odo_move_turn_deg``. It stops the
    motor at once and holds still (the LIDAR scanning, so matching can settle
    the pose) for ``odo_hold_s``, doubled for each repeat within a minute up to
    ``odo_hold_max_s``, reporting ``odometry_fault`` in its status; the fault
    cannot be seen from standing still, so it drives on after the hold. Motor
    Control's ``NAV_TREAD_FAULT`` (a driven tread that does not count) starts
    the same hold at once, a second or more before the pose shows it; one
    saying a tread, or both, count short (a slipping encoder, or a weak motor)
    stops the motion too and holds ``short_hold_s`` (see `on_tread_fault`).
    A turn that ended with both treads silent (value 4: the rover may have
    turned tens of degrees unseen) holds as a silent tread does and tells Map
    Management the pose is lost (``MAP_POSE_LOST``): it places no batch until
    scan matching finds the pose again (`mapping.MapManagement`).

Restart
    The new incarnation asks Map Management for a snapshot (MAP_GET) and Motor
    Control for the pose. Only navigation starts the LIDAR, so scans still
    arriving (NAV_SCAN_COUNT rising within ``probe_s``) prove mapping was under
    way: it resumes exploring from the current pose and map. The blacklist is
    lost, which costs at most a few wasted trips.

Frame: the mapper's own frame is the map frame [cm, deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trio

from actors import BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import LidarHealth
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.odometry import angle_diff_deg
from actors.firmware.mapping.occupancy import UNKNOWN, GridMap
from actors.firmware.nav.base import NavBase
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.route import Motion, PathFollower, plan_route, route_points
from actors.firmware.planning.clearance import obstacle_ahead
from actors.firmware.planning.frontier import Frontier, choose_frontier, find_frontiers

__all__ = ["MappingOptions", "MappingNav"]


@dataclass(frozen=True, slots=True)
class MappingOptions:
    """Tunables of exploration and of the completion test."""

    lidar_duty: float = 0.5
    """LIDAR rotation PWM for mapping (Command B)."""
    first_scans: int = 3
    """Scan batches to wait for before the first move."""
    min_frontier_cells: int = 6
    """Smallest useful frontier [cells]."""
    approach_cm: float = 30.0
    """How near a frontier the rover must get [cm]."""
    reach_cm: float = 10.0
    """A frontier target counts as reached this close [cm]."""
    rechoose_steps: int = 3
    """Re-choose the frontier after this many ADP steps (the map grew meanwhile)."""
    stop_cm: float = 20.0
    """Stop this far before an obstacle ahead (centre to cell centre) [cm]."""
    obstacle_turns: int = 3
    """Turns away from an obstacle toward one target with no move between them before
    the target is blacklisted (the route passes where the rover will not drive)."""
    stable_window_s: float = 10.0
    """The map must not have changed for this long [s]..."""
    stable_scans: int = 5
    """...while at least this many scan batches arrived."""
    change_cells: int = 3
    """The map changed when its count of known cells moved by more than this (or
    ``change_share`` of it) since the last change; free/occupied flicker is not a change,
    and neither is unknown/known flicker at the edges (scan matching's jitter at rest
    once kept a furniture map "changing" for 340 s), which nets out."""
    change_share: float = 0.002
    """Relative part of the change threshold (of the known cells)."""
    budget_s: float = 900.0
    """Mapping time budget: upload what is known after this [s]."""
    probe_s: float = 3.0
    """After a restart, rising scan counts within this mean mapping was under way [s]."""
    upload_wait_s: float = 1.0
    """Wait at most this for a fresh snapshot before uploading the last one [s]."""
    max_choices: int = 8
    """Frontiers tried per decision before waiting for the map to change."""
    blacklist: int = 256
    """Most blacklisted points kept."""
    futile_trips: int = 4
    """After this many trips in a row (each until its target was reached or given up)
    that revealed fewer than ``min_gain_cells`` each on average, the frontiers left are not worth
    visiting (pockets behind furniture, noise at edges): exploration treats them as not
    useful, and completion may follow."""
    futile_min_cells: int = 16
    """After futile trips, frontiers at least this long still count as useful [cells]:
    four visits to small pockets near the start once ended a 10 m hall at 62 % coverage
    with its far part, one long frontier, unseen."""
    futile_open_share: float = 0.5
    """...and at least this share of their cells in the open (no obstacle within 30 cm):
    a ragged edge along a wall or a pocket behind furniture is long too."""
    trip_max_s: float = 90.0
    """A trip also ends after this long [s] (the rover switching frontiers on the way
    never reaches a target: furniture once made one trip of 615 s and mapped 900 s)."""
    min_gain_cells: int = 30
    """A trip that made fewer cells known than this was futile [cells]..."""
    home_budget_s: float = 180.0
    """Most time spent driving back to the start before uploading; 0 skips homing [s]."""
    home_reach_cm: float = 15.0
    """Home counts as reached this close to the start [cm]."""
    home_blocks: int = 3
    """Blocked motions on the way home before uploading from where the rover is."""
    lidar_silent_s: float = 1.5
    """No scan counted for this long while scanning: the LIDAR is silent (dead or
    garbled), and navigation holds still [s]. Map Management publishes the count every
    0.25 s while scans arrive."""
    lidar_pause_s: float = 60.0
    """Hold still for a LIDAR fault at most this long, then drive on regardless for as
    long before holding again [s]."""
    odo_turn_shift_cm: float = 10.0
    """An in-place turn that moved the map-frame position further than this: odometry
    and scan matching disagree grossly (an encoder stuck or slipping) [cm]."""
    odo_move_turn_deg: float = 25.0
    """A straight move that turned the map-frame heading by more than this: the same [deg]."""
    odo_hold_s: float = 3.0
    """Hold still this long after such a disagreement [s]; doubled for each repeat
    within ``60 s``, up to ``odo_hold_max_s``."""
    odo_hold_max_s: float = 24.0
    """Longest hold for an odometry disagreement [s]."""
    blind_turn_deg: float = 180.0
    """After a turn that ended with both treads silent, Map Management searches this far
    either side of dead reckoning's heading for the pose (``MAP_POSE_LOST``) [deg]: in
    held-out campaign 3:199 one such turn went 50 deg unseen, and navigation's answer
    (back off, turn again) spun the rover five turns in 9 s."""
    short_hold_s: float = 2.0
    """Hold still this long after Motor Control saw a tread (or both) count short [s]:
    about eight scan batches for scan matching to catch up with what was not counted."""
    min_gain_share: float = 0.003
    """...or fewer than this share of the cells already known (a big hall's ragged far
    edges give a few dozen cells per visit for ever). Counted per visit, not per
    minute: crossing a big hall to a far frontier reveals nothing for a while."""


@dataclass
class _Exploration:
    """Exploration state of one incarnation."""

    follower: PathFollower | None = None
    target: tuple[float, float] | None = None
    steps: int = 0  # ADP steps toward the current target
    budget: int = 0  # most steps it deserves
    blocks: int = 0  # blocked motions toward the current target
    blacklist: list[tuple[float, float]] = field(default_factory=list)
    reached: list[tuple[float, float]] = field(default_factory=list)  # targets arrived at
    no_frontier: bool = False  # the last decision found nothing useful to explore
    trip_known: int | None = None  # known cells when the current trip began
    trip_started: float = 0.0  # trio time the current trip began [s]
    gains: list[int] = field(default_factory=list)  # cells each recent trip made known
    turned_away: int = 0  # turns away from an obstacle toward this target, no move between
    turned_target: tuple[float, float] | None = None  # the target they were toward


class MappingNav(NavBase):
    """The mapper's navigation actor (registered as ``mapper/nav``)."""

    role = "mapper"

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec | None = None,
                 options: NavOptions | None = None, memory: NavMemory | None = None,
                 mapping: MappingOptions | None = None,
                 addresses: Addresses | None = None) -> None:
        super().__init__(pool=pool, spec=spec, options=options, memory=memory,
                         addresses=addresses)
        self.m = mapping or MappingOptions()
        self.grid: GridMap | None = None
        """The latest snapshot from Map Management (kept: what navigation knows)."""
        self.scans = 0
        """Scan batches Map Management reported."""
        self.ex = _Exploration()
        self._changed_at = 0.0  # trio time of the last map change
        self._scans_at_change = 0
        self._known_at_change = 0  # known cells when the map last changed
        self._scans_at_start = 0
        self._started_at = 0.0
        self._probe_until = -math.inf
        self._probe_scans: int | None = None
        self._upload_deadline = math.inf
        self._wait_map = False  # decide at the next map update
        self._last_wait_decide = -math.inf
        self._finish_reason = ""
        self._home_deadline = math.inf
        self.lidar_fault: LidarHealth | None = None
        """The LIDAR fault navigation holds still for, None while driving normally."""
        self.lidar_faults = 0
        """LIDAR faults held still for (this incarnation)."""
        self._lidar_verdict = LidarHealth.OK  # LIDAR Control's last verdict
        self._scan_rise_at = -math.inf  # trio time the scan count last rose
        self._pause_started = -math.inf
        self._pause_off_until = -math.inf  # a fault that outlasted lidar_pause_s: drive on
        self._scans_at_pause = 0
        self.odometry_faults = 0
        """Odometry disagreements held still for (this incarnation)."""
        self._odo_hold_until = -math.inf  # holding still for odometry until then
        self._odo_last = -math.inf  # when the last disagreement was seen
        self._odo_strikes = 0  # disagreements in a row, each within 60 s of the last

    # ------------------------------------------------------------------ dispatch
    async def handle(self, message: Any) -> Any:
        if isinstance(message, Message) and message.command == Cmd.NAV_LIDAR_HEALTH:
            await self.on_lidar_health(int(message.value))
            return None
        if isinstance(message, Message) and message.command == Cmd.NAV_TREAD_FAULT:
            await self.on_tread_fault(TreadFault(int(message.value)))
            return None
        return await super().handle(message)

    # ------------------------------------------------------------------ lifecycle
    async def on_restart(self) -> None:
        self.map_name = self.names.map
        self.lidar = self.names.lidar
        await self.post(self.map_name, Message.uint(Cmd.MAP_GET, 0))
        self._probe_until = trio.current_time() + self.m.probe_s
        if self.memory.started:  # the retained record says mapping was under way
            await self._begin(trio.current_time(), resumed=True)

    async def on_map_lost(self) -> None:
        # Map Management restarted empty: give it back what we knew; its count restarts at 0
        self._probe_scans = None
        self._scans_at_start = self._scans_at_change = self.scans = 0
        if self.grid is not None:
            await self.put_and_post(self.map_name, Cmd.MAP_RESTORE, self.grid)

    async def on_start_cmd(self) -> None:
        if self.state in ("scanning", "exploring", "homing", "uploading"):
            return  # a repeated start (resent after a reconnect) changes nothing
        await self._begin(trio.current_time(), resumed=False)

    async def _begin(self, now: float, *, resumed: bool) -> None:
        self.started = True
        self._probe_until = -math.inf
        self._started_at = now
        self._scans_at_start = self.scans
        self._changed_at, self._scans_at_change = now, self.scans
        self._scan_rise_at = now  # the LIDAR spins up: silence counts from here
        self.lidar_fault = None
        self.ex = _Exploration()
        await self.post(self.lidar, Message.float(Cmd.LIDAR_START, self.m.lidar_duty))
        if resumed:
            await self.set_state("exploring", "resumed after a restart")
            self._wait_map = True
        else:
            await self.set_state("scanning", "waiting for the first scans")

    async def on_stop_cmd(self) -> None:
        if self.state in ("scanning", "exploring", "homing"):
            await self._finish("stopped by the server")

    # ------------------------------------------------------------------ map events
    async def on_map_update(self, grid: GridMap) -> None:
        prev = self.grid
        self.grid = grid
        now = trio.current_time()
        known = int(np.count_nonzero(grid.cells != UNKNOWN))
        if prev is None or prev.shape != grid.shape or abs(known - self._known_at_change) > max(
                self.m.change_cells, self.m.change_share * known):
            self._changed_at, self._scans_at_change = now, self.scans
            self._known_at_change = known
        if self.state == "uploading":
            await self._upload()
        elif self.state == "scanning":
            await self._maybe_explore()
        elif self.state == "exploring" and self._wait_map and not self.moving:
            self._wait_map = False
            await self.decide()

    async def on_scan_count(self, count: int) -> None:
        if self._probe_scans is None:
            self._probe_scans = count
        elif count > self._probe_scans and trio.current_time() <= self._probe_until \
                and not self.started:
            # only navigation starts the LIDAR: scans arriving mean mapping was under way
            self.scans = count
            await self._begin(trio.current_time(), resumed=True)
            return
        if count > self.scans:
            self._scan_rise_at = trio.current_time()
        self.scans = count
        if self.state == "scanning":
            await self._maybe_explore()

    async def _maybe_explore(self) -> None:
        if self.grid is not None and self.scans - self._scans_at_start >= self.m.first_scans:
            await self.set_state("exploring", "frontier exploration")
            await self.decide()

    # ------------------------------------------------------------------ LIDAR faults
    async def on_lidar_health(self, value: int) -> None:
        """LIDAR Control's verdict changed (``NAV_LIDAR_HEALTH``): hold still at once."""
        try:
            self._lidar_verdict = LidarHealth(value)
        except ValueError:
            self.counters["bad_frames"] += 1
            return
        await self._lidar_watch(trio.current_time())

    async def _lidar_watch(self, now: float) -> bool:
        """Begin or end holding still for a faulty LIDAR; True while holding.

        See "A faulty LIDAR" in the module docstring."""
        if self.state not in ("scanning", "exploring", "homing"):
            self.lidar_fault = None
            return False
        m = self.m
        silent = now - self._scan_rise_at >= m.lidar_silent_s
        if self.lidar_fault is None:
            fault = self._lidar_verdict if self._lidar_verdict != LidarHealth.OK else (
                LidarHealth.SILENT if silent else None)
            if fault is None or now < self._pause_off_until:
                return False
            self.lidar_fault = fault
            self.lidar_faults += 1
            self._pause_started = now
            self._scans_at_pause = self.scans
            if self.moving:
                await self.stop_motor()
            await self.status("lidar_fault",
                              f"LIDAR {fault.name.lower()}: holding still until it recovers")
            return True
        healthy = (self._lidar_verdict == LidarHealth.OK and not silent
                   and self.scans > self._scans_at_pause)
        if not healthy and now - self._pause_started < m.lidar_pause_s:
            return True
        if healthy:
            why = f"LIDAR recovered after {now - self._pause_started:.1f} s"
        else:
            why = f"LIDAR still faulty after {m.lidar_pause_s:.0f} s: driving on"
            self._pause_off_until = now + m.lidar_pause_s
        self.lidar_fault = None
        # what was planned before may have been planned on a map the fault spoiled
        self._changed_at, self._scans_at_change = now, self.scans
        self.ex.follower = None
        self._wait_map = True
        self._last_wait_decide = -math.inf
        await self.status(self.state, why)
        return False

    @property
    def holding(self) -> bool:
        """Holding still: the LIDAR is faulty, or odometry was contradicted lately."""
        return self.lidar_fault is not None or trio.current_time() < self._odo_hold_until

    async def _odometry_watch(self, now: float) -> bool:
        """Stop and hold when the motion in flight contradicts odometry; True while holding.

        See "Odometry that scan matching contradicts" in the module docstring."""
        m = self.m
        if self.state not in ("exploring", "homing"):
            return False
        if self._odo_hold_until > -math.inf and now >= self._odo_hold_until:
            self._odo_hold_until = -math.inf
            self._changed_at, self._scans_at_change = now, self.scans
            self.ex.follower = None
            self._wait_map = True
            self._last_wait_decide = -math.inf
            await self.status(self.state, "odometry hold over: driving on")
            return False
        if now < self._odo_hold_until:
            return True
        motion, start = self.last_motion, self.motion_from
        if not self.moving or motion is None or start is None:
            return False
        p = self.map_pose
        if motion.kind == "turn":
            off = math.hypot(p.x - start.x, p.y - start.y)
            if off <= m.odo_turn_shift_cm:
                return False
            what = f"a turn moved the pose {off:.0f} cm"
        else:
            turned = abs(angle_diff_deg(p.heading_deg, start.heading_deg))
            if turned <= m.odo_move_turn_deg:
                return False
            what = f"a straight move turned the pose {turned:.0f} deg"
        await self._odometry_hold(now, f"{what}: odometry and scan matching disagree")
        return True

    async def on_tread_fault(self, fault: TreadFault) -> None:
        """Motor Control saw a driven tread that does not count (``NAV_TREAD_FAULT``): its
        odometry is wrong from now on, so stop at once and hold, as for a disagreement.

        A tread (or both, bit 2) that counts short (bit 1) stops the motion too, with a
        short hold (``short_hold_s``, not doubled): a slipping encoder makes every
        motion turn (one tread) or go (both) further than counted, and driving on let
        the heading get 40-130 deg off, beyond what scan matching recovers (campaign
        games 1:125, 1:187). A weak motor reads the same and its odometry is right, so
        the hold is short: it costs a weak motor a pause per motion, not the game."""
        now = trio.current_time()
        if self.state not in ("exploring", "homing") or not self.moving \
                or now < self._odo_hold_until:
            return
        if fault.both:
            if fault.counts_short:
                await self._odometry_hold(now, "both treads count short", self.m.short_hold_s)
            else:
                # both silent (4): a turn that ended blocked without one Int E. Backing off
                # and turning again drove it on blind: held-out campaign 3:199 (both
                # encoders stuck 9 s) spun the mapper about five turns unseen in 9 s of
                # such blocks, and the map came out at 0.48 accuracy
                await self._odometry_hold(now, "both treads are driven but do not count")
                await self.post(self.map_name, Message.uint(Cmd.MAP_POSE_LOST,
                                                            int(self.m.blind_turn_deg)))
            return
        side = fault.side
        if fault.counts_short:
            await self._odometry_hold(now, f"the {side} tread counts short",
                                      self.m.short_hold_s)
            return
        await self._odometry_hold(now, f"the {side} tread is driven but does not count")

    async def _odometry_hold(self, now: float, what: str, hold: float | None = None) -> None:
        """Stop the motor and hold still for odometry (see the module docstring); ``hold``
        [s] given: that long, not counted as a strike."""
        m = self.m
        if hold is None:
            self._odo_strikes = self._odo_strikes + 1 if now - self._odo_last <= 60.0 else 1
            self._odo_last = now
            hold = min(m.odo_hold_max_s, m.odo_hold_s * 2.0 ** (self._odo_strikes - 1))
        self._odo_hold_until = now + hold
        self.odometry_faults += 1
        await self.stop_motor()
        await self.status("odometry_fault", f"{what}; holding {hold:.0f} s")

    # ------------------------------------------------------------------ ticks
    async def on_tick(self, now: float) -> None:
        if self.state == "uploading" and now >= self._upload_deadline:
            await self._upload()
            return
        holding = await self._lidar_watch(now)
        holding = await self._odometry_watch(now) or holding
        if self.state == "homing":
            if now >= self._home_deadline:
                await self._finish(self._finish_reason + "; home not reached in time")
            elif not self.moving and not holding:
                await self._home_step()
            return
        if self.state not in ("exploring", "scanning"):
            return
        if now - self._started_at >= self.m.budget_s:
            await self._finish(f"time budget of {self.m.budget_s:.0f} s used")
            return
        if self.state == "exploring" and not self.moving and not holding:
            if self.complete(now):
                await self._finish("no reachable frontier left and the map is stable",
                                   home=True)
            elif self.ex.no_frontier or self._wait_map:
                # waiting for the map to change; look again about once a second
                if now - self._last_wait_decide >= 1.0:
                    self._last_wait_decide = now
                    self._wait_map = False
                    await self.decide()

    def complete(self, now: float) -> bool:
        """Both completion conditions: no useful frontier, and a stable map while scanning."""
        return (self.ex.no_frontier and not self.holding
                and now - self._changed_at >= self.m.stable_window_s
                and self.scans - self._scans_at_change >= self.m.stable_scans)

    # ------------------------------------------------------------------ exploring
    async def after_motion(self, blocked: bool, done: float) -> None:
        if self.state == "homing":
            if not self.holding:
                await self._after_home_motion(blocked)
            return
        if self.state != "exploring" or self.holding:
            return
        if blocked:
            self.ex.blocks += 1
            if self.ex.blocks >= 2 and self.ex.target is not None:
                self._blacklist(self.ex.target)
            self.ex.follower = None
            last = self.last_motion
            if last is not None and last.kind == "move" and last.amount < 0:
                await self.command(Motion("turn", 90.0))  # cannot back off either: turn
            else:
                await self.command(Motion("move", -self.o.backoff_cm))
            return
        await self.decide()

    async def decide(self) -> None:
        """One ADP decision: keep or choose a frontier, then command one motion."""
        if self.state != "exploring" or self.moving or self.grid is None or self.holding:
            return
        if not self.can_move:
            self._wait_map = True  # the tick tries again
            return
        ex = self.ex
        pose = self.pose
        if ex.trip_known is not None and trio.current_time() - ex.trip_started >= \
                self.m.trip_max_s:
            # a rover that keeps switching to new frontiers on the way never ends a trip
            # (furniture seed 3: one trip of 615 s): count it as a visit, go on
            self._end_trip()
            ex.trip_known, ex.trip_started = self._known(), trio.current_time()
        if ex.follower is not None and ex.steps >= ex.budget:
            self._blacklist(ex.target)  # no progress worth the route
            ex.follower = None
        if ex.follower is None or ex.steps % self.m.rechoose_steps == 0:
            if not self._choose(keep=ex.follower is not None):
                return
        assert ex.follower is not None
        motion = ex.follower.next_motion(pose)
        if motion is None or (ex.target is not None
                              and math.dist((pose.x, pose.y), ex.target) <= self.m.reach_cm):
            if ex.target is not None:
                ex.reached.append(ex.target)
                self._end_trip()
            ex.follower = None
            self._wait_map = True  # look again once the map shows what is seen from here
            return
        if motion.kind == "move":
            motion = self._mind_the_obstacle(motion)
            if motion.kind == "turn":
                ex.follower = None
                if self._turned_away():
                    return
            else:
                ex.turned_away = 0
        ex.steps += 1
        await self.command(motion)

    def _turned_away(self) -> bool:
        """Count a turn away from an obstacle; True (target blacklisted, decide again
        at the next tick) after ``obstacle_turns`` toward one target without a move.

        Why: the route (planned with the narrowest clearance tier) can pass where the
        obstacle check refuses to drive; the rover then turned toward the route, was
        refused, turned away and planned the same route again, for 280 s by one wall
        in furniture 2 (three 90-s trips revealing 21, 7 and 4 cells), and turning in
        place by a wall is where scan matching drifts."""
        ex = self.ex
        if ex.target is None:
            return False
        if ex.turned_target is not None and math.dist(ex.target, ex.turned_target) <= 40.0:
            ex.turned_away += 1
        else:
            ex.turned_away, ex.turned_target = 1, ex.target
        if ex.turned_away < self.m.obstacle_turns:
            return False
        ex.turned_away, ex.turned_target = 0, None
        self._blacklist(ex.target)
        self._wait_map = True
        return True

    def _mind_the_obstacle(self, motion: Motion) -> Motion:
        """Shorten a move to stop ``stop_cm`` before an obstacle, or turn away from it."""
        assert self.grid is not None
        look = motion.amount + self.m.stop_cm
        ob = obstacle_ahead(self.grid, self.pose, look, half_angle_deg=20.0,
                            half_width_cm=0.5 * self.width_cm + 2.5)
        if ob is None:
            return motion
        room = ob.forward_cm - self.m.stop_cm
        if room >= 2.0:
            return Motion("move", min(motion.amount, room))
        # turn away: to the side opposite the obstacle's bearing
        return Motion("turn", -90.0 if ob.bearing_deg >= 0 else 90.0)

    def _choose(self, *, keep: bool) -> bool:
        """Choose a frontier and a route to it; False (and ``no_frontier``) when none."""
        assert self.grid is not None
        ex = self.ex
        pose = self.pose
        # after futile visits only long frontiers in the open still count (what an obstacle
        # hid in a big room), and each is blacklisted once reached (below), so this ends
        futile = self._futile()
        min_size = self.m.futile_min_cells if futile else self.m.min_frontier_cells
        # reachability with the narrowest tier the rover can drive (a corridor barely wider
        # than the body); the route itself tries the roomier tiers first
        radius, margin = self._tiers()[-1]
        frontiers = find_frontiers(self.grid, (pose.x, pose.y), robot_radius_cm=radius,
                                   margin_cm=margin, approach_cm=self.m.approach_cm)
        if futile:
            frontiers = [f for f in frontiers if f.open_share >= self.m.futile_open_share]
        for _ in range(self.m.max_choices):
            f = choose_frontier(frontiers, min_size_cells=min_size,
                                blacklist=ex.blacklist, blacklist_radius_cm=self.m.approach_cm)
            if f is None:
                ex.no_frontier = True
                ex.follower = None
                return False
            ex.no_frontier = False
            assert f.target_cm is not None
            if keep and ex.target is not None and math.dist(f.target_cm, ex.target) <= 40.0:
                return True  # still the same frontier: keep the route
            if any(math.dist(f.target_cm, r) <= self.m.reach_cm * 2 for r in ex.reached):
                self._blacklist(f.target_cm)  # reached and still a frontier: cannot be seen
                continue
            if self._route_to(f):
                return True
            self._blacklist(f.target_cm)
        ex.follower = None
        self._wait_map = True
        return False

    def _tiers(self) -> list[tuple[float, float]]:
        """(radius, margin) to plan with, roomiest first [cm]: turning radius plus margin,
        turning radius alone, half the body width plus the narrow margin (a corridor the
        rover fits through driving straight; the tiers of hiding and seeking), and half
        the body width alone: on a 5 cm grid a 30 cm corridor whose walls lie on cell
        edges maps 25 cm wide, and only this tier still finds the way through it (a
        scrape on the way is a blocked motion, and the route is replanned)."""
        r, m = self.radius_cm, self.o.plan_margin_cm
        half = 0.5 * self.width_cm
        out: list[tuple[float, float]] = []
        for t in ((r, m), (r, 0.0), (half, self.o.narrow_margin_cm), (half, 0.0)):
            if t not in out and t[0] + t[1] <= r + m:
                out.append(t)
        return out

    def _min_gain(self, known: int) -> float:
        return max(self.m.min_gain_cells, self.m.min_gain_share * known)

    def _futile(self) -> bool:
        """Whether the last ``futile_trips`` visits together revealed too little to go on.

        Judged on their sum (a running window), not on each: one visit just above the
        limit among small ones used to start the count over, and furniture 2 mapped on
        for 90-s trips gaining 21, 7, 4 and 34 cells (limit 32)."""
        g = self.ex.gains
        if len(g) < self.m.futile_trips:
            return False
        least = self._min_gain(self._known() if self.grid is not None else 0)
        return sum(g[-self.m.futile_trips:]) < least * self.m.futile_trips

    def _known(self) -> int:
        assert self.grid is not None
        return int(np.count_nonzero(self.grid.cells != UNKNOWN))

    def _route_to(self, f: Frontier) -> bool:
        assert self.grid is not None and f.target_cm is not None
        pose = self.pose
        plan = None
        for radius, margin in self._tiers():
            plan = plan_route(self.grid, (pose.x, pose.y), f.target_cm, radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                break
        if plan is None:
            return False
        ex = self.ex
        if ex.trip_known is None:  # a trip runs until a target is reached or given up
            ex.trip_known = self._known()
            ex.trip_started = trio.current_time()
        ex.follower = PathFollower(route_points(plan, (pose.x, pose.y)), None, self.o)
        ex.target = f.target_cm
        ex.steps = 0
        ex.blocks = 0
        ex.budget = ex.follower.budget(pose)
        return True

    def _end_trip(self) -> None:
        """A target was reached or given up: record what the trip made known.

        Switching to another frontier on the way (the map grew) does not end a trip,
        so a trip's gain is that of a whole visit, not of a few steps."""
        ex = self.ex
        if ex.trip_known is not None and self.grid is not None:
            ex.gains.append(self._known() - ex.trip_known)
            del ex.gains[:-self.m.futile_trips]
        ex.trip_known = None

    def _blacklist(self, point: tuple[float, float] | None) -> None:
        if point is None:
            return
        if point == self.ex.target:
            self._end_trip()
        bl = self.ex.blacklist
        bl.append(point)
        if len(bl) > self.m.blacklist:
            del bl[0]

    # ------------------------------------------------------------------ homing
    def _plan_home(self) -> bool:
        """A route back to the start pose (0, 0); False when there or no route is known."""
        assert self.grid is not None
        pose = self.pose
        if math.hypot(pose.x, pose.y) <= self.m.home_reach_cm:
            return False
        for radius, margin in self._tiers():
            plan = plan_route(self.grid, (pose.x, pose.y), (0.0, 0.0), radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                break
        else:
            return False
        ex = self.ex
        ex.follower = PathFollower(route_points(plan, (pose.x, pose.y)), None, self.o)
        ex.target = (0.0, 0.0)
        ex.steps = 0
        ex.budget = ex.follower.budget(pose)
        return True

    async def _home_step(self) -> None:
        """One ADP step home; uploads once home, or when home cannot be reached."""
        if self.state != "homing" or self.moving or not self.can_move or self.holding:
            return
        ex = self.ex
        pose = self.pose
        if ex.follower is None and not self._plan_home():
            await self._finish(self._finish_reason)
            return
        assert ex.follower is not None
        motion = ex.follower.next_motion(pose)
        if motion is None or math.hypot(pose.x, pose.y) <= self.m.home_reach_cm \
                or ex.steps >= ex.budget:
            await self._finish(self._finish_reason)
            return
        if motion.kind == "move":
            motion = self._mind_the_obstacle(motion)
            if motion.kind == "turn":
                ex.follower = None  # turned away from an obstacle: plan again from there
        ex.steps += 1
        await self.command(motion)

    async def _after_home_motion(self, blocked: bool) -> None:
        ex = self.ex
        if not blocked:
            await self._home_step()
            return
        ex.blocks += 1
        ex.follower = None
        if ex.blocks >= self.m.home_blocks:
            await self._finish(self._finish_reason + "; home blocked")
            return
        await self.command(Motion("move", -self.o.backoff_cm))

    # ------------------------------------------------------------------ finishing
    async def _finish(self, reason: str, *, home: bool = False) -> None:
        """End exploring: drive home first when ``home`` (see Homing), then upload."""
        if home and self.m.home_budget_s > 0 and self.grid is not None and self._plan_home():
            self._finish_reason = reason
            self._home_deadline = trio.current_time() + self.m.home_budget_s
            self.ex.blocks = 0
            await self.set_state("homing", f"{reason}; driving back to the start")
            await self._home_step()
            return
        self._home_deadline = math.inf
        await self.stop_motor()
        await self.post(self.lidar, Message.uint(Cmd.LIDAR_STOP, 0))
        await self.post(self.map_name, Message.uint(Cmd.MAP_GET, 0))
        self._finish_reason = reason
        self._upload_deadline = trio.current_time() + self.m.upload_wait_s
        await self.set_state("uploading", reason)

    async def _upload(self) -> None:
        self._upload_deadline = math.inf
        self.started = self.memory.started = False
        reason = self._finish_reason
        if self.grid is None or self.grid.known_bounds() is None:
            await self.set_state("idle", f"{reason}; nothing mapped to upload")
            return
        grid = self.grid.crop_known(margin_cells=1)
        await self.send_map(grid)
        known = int(np.count_nonzero(grid.cells != UNKNOWN))
        await self.set_state("mapped", f"{reason}; {known} cells known")
