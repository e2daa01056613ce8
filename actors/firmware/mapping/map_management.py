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

Scan matching (why: see `scan_match`)
    Scans come stamped with the raw odometry pose. Each batch is placed at
    ``correction (+) odometry`` and, once the first ``warmup_scans`` batches
    made a reference, registered against the obstacle surfaces of the map
    built so far; an accepted match updates the correction (odometry -> map
    frame). The matching fields are rebuilt from the grid at most every
    ``fields_s``. The correction goes to navigation (``NAV_MAP_ORIGIN_XY`` +
    ``NAV_MAP_ORIGIN_HEADING``) with the published updates: navigation keeps
    it as its ``origin`` (map -> odometry), so its map-frame pose is the
    correction composed with Motor Control's odometry pose.

Re-localisation
    A stuck or slipping encoder can turn the rover further than matching may
    correct (``max_turn_deg``): then every batch that sees the map is refused
    and the pose never comes back. After ``_RELOCALISE_AFTER`` such batches in
    a row whose guess fits badly, `scan_match.relocalise` searches headings
    within 24 deg (at most every ``_RELOCALISE_EVERY_S``; about 24 ms each).

Restart: the grid is lost with the incarnation (it is the thread's working
memory). The new incarnation starts empty, integrates scans from then on and
tells navigation ``NAV_MAP_LOST``; navigation may answer ``MAP_RESTORE`` with
the last snapshot it received, whose known cells seed the cells the new grid
has not observed yet (what was seen since the restart wins). The scan count
starts again from 0 (``NAV_MAP_LOST`` tells navigation so). The correction
is asked back from navigation, which keeps it as its origin in retained
memory (it answers ``NAV_MAP_LOST`` with ``MAP_ORIGIN_XY`` +
``MAP_ORIGIN_HEADING``); scans arriving before it (at most
``_CORRECTION_WAIT_S``) are dropped, not placed in the wrong frame.

Flood: ``NOOP`` is ignored (counted in `noops`), so a flood fault costs
queue slots and dropped scans, never a restart.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import trio

from actors import Actor, BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.arrays import pad_border
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import Scan
from actors.firmware.handles import post
from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.mapping.scan_match import (
    BLUR_WIDE,
    MatchFields,
    MatchOptions,
    MatchResult,
    hits_to_local,
    match_scan,
    relocalise,
)
from actors.firmware.origin_wire import OriginHalves, pose_messages
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose, angle_diff_deg, compose, inverse

__all__ = ["MapManagement"]

_MATCH = MatchOptions()  # immutable default
_CORRECTION_WAIT_S = 1.0  # a restarted map waits this long for navigation's copy of the correction
_RELOCALISE_AFTER = 3  # supported batches refused in a row before the wider search
_RELOCALISE_EVERY_S = 0.5  # at most one wider search per this much time [s] (24 ms each)
_RELOCALISE_BELOW = 0.6  # ...and only when the guess scores below this (lost poses: 0.3-0.45)
_LOST_MAX_S = 30.0  # after MAP_POSE_LOST, place no batch for at most this long [s]
_LOST_EVERY_S = 0.5  # ...and search for the pose at most this often (a full turn: ~0.2 s CPU)
_LOST_AGREE_CM = 8.0  # two searches in a row must agree on the correction this well [cm]
_LOST_AGREE_DEG = 3.0  # ...and [deg]


def _max3(values: np.ndarray) -> np.ndarray:
    """Maximum over each cell's 3 x 3 neighbourhood."""
    p = pad_border(values)
    rows = np.maximum(np.maximum(p[:-2], p[1:-1]), p[2:])
    return np.maximum(np.maximum(rows[:, :-2], rows[:, 1:-1]), rows[:, 2:])


def _same_pose(a: Pose, b: Pose | None) -> bool:
    """Whether two odometry stamps are the same (within 5 mm and 0.3 deg; headings
    compared across the wrap, so 179.9 and -179.9 deg are the same)."""
    return b is not None and abs(a.x - b.x) < 0.5 and abs(a.y - b.y) < 0.5 and abs(
        angle_diff_deg(a.heading_deg, b.heading_deg)) < 0.3


class MapManagement(Actor):
    """The ``mapper/map`` actor (see the module docstring).

    Args:
        pool: the rover's buffer pool (scans in, snapshots out).
        size_cm: grid extent (width, height) [cm], centred on the start.
        resolution_cm: cell side [cm].
        publish_s: at most one map update per this much sim time [s].
        restarted: True for an incarnation after the first (sends NAV_MAP_LOST).
        matching: scan-to-map matching options; None turns matching off.
        fields_s: rebuild the matching fields from the grid at most this often [s].
        warmup_scans: integrate this many batches unmatched first (the reference).
        settle_s: a batch is placed unmatched (the correction kept) only when odometry
            has not changed between batches for this long [s] and the last matched
            batch was taken at the same odometry pose: the rover stands.
    """

    def __init__(self, pool: BufferPool, *, size_cm: tuple[float, float] = (2400.0, 2400.0),
                 resolution_cm: float = 5.0, publish_s: float = 0.25,
                 restarted: bool = False, matching: MatchOptions | None = _MATCH,
                 fields_s: float = 0.5, warmup_scans: int = 20, settle_s: float = 1.0,
                 addresses: Addresses | None = None) -> None:
        self.pool = pool
        self._addresses = addresses
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
        self.matching = matching
        self.fields_s = fields_s
        self.warmup_scans = warmup_scans
        self.settle_s = settle_s
        self._prev_odom: Pose | None = None  # odometry pose of the previous batch
        self._still_since = -float("inf")  # time odometry last changed between two batches
        self.correction = Pose()
        """Odometry frame -> map frame, from scan matching (identity until a match)."""
        self.matched = 0
        """Scan batches placed by a match (the others at the corrected odometry pose)."""
        self._fields: MatchFields | None = None
        self._fields_at = -float("inf")
        self._fields_stale = True  # the grid changed since the fields were built
        self._last_odom: Pose | None = None  # odometry pose of the last matched batch
        self._sent_correction = Pose()  # the correction navigation has (as far as we know)
        self._origin_halves = OriginHalves()  # MAP_ORIGIN_XY waiting for its heading
        # a restarted incarnation waits (a bounded time) for the correction navigation kept
        self._await_correction_until = -float("inf")
        self.unplaced = 0
        """Batches dropped because they see the map but match nowhere near dead reckoning."""
        self.held_scans = 0
        """Batches dropped while waiting for the correction after a restart."""
        self.relocalised = 0
        """Batches placed by the wider search (`scan_match.relocalise`)."""
        self._refused = 0  # supported batches refused in a row
        self._lost_until = -float("inf")  # MAP_POSE_LOST: no batch placed before a re-find
        self._lost_deg = 180.0  # ...and how far the heading may be off [deg]
        self._lost_candidate: Pose | None = None  # the correction the last search found
        self.lost_scans = 0
        """Batches dropped while the pose was lost (MAP_POSE_LOST, not found again yet)."""
        self.refound = 0
        """Times the pose was found again after MAP_POSE_LOST."""
        self._relocalise_at = -float("inf")  # time of the last wider search
        self._changed = True  # a cell changed class since the last update
        self._counted = 0  # scan count last sent
        self._last_publish = -float("inf")
        self._timer_armed = False

    async def on_start(self) -> None:
        names = self._addresses or Addresses.beside(self.ctx.name)
        self._nav = names.nav
        if self.restarted and self._send(self._nav, Message.uint(Cmd.NAV_MAP_LOST, 0)):
            self._await_correction_until = trio.current_time() + _CORRECTION_WAIT_S

    def _send(self, name: str, message: Message) -> bool:
        """``send_nowait`` to a neighbour; False when full or not registered (yet)."""
        system = self.ctx.system
        return system.whereis(name) is not None and system.send_nowait(name, message)

    def discard(self, message: Message) -> None:
        """A dropped poison message gives its pool buffer back (the handler may have taken it)."""
        if message.command in (Cmd.MAP_SCAN, Cmd.MAP_RESTORE):
            with contextlib.suppress(KeyError):
                self.pool.take(int(message.value))

    async def handle(self, message: Message) -> None:
        cmd = message.command
        if cmd == Cmd.MAP_SCAN:
            scan = self.pool.take(int(message.value))
            if trio.current_time() < self._await_correction_until:
                self.held_scans += 1  # placed in the wrong frame, it would smear the map
                return
            pose = self._place(scan)
            if pose is None:
                self.unplaced += 1  # it sees mapped walls but fits nowhere: a bad pose
                return
            if self.grid.integrate(pose, scan.angles_deg, scan.ranges_cm):
                self._changed = self._fields_stale = True
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
        elif cmd == Cmd.MAP_ORIGIN_XY:
            self._origin_halves.take_xy(message)
        elif cmd == Cmd.MAP_ORIGIN_HEADING:
            # only a restarted incarnation waits for navigation's copy; any other is stale
            origin = self._origin_halves.take_heading(message)
            if origin is not None and trio.current_time() < self._await_correction_until:
                self.correction = self._sent_correction = origin
            self._await_correction_until = -float("inf")
        elif cmd == Cmd.MAP_POSE_LOST:
            self._lost_until = trio.current_time() + _LOST_MAX_S
            self._lost_deg = float(min(180, max(int(message.value), 6)))
            self._relocalise_at = -float("inf")
            self._lost_candidate = None
        elif cmd == Cmd.NOOP:
            self.noops += 1  # a flood fault: costs a queue slot, never a restart
        else:
            raise ValueError(f"map management got an unknown command 0x{cmd:04x}")

    def _place(self, scan: Scan) -> Pose | None:
        """The map-frame pose of a batch: corrected odometry, refined by scan matching.

        A batch keeps the correction unmatched when the rover stands: odometry has not
        changed for ``settle_s`` and the last matched batch was taken at the same
        odometry pose (within 5 mm and 0.3 deg); so does one that cannot be matched
        (too few hits, unmapped view). An unchanged odometry stamp alone does not
        mean the rover stands: one Int E turns the heading by 2.2 deg, so a turning
        rover's batch can carry the previous tick's stamp, and after a turn the rover
        keeps turning by up to an interrupt's worth (or swings back) unseen by its
        encoders. Placed without matching, such batches were 2-9 deg off and drew
        walls a cell or two off (in a furnished room: map accuracy 0.968 against
        0.996 with the matched batches alone).
        None for a batch that sees mapped obstacles but whose match was refused: its
        pose is in doubt, and one badly placed batch clears free space through walls
        (outside the room, where no later ray can repair it).
        """
        odom = scan.pose
        guess = compose(self.correction, odom)
        opts = self.matching
        now = trio.current_time()
        if not _same_pose(odom, self._prev_odom):
            self._still_since = now
        self._prev_odom = odom
        if now < self._lost_until and opts is not None and self.scans >= self.warmup_scans:
            return self._refind(scan, guess, odom, opts, now)
        if opts is None or self.scans < self.warmup_scans or (
                now - self._still_since >= self.settle_s and _same_pose(odom, self._last_odom)):
            return guess  # standing still: matching again would only add its own jitter
        fields = self._current_fields(opts, now)
        pts = hits_to_local(scan.angles_deg, scan.ranges_cm, opts)
        result = match_scan(fields, pts, guess, opts)
        if not result.accepted and result.supported:
            result = self._relocalise(pts, guess, result, now)
        if not result.accepted:
            return None if result.supported else guess
        return self._accept(result.pose, odom)

    def _current_fields(self, opts: MatchOptions, now: float) -> MatchFields:
        """The matching fields, rebuilt first when stale for ``fields_s`` (or never built)."""
        if self._fields is None or (self._fields_stale and now - self._fields_at >= self.fields_s):
            self._build_fields(opts, now)
        assert self._fields is not None
        return self._fields

    def _accept(self, pose: Pose, odom: Pose) -> Pose:
        """A batch placed at ``pose`` by matching: the correction follows it."""
        self._refused = 0
        self.matched += 1
        self._last_odom = odom
        self.correction = compose(pose, inverse(odom))
        return pose

    def _refind(self, scan: Scan, guess: Pose, odom: Pose, opts: MatchOptions, now: float
                ) -> Pose | None:
        """A batch while the pose is lost (``MAP_POSE_LOST``): placed only when the wide
        search (`scan_match.relocalise`, headings within ``_lost_deg`` of the guess) finds
        where it fits; then the pose is found and matching goes on from there.

        Why: both encoders stuck while the treads are driven (for 9 s, say) turn the
        rover unseen; odometry stands still, so every batch would be placed unmatched
        at the standing pose ("the rover stands") while the rover spins: each draws
        the room turned by a different angle, and matching later locks onto that smear 180
        deg off (map accuracy about 0.5, hiding spots inside
        phantom walls). Navigation knows it from Motor Control's report (both treads
        silent in a turn) and says so; a batch that cannot be placed is dropped, as a
        refused match is (`_place`).
        """
        fields = self._current_fields(opts, now)
        if now - self._relocalise_at < _LOST_EVERY_S:
            self.lost_scans += 1
            return None
        self._relocalise_at = now
        pts = hits_to_local(scan.angles_deg, scan.ranges_cm, opts)
        wide = relocalise(fields, pts, guess, opts, turn_deg=self._lost_deg)
        if not wide.accepted:
            self.lost_scans += 1
            return None
        found = compose(wide.pose, inverse(odom))  # the correction it implies
        seen, self._lost_candidate = self._lost_candidate, found
        if seen is None or math.hypot(found.x - seen.x, found.y - seen.y) > _LOST_AGREE_CM or \
                abs(angle_diff_deg(found.heading_deg, seen.heading_deg)) > _LOST_AGREE_DEG:
            self.lost_scans += 1  # one batch (a 100 deg sector) alone can fit a smear
            return None
        self._lost_until = -float("inf")
        self._lost_candidate = None
        self.refound += 1
        return self._accept(wide.pose, odom)

    def _relocalise(self, pts: np.ndarray, guess: Pose, refused: MatchResult, now: float
                    ) -> MatchResult:
        """After a few supported batches refused in a row, each with a guess that fits
        badly (the pose is lost: a stuck or slipping encoder), try the wider search, at
        most every ``_RELOCALISE_EVERY_S``.

        A refused batch whose guess fits well (``_RELOCALISE_BELOW``) says the pose is
        right (matching only found no better fit) and starts the count over. Counting it,
        two such batches and one blurred by the start of a turn (fit 0.45) are enough
        to start a search in a healthy hall, which can accept a pose 23 deg off and
        draw the rest of the map turned by that much (accuracy 0.82).
        """
        if refused.score_guess >= _RELOCALISE_BELOW:
            self._refused = 0  # a guess that fits this well is not lost
            return refused
        self._refused += 1
        if self._refused < _RELOCALISE_AFTER or now - self._relocalise_at < _RELOCALISE_EVERY_S:
            return refused
        self._relocalise_at = now
        assert self._fields is not None
        wide = relocalise(self._fields, pts, guess, self.matching)
        if wide.accepted:
            self.relocalised += 1
            return wide
        return refused

    def _build_fields(self, opts: MatchOptions, now: float) -> None:
        """Matching fields of the grid's obstacle surfaces (known part only).

        The returns splatted on the cell centres (`OccupancyGrid.hit_counts`) near
        occupied cells, relative to the most hit centre around (3 x 3): where the
        returns fell, not which cells are occupied, says where a wall's face is. A face
        on a cell edge weighs on both sides equally, so the ridge lies on the edge; the
        band a wall grows behind its face (returns a little beyond it are never cleared
        by rays from behind) holds few returns, so it barely pulls.
        """
        grid = self.grid
        lo = grid.log_odds()
        m = grid.model
        occupied = lo > m.occ_threshold
        rows = np.flatnonzero(occupied.any(axis=1))
        res = grid.resolution_cm
        if rows.size == 0:
            self._fields = MatchFields(occupied[:1, :1], grid.origin_cm, res)
        else:
            cols = np.flatnonzero(occupied.any(axis=0))
            k = BLUR_WIDE + 2
            r0, r1 = max(0, int(rows[0]) - k), int(rows[-1]) + k + 1
            c0, c1 = max(0, int(cols[0]) - k), int(cols[-1]) + k + 1
            near_occ = _max3(occupied[r0:r1, c0:c1].astype(np.float32)) > 0
            hits = np.where(near_occ, grid.hit_counts()[r0:r1, c0:c1], 0.0)
            weights = hits / np.maximum(_max3(hits), 1.0)
            origin = (grid.origin_cm[0] + c0 * res, grid.origin_cm[1] + r0 * res)
            self._fields = MatchFields(weights, origin, res)
        self._fields_at = now
        self._fields_stale = False

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
        self._send_correction()

    def _send_correction(self) -> None:
        """Tell navigation the correction (its origin) when it moved by a cm or half a
        degree (less is below what navigation steers by)."""
        c, old = self.correction, self._sent_correction
        if abs(c.x - old.x) < 1.0 and abs(c.y - old.y) < 1.0 and abs(
                c.heading_deg - old.heading_deg) < 0.5:
            return
        xy, heading = pose_messages(Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING, c)
        if self._send(self._nav, xy) and self._send(self._nav, heading):
            self._sent_correction = c

    def _send_snapshot(self) -> None:
        self._changed = False
        snap = self.grid.snapshot()
        if post(self.pool, lambda m: self._send(self._nav, m), Cmd.NAV_MAP_UPDATE, snap):
            self.updates += 1
        else:
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
        self._changed = grid.fill_unknown(rs, cs, src)
