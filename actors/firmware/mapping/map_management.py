"""Map Management (mapper): the occupancy grid built from LIDAR scans.

The seed's Map Management thread; [mapping.md](../../../docs/mapping.md) says
why each step is as it is. ``MAP_SCAN`` brings a `lidar.Scan` (a batch of one
world tick, stamped with the raw odometry pose) by handle. Map Management

* **windows** the batches (`scan_window`): after the first ``warmup_scans``
  (the reference, fused one by one), consecutive batches are gathered into a
  window of about a revolution, de-skewed into its last batch's frame and cut
  before a turn, after a revolution's sweep or travel, at a motion's end (the
  third batch in a row whose stamp did not move after one that did), before a
  tread report, a restore or navigation's ``MAP_GET``, and when the rover
  starts or stops standing;
* **processes** a window only after enough motion (`_due`: ``update_min_cm``
  or ``update_min_deg`` of counted odometry since the last window placed, as
  Nav2 AMCL's ``update_min_d`` / ``update_min_a``) or when something requires
  it; a window between only predicts and is dropped from the grid;
* **matches** a processed window against the map built so far
  (`scan_match.match_scan` from the belief's mean, or `scan_match.relocalise`
  over the belief's bounds when it is wider than the local match reaches, at
  most every ``_SEARCH_EVERY_S``), the fields rebuilt from the grid at most
  every ``fields_s`` (`map_fields`); judges the match by the scan likelihood
  and the belief's gate, and lets the pose belief
  (`localisation.mapper_localiser.MapperLocaliser`, which it feeds with every
  stamp and tread report) place it; a refused window is dropped, its reason
  counted (`refusals`: data for metrics, never a trigger);
* **integrates** a placed window into the log-odds `OccupancyGrid`, each beam
  from its own batch's pose;
* **publishes** to navigation (`map_publisher`): snapshots, the scan count and
  the correction (odometry -> map frame, navigation's ``origin``).

Restart: the grid is lost with the incarnation (it is the thread's working
memory). The new incarnation starts empty and tells navigation
``NAV_MAP_LOST``; navigation may answer ``MAP_RESTORE`` with the last snapshot
it received, whose known cells seed the cells the new grid has not observed
(`map_fields.restore_unknown`), and answers with the correction it keeps
(``MAP_ORIGIN_XY`` + ``MAP_ORIGIN_HEADING``); scans arriving before it (at most
``_CORRECTION_WAIT_S``) are dropped, not placed in the wrong frame.

Flood: ``NOOP`` is ignored (counted in `noops`), so a flood fault costs
queue slots and dropped scans, never a restart.
"""

from __future__ import annotations

import contextlib
import math
from collections import Counter

import numpy as np
import trio

from actors import Actor, BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import Scan
from actors.firmware.hardware import HardwareSpec
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.mapper_localiser import MapperLocaliser
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.localisation.odometry_fault import OdometryFaultNoise
from actors.firmware.localisation.scan_likelihood import (
    FitVerdict,
    ScanOptions,
    gate_fit,
    judge_fit,
    odometry_floor,
)
from actors.firmware.mapping.map_fields import build_fields, restore_unknown
from actors.firmware.mapping.map_publisher import MapPublisher
from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.mapping.scan_match import (
    MatchFields,
    MatchOptions,
    match_scan,
    relocalise,
)
from actors.firmware.mapping.scan_window import ScanWindow, same_stamp
from actors.firmware.origin_wire import MM, PoseHalves, xy_half
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["MapManagement"]

_MATCH = MatchOptions()  # immutable default
_NOISE = MotionNoise()  # immutable default
_FAULT = OdometryFaultNoise()  # immutable default
_CORRECTION_WAIT_S = 1.0  # a restarted map waits this long for navigation's copy of the correction
_SEARCH_EVERY_S = 0.5  # at most one wide search per this much time [s] (a CPU bound: 24 ms
# for the default 24 deg either side, about 0.2 s for a whole turn)
_SCAN = ScanOptions()  # immutable default: the scan likelihood's noise levels
UPDATE_MIN_CM = 8.0
"""A window is processed (matched, judged, fused) once the counted odometry moved this far
since the last window placed [cm] (Nav2 AMCL's ``update_min_d``, gmapping's
``linearUpdate``)."""
UPDATE_MIN_DEG = 10.0
"""... or turned this much [deg] (AMCL's ``update_min_a``, gmapping's ``angularUpdate``)."""
_END_BATCHES = 3  # a motion ends at the 3rd batch in a row whose stamp did not change (a
# pause of a batch or two within a drive or a slow turn is no end)


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
        settle_s: a window is placed unmatched (the correction kept) only when odometry
            has not changed between batches for this long [s] and the last matched
            window ended at the same odometry pose: the rover stands.
        spec: the rover's calibration constants: the track width (the motion model's
            geometry) and a tread's travel per Int E (with the track, the
            dead-reckoned heading's quantum a window's drive heading spans).
        noise: the motion model's noise levels.
        fault_noise: the prior of the "odometry broke unseen" hypothesis.
    """

    def __init__(self, pool: BufferPool, spec: HardwareSpec, *,
                 size_cm: tuple[float, float] = (2400.0, 2400.0),
                 resolution_cm: float = 5.0, publish_s: float = 0.25,
                 restarted: bool = False, matching: MatchOptions | None = _MATCH,
                 fields_s: float = 0.5, warmup_scans: int = 20, settle_s: float = 1.0,
                 update_min_cm: float = UPDATE_MIN_CM, update_min_deg: float = UPDATE_MIN_DEG,
                 noise: MotionNoise = _NOISE,
                 fault_noise: OdometryFaultNoise = _FAULT,
                 addresses: Addresses | None = None) -> None:
        self.pool = pool
        self._addresses = addresses
        self.grid = OccupancyGrid(size_cm[0], size_cm[1], resolution_cm)
        self.publisher = MapPublisher(pool, publish_s)
        """The updates to navigation (snapshots, the scan count, the correction)."""
        self.restarted = restarted
        self.scans = 0
        """Scan batches taken by this incarnation: fused, or in a window that only
        predicted (`_due`); a dropped window's are counted in `refusals`."""
        self.noops = 0
        """NOOP messages ignored (what a flood fault posts)."""
        self.matching = matching
        self.fields_s = fields_s
        self.warmup_scans = warmup_scans
        self.settle_s = settle_s
        self.update_min_cm = update_min_cm
        self.update_min_deg = update_min_deg
        self._quantum_deg = spec.heading_quantum_deg
        self._prev_odom: Pose | None = None  # odometry pose of the previous batch
        self._still_since = -float("inf")  # time odometry last changed between two batches
        self.localiser = MapperLocaliser(
            spec.track_width_cm, noise, fault_noise,
            matching.max_shift_cm if matching is not None else _MATCH.max_shift_cm)
        """The pose belief, and from it the correction (odometry -> map frame)."""
        self.matched = 0
        """Windows of batches placed by a match (the others at the belief's mean)."""
        self.windows = 0
        """Windows of batches fused into the grid (`scan_window`; a batch of the
        reference is a window of its own)."""
        self.predicted = 0
        """Windows only predicted (the rover moved less than ``update_min_cm`` and turned
        less than ``update_min_deg`` since the last window placed; `_due`)."""
        self._updated_odom: Pose | None = None  # the frame of the last window placed
        self.searched = 0
        """Windows placed by the wide search (`scan_match.relocalise`)."""
        self.refusals: Counter[str] = Counter()
        """Batches dropped (a window counts its batches), by reason: a matched pose the
        scan likelihood refused (`FitVerdict`'s value), a match refused by the matcher,
        or a wide belief that the window could not settle. Data for metrics, never a
        trigger."""
        self.held_scans = 0
        """Batches dropped while waiting for the correction after a restart."""
        self._fields: MatchFields | None = None
        self._distance: DistanceField | None = None
        self._fields_at = -float("inf")
        self._fields_stale = True  # the grid changed since the fields were built
        self._last_odom: Pose | None = None  # last odometry stamp of the last matched window
        self._origin_halves = PoseHalves()  # MAP_ORIGIN_XY waiting for its heading
        # a restarted incarnation waits (a bounded time) for the correction navigation kept
        self._await_correction_until = -float("inf")
        self._search_at = -float("inf")  # time of the last wide search
        self._window = ScanWindow(self._quantum_deg)  # batches to fuse as one (`scan_window`)
        self._window_standing = False  # whether they were taken while the rover stood
        self._still = 0  # batches in a row whose stamp did not change from the one before

    @property
    def unplaced(self) -> int:
        """Batches dropped (all reasons together)."""
        return sum(self.refusals.values())

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
            now = trio.current_time()
            if now < self._await_correction_until:
                self.held_scans += 1  # placed in the wrong frame, it would smear the map
                return
            self._take_batch(scan, now)
        elif cmd == Cmd.MAP_GET:  # from navigation (value 0), or our deferred timer (1)
            if message.value == 1:
                self.publisher.timer_armed = False
                self._publish(force=False)
            else:
                self._flush()  # navigation wants the map as it is now (an upload)
                self._publish()
        elif cmd == Cmd.MAP_RESTORE:
            self._flush()
            self._restore(self.pool.take(int(message.value)))
            self._publish()
        elif cmd == Cmd.MAP_ORIGIN_XY:
            self._origin_halves.take_xy(message)
        elif cmd == Cmd.MAP_ORIGIN_HEADING:
            # only a restarted incarnation waits for navigation's copy; any other is stale
            origin = self._origin_halves.take_heading(message)
            if origin is not None and trio.current_time() < self._await_correction_until:
                self.localiser.restart_at(origin)
                self.publisher.sent_correction = origin
            self._await_correction_until = -float("inf")
        elif cmd == Cmd.MAP_TREAD_FAULT:
            left_cm, right_cm = xy_half(message, MM)  # one length per tread (`length_pair`)
            self._flush()  # the batches before the report are placed as the counts say
            self._tread_fault(left_cm, right_cm)
        elif cmd == Cmd.NOOP:
            self.noops += 1  # a flood fault: costs a queue slot, never a restart
        else:
            raise ValueError(f"map management got an unknown command 0x{cmd:04x}")

    def _tread_fault(self, left_cm: float, right_cm: float) -> None:
        """Motor Control reported a tread (or both) in the motion that just ended; the
        travel each was driven beyond its count widens the belief
        (`MapperLocaliser.tread_fault`).

        The report comes as the PWM stops and predicts the pose at rest (the drive
        model's travel includes the coast), while the rover still coasts, unseen by an
        encoder that does not count. So for ``settle_s`` after it no wide search runs (a
        batch taken mid-coast fits where the rover was then, not where it comes to
        rest), and the rover counts as standing only ``settle_s`` after it (the frozen
        stamps of stuck encoders say nothing of whether it moves)."""
        now = trio.current_time()
        if self.localiser.tread_fault(left_cm, right_cm, now):
            self._still_since = now

    def _predict(self, odom: Pose) -> None:
        """Move the belief to the stamp ``odom`` when it moved (`MapperLocaliser.predict`)."""
        stamp = self.localiser.stamp
        if stamp is None or not same_stamp(odom, stamp):
            self.localiser.predict(odom)

    def wide(self, opts: MatchOptions) -> bool:
        """Whether the belief is wider than the local match reaches (its 95 % heading over
        ``max_turn_deg`` or its 95 % radius over ``max_shift_cm``): then only the wide
        search may place a window."""
        return self.localiser.wide(opts.max_turn_deg, opts.max_shift_cm)

    def _take_batch(self, scan: Scan, now: float) -> None:
        """Add a batch to the window, and fuse the window when it is cut (the module
        docstring, `scan_window`; [mapping.md](../../../docs/mapping.md) "Which windows
        are matched" says when the rover stands, and why an unchanged stamp alone does
        not say it). The third batch in a row whose stamp did not change after one that
        did ends a motion: the window is cut and processed there. A cut window is
        processed or only predicts as `_due` says.
        """
        odom = scan.pose
        moved = not same_stamp(odom, self._prev_odom)
        still_before = self._still
        self._still = 0 if moved else self._still + 1
        ended = self._still == _END_BATCHES
        if moved:
            self._still_since = now
        self._prev_odom = odom
        opts = self.matching
        if opts is None or self.scans + len(self._window) < self.warmup_scans:
            self._predict(odom)  # the reference is built batch by batch
            window = ScanWindow(self._quantum_deg)
            window.add(scan)
            self._fuse(window, now, standing=False)
            return
        # (evaluated before the prediction: a batch whose stamp moved never stands, and
        # one whose stamp did not leaves the belief where it is)
        standing = not self.wide(opts) and now - self._still_since >= self.settle_s and (
            same_stamp(odom, self._last_odom))
        if self._window and (standing != self._window_standing
                             or not self._window.fits(scan)):
            self._flush(now, required=standing != self._window_standing, still=still_before)
        self._predict(odom)
        self._window.add(scan)
        self._window_standing = standing
        if ended or self._window.full():
            self._flush(now, required=ended, still=self._still)

    def _flush(self, now: float | None = None, *, required: bool = True,
               still: int = 0) -> None:
        """Process the window gathered so far (if any) when ``required`` or `_due` (its
        last ``still`` batches in a row kept their stamp), else let it only predict; start
        a new one."""
        window = self._window
        if not window:
            return
        self._window = ScanWindow(self._quantum_deg)
        if required or self._due(window, still):
            self._fuse(window, trio.current_time() if now is None else now,
                       standing=self._window_standing)
        else:
            self._predict_only(window)

    def _due(self, window: ScanWindow, still: int) -> bool:
        """Whether a window is processed (matched, judged, fused): the rover moved at least
        ``update_min_cm`` or turned at least ``update_min_deg`` (counted odometry, the
        window's frame against the last placed window's: after a refused window the next
        is processed too, else a run of refusals would leave the belief uncorrected for
        many times the distance, as in a corridor whose walls hold the match to few
        fits); or its stamps stood still since a motion's end (every batch of it kept the
        stamp, ``still`` covering the window and a motion's end: a stopped rover is matched
        until it stands, as stuck encoders freeze the stamps of a rover that moves on); or
        it stands; or the belief is wider than the local match reaches (only a scan
        settles it); or no window was processed yet."""
        opts = self.matching
        last = self._updated_odom
        if opts is None or last is None or self._window_standing or self.wide(opts) or (
                still >= max(len(window), _END_BATCHES)):
            return True
        frame = window.frame
        return math.hypot(frame.x - last.x, frame.y - last.y) >= self.update_min_cm or abs(
            angle_diff_deg(frame.heading_deg, last.heading_deg)) >= self.update_min_deg

    def _predict_only(self, window: ScanWindow) -> None:
        """A window between updates: the belief keeps the odometry's prediction (each
        batch moved it already) and the window is dropped from the grid (fused at the
        predicted pose, windows smeared the map: cluttered seed 1's accuracy 0.987, hall's
        0.981, against 0.9996 and 0.999 dropped); the next processed window sees the same
        walls. Its batches count as taken (navigation reads a rising count as a live
        LIDAR)."""
        self.scans += len(window)
        self.predicted += 1
        self._maybe_publish()

    def _fuse(self, window: ScanWindow, now: float, *, standing: bool) -> None:
        """Place a window and fuse it into the grid (each beam from its own batch's
        origin), or drop it when its pose is in doubt."""
        pose = self._place(window, now, standing)
        if pose is None:
            return  # its pose is in doubt (the reason is counted in `refusals`)
        self._updated_odom = window.frame
        angles, ranges = window.beams()
        if len(window) == 1:
            changed = self.grid.integrate(pose, angles, ranges)
        else:
            changed = self.grid.integrate_batches(window.beam_poses(pose), window.sizes(),
                                                  angles, ranges)
        if changed:
            self.publisher.changed = self._fields_stale = True
        self.scans += len(window)
        self.windows += 1
        self._maybe_publish()

    def _place(self, window: ScanWindow, now: float, standing: bool) -> Pose | None:
        """The map-frame pose of a window's last batch, or None when the window is
        dropped (the module docstring): the belief's mean while the reference is built
        and while the rover stands; else the window's de-skewed hits matched, judged
        and weighed once."""
        opts = self.matching
        loc = self.localiser
        guess = loc.belief.mean
        if opts is None or self.scans < self.warmup_scans:
            return guess
        odom = window.frame
        if odom is not window.last:  # a flicker stamp: the belief takes the drive's heading
            guess = loc.take_frame(odom)
        pts = window.local_points(opts)
        wide = self.wide(opts)
        stamp = loc.stamp_covariance(now - self._still_since < self.settle_s,
                                     window.travel_cm if window.moved else None)
        fields = self._current_fields(opts, now)
        if standing and self._stands_at(guess, pts, fields, opts, stamp):
            return guess  # standing still: placing it at the match would add its jitter
        if wide:
            if now - loc.reported_at < self.settle_s:  # not yet at the pose the report predicts
                return self._refuse("coasting", len(window))
            if now - self._search_at < _SEARCH_EVERY_S:
                return self._refuse("searching", len(window))
            self._search_at = now
            b = loc.belief
            result = relocalise(fields, pts, guess, opts, turn_deg=min(180.0, b.heading95_deg),
                                max_shift_cm=max(opts.max_shift_cm, b.radius95_cm))
            at_mean = at_match = None
        else:
            result = match_scan(fields, pts, guess, opts)
            assert self._distance is not None
            weighed = loc.weigh_odometry(self._distance, pts,
                                         result.pose if result.accepted else None, now, stamp)
            if weighed is None:
                return self._refuse("odometry in doubt", len(window))
            at_mean, at_match = weighed
        if not result.accepted:
            if not result.supported and at_mean is not None and (
                    at_mean.verdict is not FitVerdict.BAD_FIT):
                return guess  # new ground, or too few hits: nothing to judge it by
            if result.supported and at_mean is not None and at_mean.accepted and (
                    now - self._still_since >= self.settle_s):
                # the rover has stood settle_s, its scan fits well at the mean and the
                # match found nothing better nearby: its resting pose is judged, so it
                # stands from the next window on (else a match that keeps ending a
                # hair worse than the guess would keep a standing rover unplaced)
                self._last_odom = odom
            return self._refuse(result.reason.split(" (")[0], len(window))
        assert self._distance is not None
        if at_match is None:
            at_match = judge_fit(self._distance, result.pose, pts, _SCAN)
        fit = gate_fit(at_match, result.pose, guess, loc.belief.covariance
                       + stamp - odometry_floor())
        if not fit.accepted:
            if fit.verdict in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS) and not wide:
                return guess
            return self._refuse(fit.verdict.value, len(window))
        placed = loc.update(self._distance, result.pose, pts, stamp, len(window), odom)
        self.matched += 1
        self.searched += wide
        self._last_odom = odom
        return placed

    def _stands_at(self, pose: Pose, pts: np.ndarray, fields: MatchFields,
                   opts: MatchOptions, stamp: np.ndarray) -> bool:
        """Whether a standing window's scan says the rover stands at ``pose``, the belief's
        mean: it does not fit badly there (`judge_fit`: too few hits or new ground say
        nothing against it), and the local match does not land outside the belief's
        gate (its covariance widened by the stamp's own error).

        Why: frozen stamps read as standing also when both encoders stopped counting
        while the rover moves on. A scan that fits badly at the mean shows it moved; so
        does one whose match lies outside the gate, where the fit at the mean alone does
        not: along a corridor, or turned a few degrees among near walls, the hits still
        fit "not badly" 10 cm or 10 deg off. Such a window is matched and weighed (the
        "odometry broke unseen" hypothesis) instead of placed at the mean."""
        if self._distance is None:
            return True
        if judge_fit(self._distance, pose, pts, _SCAN).verdict is FitVerdict.BAD_FIT:
            return False
        result = match_scan(fields, pts, pose, opts)
        if not result.accepted:
            return True  # nothing better nearby
        return self.localiser.within_gate(result.pose, stamp)

    def _refuse(self, reason: str, batches: int) -> None:
        """Drop a window of ``batches`` batches, counting why (per batch)."""
        self.refusals[reason] += batches

    def _current_fields(self, opts: MatchOptions, now: float) -> MatchFields:
        """The matching fields, rebuilt first when stale for ``fields_s`` (or never built)."""
        if self._fields is None or (self._fields_stale and now - self._fields_at >= self.fields_s):
            self._build_fields(now)
        assert self._fields is not None
        return self._fields

    def _build_fields(self, now: float) -> None:
        """Matching fields of the grid's obstacle surfaces (`map_fields.build_fields`)."""
        self._fields, self._distance = build_fields(self.grid)
        self._fields_at = now
        self._fields_stale = False

    def _maybe_publish(self) -> None:
        now = trio.current_time()
        wait = self.publisher.due(self.scans, now)
        if wait is None:
            return
        if wait <= 0:
            self._publish(force=False)
        elif not self.publisher.timer_armed:  # publish the last change even if no scan follows
            self.publisher.timer_armed = True
            self.ctx.start_timer(wait, Message.uint(Cmd.MAP_GET, 1))

    def _publish(self, force: bool = True) -> None:
        """Send a snapshot (when something changed, or ``force``) and the scan count."""
        self.publisher.publish(lambda m: self._send(self._nav, m), self.grid, self.scans,
                               self.localiser.correction, trio.current_time(), force=force)

    def _restore(self, snap: GridMap) -> None:
        """Seed cells this grid has not observed from ``snap`` (`map_fields.restore_unknown`)."""
        changed = restore_unknown(self.grid, snap)
        if changed is not None:
            self.publisher.changed = changed
