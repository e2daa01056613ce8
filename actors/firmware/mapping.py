"""Map Management (mapper): the occupancy grid built from LIDAR scans.

The seed's Map Management thread. ``MAP_SCAN`` brings a `lidar.Scan` by
handle (taking it releases the pool slot); it is fused into a log-odds
`OccupancyGrid` (5 cm cells by default: free along each ray, occupied at the
hit). Updates go to navigation, rate-limited to one per ``publish_s`` of sim
time: ``NAV_MAP_UPDATE`` (handle of an immutable `GridMap` snapshot) when a
cell changed class, and ``NAV_SCAN_COUNT`` (scan batches integrated so far)
whenever scans arrived, changed or not, so navigation can tell "map unchanged
while scans keep arriving" from "LIDAR stalled". ``MAP_GET`` publishes both
at once.

Restart: the grid is lost with the incarnation (it is the thread's working
memory). The new incarnation starts empty, integrates scans from then on and
tells navigation ``NAV_MAP_LOST``; navigation may answer ``MAP_RESTORE`` with
the last snapshot it received, whose known cells seed the cells the new grid
has not observed yet (what was seen since the restart wins). The scan count
starts again from 0 (``NAV_MAP_LOST`` tells navigation so).
"""

from __future__ import annotations

import numpy as np
import trio

from actors import Actor, BufferPool, Message, PoolExhausted

from .commands import Cmd
from .occupancy import FREE, OCCUPIED, UNKNOWN, GridMap, OccupancyGrid

__all__ = ["MapManagement"]


class MapManagement(Actor):
    """The ``mapper/map`` actor (see the module docstring).

    Args:
        pool: the rover's buffer pool (scans in, snapshots out).
        size_cm: grid extent (width, height) [cm], centred on the start.
        resolution_cm: cell side [cm].
        publish_s: at most one map update per this much sim time [s].
        restarted: True for an incarnation after the first (sends NAV_MAP_LOST).
    """

    def __init__(self, pool: BufferPool, *, size_cm: tuple[float, float] = (2400.0, 2400.0),
                 resolution_cm: float = 5.0, publish_s: float = 0.25,
                 restarted: bool = False) -> None:
        self.pool = pool
        self.grid = OccupancyGrid(size_cm[0], size_cm[1], resolution_cm)
        self.publish_s = publish_s
        self.restarted = restarted
        self.scans = 0
        """Scan batches integrated by this incarnation."""
        self.updates = 0
        """Snapshots sent to navigation."""
        self.dropped_updates = 0
        """Snapshots navigation's queue or the pool refused (the next one supersedes)."""
        self.noops = 0
        """NOOP messages ignored (what a flood fault posts)."""
        self._changed = True  # a cell changed class since the last update
        self._counted = 0  # scan count last sent
        self._last_publish = -float("inf")
        self._timer_armed = False

    async def on_start(self) -> None:
        prefix = self.ctx.name.rpartition("/")[0]
        self._nav = f"{prefix}/nav" if prefix else "nav"
        if self.restarted:
            self._send(self._nav, Message.uint(Cmd.NAV_MAP_LOST, 0))

    def _send(self, name: str, message: Message) -> bool:
        """``send_nowait`` to a neighbour; False when full or not registered (yet)."""
        system = self.ctx.system
        return system.whereis(name) is not None and system.send_nowait(name, message)

    async def handle(self, message: Message) -> None:
        cmd = message.command
        if cmd == Cmd.MAP_SCAN:
            scan = self.pool.take(int(message.value))
            if self.grid.integrate(scan.pose, scan.angles_deg, scan.ranges_cm):
                self._changed = True
            self.scans += 1
            self._maybe_publish()
        elif cmd == Cmd.MAP_GET:  # from navigation (value 0), or our deferred timer (1)
            if message.value == 1:
                self._timer_armed = False
                self._publish(force=False)
            else:
                self._publish()
        elif cmd == Cmd.MAP_RESTORE:
            self._restore(self.pool.take(int(message.value)))
            self._publish()
        elif cmd == Cmd.NOOP:
            self.noops += 1  # a flood fault: costs a queue slot, never a restart
        else:
            raise ValueError(f"map management got an unknown command 0x{cmd:04x}")

    def _maybe_publish(self) -> None:
        if not self._changed and self.scans == self._counted:
            return
        now = trio.current_time()
        wait = self._last_publish + self.publish_s - now
        if wait <= 0:
            self._publish(force=False)
        elif not self._timer_armed:  # publish the last change even if no scan follows
            self._timer_armed = True
            self.ctx.start_timer(wait, Message.uint(Cmd.MAP_GET, 1))

    def _publish(self, force: bool = True) -> None:
        """Send a snapshot (when something changed, or ``force``) and the scan count."""
        self._last_publish = trio.current_time()
        self._counted = self.scans
        if self._changed or force:
            self._send_snapshot()
        self._send(self._nav, Message.uint(Cmd.NAV_SCAN_COUNT, self.scans))

    def _send_snapshot(self) -> None:
        self._changed = False
        snap = self.grid.snapshot()
        try:
            handle = self.pool.put(snap)
        except PoolExhausted:
            self.dropped_updates += 1
            return
        if self._send(self._nav, Message.handle(Cmd.NAV_MAP_UPDATE, handle)):
            self.updates += 1
        else:
            self.pool.take(handle)
            self.dropped_updates += 1

    def _restore(self, snap: GridMap) -> None:
        """Seed cells this grid has not observed from ``snap`` (same resolution only)."""
        grid = self.grid
        if abs(snap.resolution_cm - grid.resolution_cm) > 1e-9:
            raise ValueError(f"MAP_RESTORE needs resolution {grid.resolution_cm} cm, "
                             f"got {snap.resolution_cm}")
        r0, c0 = grid.world_to_cell(snap.origin_cm[0] + 1e-6, snap.origin_cm[1] + 1e-6)
        ny, nx = snap.shape
        gy, gx = grid.shape
        rs, cs = max(0, r0), max(0, c0)
        re, ce = min(gy, r0 + ny), min(gx, c0 + nx)
        if rs >= re or cs >= ce:
            return
        src = snap.cells[rs - r0:re - r0, cs - c0:ce - c0]
        lo = grid._log_odds[rs:re, cs:ce]  # noqa: SLF001 - the grid's own storage
        own = grid.cells()[rs:re, cs:ce]
        fill = own == UNKNOWN
        m = grid.model
        lo[fill & (src == FREE)] = m.l_min
        lo[fill & (src == OCCUPIED)] = m.l_max
        self._changed = bool(np.any(fill & (src != UNKNOWN)))
