"""Mapping navigation: frontier exploration with the ADP loop, and knowing when it is done.

The parts, one module each: `exploration` (where to go), `homing` (back to the
start), `sensor_watch` (holds for a faulty LIDAR or odometry), and their
tunables in `mapping_options`; this module is the actor and the completion test.

Flow
    idle --start--> scanning (LIDAR_START, wait for the first scans) -->
    exploring (frontier -> A* route -> ADP steps; re-choose every few steps as
    the map grows) --complete--> homing --> uploading; --stop | time budget-->
    uploading (MOTOR_STOP, LIDAR_STOP, MAP_GET, wait for the fresh snapshot) -->
    mapped (WIFLY_SEND_MAP with the map cropped to its known part).

Complete when both hold (either alone can lie)
    * no reachable viewpoint would reveal the least useful gain (`exploration`: what
      remains of the frontier cannot be seen from any pose the rover may stand on; a
      stalled LIDAR would also give "no change"); after ``FUTILE_TRIPS`` trips in a
      row that made fewer than ``MIN_GAIN_CELLS`` cells known each on average (a
      window, so one trip just above the limit does not start the count over), a
      viewpoint must promise as much as those trips together should have shown, and
    * the map's count of known cells has not moved for ``stable_window_s``
      while the scan count kept rising (a stalled LIDAR gives no scans, so it
      never reads as done).
    Or when the server says ``stop``, or after ``budget_s`` of mapping.

Restart
    The new incarnation asks Map Management for a snapshot (MAP_GET) and Motor
    Control for the pose, and takes its origin from `NavMemory`. Only navigation
    starts the LIDAR, so scans still arriving (NAV_SCAN_COUNT rising within
    ``PROBE_S``) prove mapping was under way: it resumes exploring from the
    current pose and map. The blacklist is lost, which costs at most a few
    wasted trips. A restarted Map Management (``NAV_MAP_LOST``) gets the origin
    back (``MAP_ORIGIN_*``: its scan matching correction) and the last snapshot.

Frames
    The map frame is the mapper's start frame [cm, deg]. Motor Control's pose is
    dead reckoning in the own (odometry) frame; Map Management's scan matching
    finds how far it drifted and sends the correction (``NAV_MAP_ORIGIN_XY`` +
    ``NAV_MAP_ORIGIN_HEADING``), which navigation keeps as its ``origin``
    (retained), so ``map_pose = compose(origin, pose)`` is what it plans, steers
    and reports by. The server's ``origin`` (the identity, with ``start``) does not
    set it: the map frame is the mapper's own start frame by definition, and
    only scan matching moves the origin.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import trio

from actors import BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import LidarHealth
from actors.firmware.drivers.tread_monitor import TreadFault
from actors.firmware.hardware import MAPPER, HardwareSpec
from actors.firmware.mapping.parked_body import with_parked_body
from actors.firmware.nav.base import NavBase
from actors.firmware.nav.exploration import Exploration, ExplorationState
from actors.firmware.nav.homing import Homing
from actors.firmware.nav.mapping_options import MappingOptions
from actors.firmware.nav.options import NavMemory, NavOptions
from actors.firmware.nav.sensor_watch import SensorWatch
from actors.firmware.origin_wire import MM, PoseHalves, pose_messages, xy_half
from server.protocol.grid_map import UNKNOWN, GridMap
from server.protocol.pose import ZERO_POSE

__all__ = ["MappingOptions", "MappingNav", "FIRST_SCANS", "CHANGE_CELLS",
           "CHANGE_SHARE", "PROBE_S", "UPLOAD_WAIT_S"]

# Counts, shares and fixed waits of the completion test and of a restart; the physical
# quantities are `MappingOptions`.
FIRST_SCANS = 3
"""Scan batches to wait for before the first move."""
CHANGE_CELLS = 3
"""The map changed when its count of known cells moved by more than this (or
``CHANGE_SHARE`` of it) since the last change; free/occupied flicker is not a change,
and neither is unknown/known flicker at the edges (scan matching's jitter at rest), which
nets out."""
CHANGE_SHARE = 0.002
"""Relative part of the change threshold (of the known cells)."""
PROBE_S = 3.0
"""After a restart, rising scan counts within this mean mapping was under way [s] (Map
Management publishes the count every 0.25 s while scans arrive)."""
UPLOAD_WAIT_S = 1.0
"""Wait at most this for a fresh snapshot before uploading the last one [s]."""


class MappingNav(NavBase):
    """The mapper's navigation actor (registered as ``mapper/nav``)."""

    role = MAPPER
    origin_from_server = False

    def __init__(self, *, pool: BufferPool, spec: HardwareSpec,
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
        self.ex = ExplorationState()
        """Exploration's state (the route, the target, the blacklist, the trips)."""
        self.changed_at = 0.0
        """Trio time of the last map change [s] (the stable window counts from it)."""
        self._known_at_change = 0  # known cells when the map last changed
        self._scans_at_start = 0
        self._started_at = 0.0
        self._probe_until = -math.inf
        self._probe_scans: int | None = None
        self._upload_deadline = math.inf
        self.wait_map = False
        """Decide at the next map update (or the next tick's look, about once a second)."""
        self.last_wait_decide = -math.inf
        """When the tick last looked again while waiting for the map [s]."""
        self.finish_reason = ""
        """Why mapping ended (said with the upload)."""
        self._home_deadline = math.inf
        self.lidar_fault: LidarHealth | None = None
        """The LIDAR fault being held for (`sensor_watch`), None when none."""
        self.lidar_faults = 0
        """LIDAR faults held for."""
        self.scan_rise_at = -math.inf
        """Trio time the scan count last rose [s]."""
        self.odometry_faults = 0
        """Odometry holds (`sensor_watch`)."""
        self.explorer = Exploration(self)
        """Where to go next: frontier exploration."""
        self.homing = Homing(self)
        """The way home once mapping completes by itself."""
        self.watch = SensorWatch(self)
        """The holds for a faulty LIDAR or odometry."""
        self._origin_halves = PoseHalves()  # NAV_MAP_ORIGIN_XY waiting for its heading

    # ------------------------------------------------------------------ dispatch
    async def handle(self, message: Any) -> Any:
        cmd = message.command if isinstance(message, Message) else None
        if cmd == Cmd.NAV_LIDAR_HEALTH:
            await self.watch.on_lidar_health(int(message.value))
        elif cmd == Cmd.NAV_TREAD_FAULT:
            await self.watch.on_tread_fault(TreadFault(int(message.value)))
        elif cmd == Cmd.NAV_TREAD_DRIVEN:
            await self.watch.relay_tread_driven(*xy_half(message, MM))
        elif cmd == Cmd.NAV_MAP_ORIGIN_XY:
            self._origin_halves.take_xy(message)
        elif cmd == Cmd.NAV_MAP_ORIGIN_HEADING:
            origin = self._origin_halves.take_heading(message)
            if origin is not None:
                self.set_origin(origin)
        else:
            return await super().handle(message)
        return None

    # ------------------------------------------------------------------ lifecycle
    async def on_restart(self) -> None:
        self.map_name = self.names.map
        self.lidar = self.names.lidar
        await self.post(self.map_name, Message.uint(Cmd.MAP_GET, 0))
        self._probe_until = trio.current_time() + PROBE_S
        if self.memory.started:  # the retained record says mapping was under way
            await self._begin(trio.current_time(), resumed=True)

    async def on_map_lost(self) -> None:
        # Map Management restarted empty: give it back what we knew (the origin first: it
        # drops scans until the origin arrives); its count restarts at 0
        self._probe_scans = None
        self._scans_at_start = self.scans = 0
        xy, heading = pose_messages(Cmd.MAP_ORIGIN_XY, Cmd.MAP_ORIGIN_HEADING,
                                    self.origin or ZERO_POSE)
        if await self.post(self.map_name, xy):
            await self.post(self.map_name, heading)
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
        self.changed_at = now
        self.scan_rise_at = now  # the LIDAR spins up: silence counts from here
        self.lidar_fault = None
        self.ex = ExplorationState()
        await self.post(self.lidar, Message.float(Cmd.LIDAR_START, self.m.lidar_duty))
        if resumed:
            await self.set_state("exploring", "resumed after a restart")
            self.wait_map = True
        else:
            await self.set_state("scanning", "waiting for the first scans")

    async def on_stop_cmd(self) -> None:
        if self.state in ("scanning", "exploring", "homing"):
            await self.finish("stopped by the server")

    # ------------------------------------------------------------------ map events
    async def on_map_update(self, grid: GridMap) -> None:
        prev = self.grid
        self.grid = grid
        now = trio.current_time()
        known = int(np.count_nonzero(grid.cells != UNKNOWN))
        if prev is None or prev.shape != grid.shape or abs(known - self._known_at_change) > max(
                CHANGE_CELLS, CHANGE_SHARE * known):
            self.changed_at = now
            self._known_at_change = known
        if self.state == "uploading":
            await self._upload()
        elif self.state == "scanning":
            await self._maybe_explore()
        elif self.state == "exploring" and self.wait_map and not self.moving:
            self.wait_map = False
            await self.explorer.decide()

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
            self.scan_rise_at = trio.current_time()
        self.scans = count
        if self.state == "scanning":
            await self._maybe_explore()

    async def _maybe_explore(self) -> None:
        if self.grid is not None and self.scans - self._scans_at_start >= FIRST_SCANS:
            await self.set_state("exploring", "frontier exploration")
            await self.explorer.decide()

    # ------------------------------------------------------------------ ticks
    async def on_tick(self, now: float) -> None:
        if self.state == "uploading" and now >= self._upload_deadline:
            await self._upload()
            return
        holding = await self.watch.lidar_watch(now)
        holding = await self.watch.odometry_watch(now) or holding
        if self.state == "homing":
            if now >= self._home_deadline:
                await self.finish(self.finish_reason + "; home not reached in time")
            elif not self.moving and not holding:
                await self.homing.home_step()
            return
        if self.state not in ("exploring", "scanning"):
            return
        if now - self._started_at >= self.m.budget_s:
            await self.finish(f"time budget of {self.m.budget_s:.0f} s used")
            return
        if self.state == "exploring" and not self.moving and not holding:
            if self.complete(now):
                await self.finish("no reachable frontier left and the map is stable",
                                   home=True)
            elif self.ex.no_frontier or self.wait_map:
                # waiting for the map to change; look again about once a second
                if now - self.last_wait_decide >= 1.0:
                    self.last_wait_decide = now
                    self.wait_map = False
                    await self.explorer.decide()

    @property
    def holding(self) -> bool:
        """Holding still: the LIDAR is faulty, or odometry is in doubt."""
        return self.watch.holding

    async def after_motion(self, blocked: bool, done: float) -> None:
        await self.explorer.after_motion(blocked, done)

    def complete(self, now: float) -> bool:
        """Both completion conditions: no useful frontier, and a map that has not changed
        for ``stable_window_s`` while not holding (a silent LIDAR holds)."""
        return (self.ex.no_frontier and not self.holding
                and now - self.changed_at >= self.m.stable_window_s)

    # ------------------------------------------------------------------ finishing
    async def finish(self, reason: str, *, home: bool = False) -> None:
        """End exploring: drive home first when ``home`` (see Homing), then upload."""
        if home and self.m.home_budget_s > 0 and self.grid is not None and self.homing.plan_home():
            self.finish_reason = reason
            self._home_deadline = trio.current_time() + self.m.home_budget_s
            self.ex.blocks = 0
            await self.set_state("homing", f"{reason}; driving back to the start")
            await self.homing.home_step()
            return
        self._home_deadline = math.inf
        await self.stop_motor()
        await self.post(self.lidar, Message.uint(Cmd.LIDAR_STOP, 0))
        await self.post(self.map_name, Message.uint(Cmd.MAP_GET, 0))
        self.finish_reason = reason
        self._upload_deadline = trio.current_time() + UPLOAD_WAIT_S
        await self.set_state("uploading", reason)

    async def _upload(self) -> None:
        self._upload_deadline = math.inf
        self.started = self.memory.started = False
        reason = self.finish_reason
        if self.grid is None or self.grid.known_bounds() is None:
            await self.set_state("idle", f"{reason}; nothing mapped to upload")
            return
        # it stays parked here: hider and seeker plan round it (`parked_body`)
        grid = with_parked_body(self.grid.crop_known(margin_cells=1), self.map_pose,
                                self.length_cm, self.width_cm)
        await self.send_map(grid)
        known = int(np.count_nonzero(grid.cells != UNKNOWN))
        await self.set_state("mapped", f"{reason}; {known} cells known")

