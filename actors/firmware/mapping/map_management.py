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

Windows of batches (why: see `scan_window`)
    Batches come stamped with the raw odometry pose. Once the first
    ``warmup_scans`` batches made a reference (fused one by one), consecutive
    batches are gathered into a window of about a revolution, de-skewed into the
    last batch's frame by the odometry counted between the stamps, and matched,
    judged, weighed and fused once per window. A window holds the drive's
    heading across a straight drive's flicker of the counted heading, and is cut
    before a batch whose stamp turned (a turn in place, or beyond the flicker),
    after a revolution's sweep or its travel budget (`scan_window`), at a
    motion's end (the third batch in a row whose stamp did not move after one
    that did), before a tread fault report, a restore or navigation's
    ``MAP_GET``, and when the rover starts or stops standing.

Updates after enough motion (why: the matching, judging and fusing cost per window)
    As Nav2 AMCL's ``update_min_d`` / ``update_min_a`` and gmapping's
    ``linearUpdate`` / ``angularUpdate``, a window is processed only when the
    counted odometry moved ``update_min_cm`` or turned ``update_min_deg`` since
    the last window placed (a refused window does not count), or when something
    requires it (`_due`: a motion's end, a tread report, a restore, ``MAP_GET``,
    a stopped or standing rover, a wide belief). A window between only predicts:
    each batch moved the belief already, and the window is dropped from the grid
    (fused at the predicted pose, windows smeared the walls); its batches still
    count in ``scans``.

Scan matching (why: see `scan_match`)
    A window is guessed at ``correction (+) odometry`` (its frame: the last
    stamp, with the drive's heading across a flicker; the belief moves to it) and
    registered against the obstacle surfaces of the map built so far; an
    accepted match updates the pose belief and with it the correction
    (odometry -> map frame). The matching fields are rebuilt from
    the grid at most every ``fields_s``. The correction goes to navigation (``NAV_MAP_ORIGIN_XY`` +
    ``NAV_MAP_ORIGIN_HEADING``) with the published updates: navigation keeps
    it as its ``origin`` (map -> odometry), so its map-frame pose is the
    correction composed with Motor Control's odometry pose.

The pose belief (why: see `localisation.gaussian_pose`)
    Map Management holds the mapper's pose belief, a Gaussian over its
    map-frame pose (`GaussianPose`), and the correction is its mean composed
    with the inverse of the odometry stamp. Each batch first moves the belief
    by the treads' counted motion since the last batch (the motion model's
    noise); a tread Motor Control reported (``MAP_TREAD_FAULT``, relayed by
    navigation with the travel driven beyond the count) widens it as the
    model says, and a both-silent turn is two such treads. Then each window is
    matched: from the mean (`scan_match.match_scan`) while the belief is
    within the local match's reach (its 95 % heading under ``max_turn_deg``
    and radius under ``max_shift_cm``), or by the wide search
    (`scan_match.relocalise`) over the belief's 95 % bounds when it is wider
    (at most every ``_SEARCH_EVERY_S``: a bound on CPU). The matched pose is
    judged by the scan likelihood (`scan_likelihood.judge_fit`: enough hits,
    not new ground, the fit, and the belief's gate); accepted, it updates the
    belief with the scan's information (`face_information`: its hits on faces),
    and the window is placed where the prediction and the match, weighed,
    put it: the match across walls, the prediction along a corridor's walls
    (which the scan does not constrain). Refused, the window is dropped
    and the reason counted (`refusals`: data for metrics, never a trigger):
    its pose is in doubt, and one badly placed batch clears free space
    through walls. A window that cannot be judged (too few hits, new ground)
    is placed at the mean while the belief is within the local reach, and
    dropped while it is wider.

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
from collections import Counter

import numpy as np
import trio

from actors import Actor, BufferPool, Message
from actors.firmware.addresses import Addresses
from actors.firmware.arrays import pad_border
from actors.firmware.commands import Cmd
from actors.firmware.drivers.lidar import Scan
from actors.firmware.handles import post
from actors.firmware.localisation.distance_field import DistanceField
from actors.firmware.localisation.face_information import face_information
from actors.firmware.localisation.gaussian_pose import GaussianPose
from actors.firmware.localisation.motion_model import MotionNoise
from actors.firmware.localisation.odometry import tread_travel
from actors.firmware.localisation.odometry_fault import (
    FitEvidence,
    OdometryFaultNoise,
    broken_spread,
    evidence,
    hazard,
    posterior,
)
from actors.firmware.localisation.scan_likelihood import (
    GATE_CHI2,
    MAX_BEAMS,
    MIN_FIT,
    FitVerdict,
    ScanFit,
    ScanOptions,
    acceptable_log_fit,
    gate_fit,
    judge_fit,
    odometry_floor,
)
from actors.firmware.mapping.occupancy import OCCUPIED, OccupancyGrid
from actors.firmware.mapping.scan_match import (
    BLUR_WIDE,
    MatchFields,
    MatchOptions,
    MatchResult,
    match_scan,
    relocalise,
)
from actors.firmware.mapping.scan_window import ScanWindow, same_stamp
from actors.firmware.origin_wire import OriginHalves, pose_messages
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose, angle_diff_deg, compose, inverse

__all__ = ["MapManagement"]

_MATCH = MatchOptions()  # immutable default
_NOISE = MotionNoise()  # immutable default
_FAULT = OdometryFaultNoise()  # immutable default
_CORRECTION_WAIT_S = 1.0  # a restarted map waits this long for navigation's copy of the correction
_SEARCH_EVERY_S = 0.5  # at most one wide search per this much time [s] (a CPU bound: 24 ms
# for the default 24 deg either side, about 0.2 s for a whole turn)
_SCAN = ScanOptions()  # immutable default: the scan likelihood's noise levels
_ACCEPTABLE = acceptable_log_fit(_SCAN)  # what a just acceptable fit scores per measurement
_TRACK_WIDTH_CM = 13.0  # the rover's track width when no hardware spec is given [cm]
_CM_PER_INTERRUPT = 0.5  # a tread's travel per Int E when no hardware spec is given [cm]
UPDATE_MIN_CM = 8.0
"""A window is processed (matched, judged, fused) once the counted odometry moved this far
since the last window placed [cm] (Nav2 AMCL's ``update_min_d``, gmapping's
``linearUpdate``)."""
UPDATE_MIN_DEG = 10.0
"""... or turned this much [deg] (AMCL's ``update_min_a``, gmapping's ``angularUpdate``)."""
_END_BATCHES = 3  # a motion ends at the 3rd batch in a row whose stamp did not change (a
# pause of a batch or two within a drive or a slow turn is no end)


def _max3(values: np.ndarray) -> np.ndarray:
    """Maximum over each cell's 3 x 3 neighbourhood."""
    p = pad_border(values)
    rows = np.maximum(np.maximum(p[:-2], p[1:-1]), p[2:])
    return np.maximum(np.maximum(rows[:, :-2], rows[:, 1:-1]), rows[:, 2:])


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
        track_width_cm: distance between the treads' contact lines [cm] (the motion
            model's geometry).
        cm_per_interrupt: a tread's travel per Int E [cm] (with the track, the
            dead-reckoned heading's quantum a window's drive heading spans).
        noise: the motion model's noise levels.
        fault_noise: the prior of the "odometry broke unseen" hypothesis.
    """

    def __init__(self, pool: BufferPool, *, size_cm: tuple[float, float] = (2400.0, 2400.0),
                 resolution_cm: float = 5.0, publish_s: float = 0.25,
                 restarted: bool = False, matching: MatchOptions | None = _MATCH,
                 fields_s: float = 0.5, warmup_scans: int = 20, settle_s: float = 1.0,
                 update_min_cm: float = UPDATE_MIN_CM, update_min_deg: float = UPDATE_MIN_DEG,
                 track_width_cm: float = _TRACK_WIDTH_CM,
                 cm_per_interrupt: float = _CM_PER_INTERRUPT, noise: MotionNoise = _NOISE,
                 fault_noise: OdometryFaultNoise = _FAULT,
                 addresses: Addresses | None = None) -> None:
        self.pool = pool
        self._addresses = addresses
        self.grid = OccupancyGrid(size_cm[0], size_cm[1], resolution_cm)
        self.publish_s = publish_s
        self.restarted = restarted
        self.scans = 0
        """Scan batches taken by this incarnation: fused, or in a window that only
        predicted (`_due`); a dropped window's are counted in `refusals`."""
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
        self.update_min_cm = update_min_cm
        self.update_min_deg = update_min_deg
        self.track_width_cm = track_width_cm
        self._quantum_deg = math.degrees(cm_per_interrupt / track_width_cm)
        self.noise = noise
        self.fault_noise = fault_noise
        self._prev_odom: Pose | None = None  # odometry pose of the previous batch
        self._still_since = -float("inf")  # time odometry last changed between two batches
        self.belief = GaussianPose.at(Pose())
        """The pose belief (map frame) at the odometry stamp ``_belief_odom``."""
        self._belief_odom: Pose | None = None  # the odometry stamp the belief was last moved to
        self.broken = 0.0
        """Weight of the "odometry broke unseen" hypothesis (`odometry_fault`) [1]."""
        self.switches = 0
        self._weighed_at = -float("inf")  # time of the last window weighed by `_weigh_odometry`
        # odometry -> map frame under "broken", learnt from a confident fit the narrow
        # belief could not hold (None: not learnt, the broken component is wide)
        self._alt_correction: Pose | None = None
        self._charged = False  # the scans since the last that weighed for "right" paid the
        # broken component's Occam factor (`odometry_fault.evidence`)
        """Times the belief became the broken component (data for metrics)."""
        self._step = (0.0, 0.0)  # the last step between two stamps: travel [cm], turn [rad]
        self.correction = Pose()
        """Odometry frame -> map frame: the belief's mean composed with the inverse of
        its odometry stamp (identity until a match or a report moves it)."""
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
        self._sent_correction = Pose()  # the correction navigation has (as far as we know)
        self._origin_halves = OriginHalves()  # MAP_ORIGIN_XY waiting for its heading
        # a restarted incarnation waits (a bounded time) for the correction navigation kept
        self._await_correction_until = -float("inf")
        self._search_at = -float("inf")  # time of the last wide search
        self._reported_at = -float("inf")  # time of the last MAP_TREAD_FAULT that moved the belief
        self._changed = True  # a cell changed class since the last update
        self._counted = 0  # scan count last sent
        self._last_publish = -float("inf")
        self._timer_armed = False
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
                self._timer_armed = False
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
                self.correction = self._sent_correction = origin
            self._await_correction_until = -float("inf")
        elif cmd == Cmd.MAP_TREAD_FAULT:
            left_mm, right_mm = message.as_pair()
            self._flush()  # the batches before the report are placed as the counts say
            self._tread_fault(left_mm / 10.0, right_mm / 10.0)
        elif cmd == Cmd.NOOP:
            self.noops += 1  # a flood fault: costs a queue slot, never a restart
        else:
            raise ValueError(f"map management got an unknown command 0x{cmd:04x}")

    def _tread_fault(self, left_cm: float, right_cm: float) -> None:
        """Motor Control reported a tread (or both) in the motion that just ended; the
        travel each was driven beyond its count widens the belief (and moves its mean
        halfway), as the motion model says.

        The report comes as the PWM stops and predicts the pose at rest (the drive
        model's travel includes the coast), while the rover still coasts, unseen by an
        encoder that does not count. So for ``settle_s`` after it no wide search runs (a
        batch taken mid-coast fits where the rover was then, not where it comes to
        rest), and the rover counts as standing only ``settle_s`` after it (the frozen
        stamps of stuck encoders say nothing of whether it moves)."""
        if (left_cm == 0.0 and right_cm == 0.0) or self._belief_odom is None:
            return
        self.belief = self.belief.predict(0.0, 0.0, self.track_width_cm, self.noise,
                                          (left_cm, right_cm))
        self.correction = compose(self.belief.mean, inverse(self._belief_odom))
        self._reported_at = self._still_since = trio.current_time()

    def _predict(self, odom: Pose) -> None:
        """Move the belief by the treads' counted travel from its stamp to ``odom`` (the
        first batch of an incarnation puts it at the corrected stamp)."""
        if self._belief_odom is None:
            self._belief_odom = odom
            self.belief = GaussianPose.at(compose(self.correction, odom))
            return
        if same_stamp(odom, self._belief_odom):
            return
        left, right = tread_travel(self._belief_odom, odom, self.track_width_cm)
        self._step = (0.5 * (left + right), (right - left) / self.track_width_cm)
        self.belief = self.belief.predict(left, right, self.track_width_cm, self.noise)
        self._belief_odom = odom
        # the mean moved with the counts: the correction is unchanged, up to rounding
        self.belief = self.belief.moved_to(compose(self.correction, odom))

    def wide(self, opts: MatchOptions) -> bool:
        """Whether the belief is wider than the local match reaches (its 95 % heading over
        ``max_turn_deg`` or its 95 % radius over ``max_shift_cm``): then only the wide
        search may place a window."""
        b = self.belief
        return b.heading95_deg > opts.max_turn_deg or b.radius95_over(opts.max_shift_cm)

    def _take_batch(self, scan: Scan, now: float) -> None:
        """Add a batch to the window, and fuse the window when it is cut (the module
        docstring, `scan_window`).

        The rover stands when odometry has not changed for ``settle_s`` and the last
        matched window ended at the same odometry pose (within 5 mm and 0.3 deg, the
        belief within the local reach): a standing window is placed at the belief's mean
        unmatched when its scan says it stands there (`_stands_at`). An unchanged stamp
        alone does not mean the rover stands: one Int E turns the heading by 2.2 deg, so
        a turning rover's batch can carry the previous tick's stamp, and after a turn the
        rover keeps turning by up to an interrupt's worth (or swings back) unseen by its
        encoders; such batches are matched, and two stuck encoders freeze the stamps of a
        rover that turns on. The third batch in a row whose stamp did not change after
        one that did ends a motion (one or two are a pause within a drive or a slow
        turn): the window is cut and processed there, so navigation gets the pose a
        motion ended at without waiting for the next window. A cut window is processed
        or only predicts as `_due` says.
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
            self._changed = self._fields_stale = True
        self.scans += len(window)
        self.windows += 1
        self._maybe_publish()

    def _place(self, window: ScanWindow, now: float, standing: bool) -> Pose | None:
        """The map-frame pose of a window's last batch, or None when the window is
        dropped (the module docstring): the belief's mean while the reference is built
        and while the rover stands; else the window's de-skewed hits matched, judged
        and weighed once."""
        opts = self.matching
        guess = self.belief.mean
        if opts is None or self.scans < self.warmup_scans:
            return guess
        odom = window.frame
        if odom is not window.last:  # a flicker stamp: the belief takes the drive's heading
            self._belief_odom = odom
            guess = compose(self.correction, odom)
            self.belief = self.belief.moved_to(guess)
        pts = window.local_points(opts)
        wide = self.wide(opts)
        stamp = self._stamp_covariance(now, window)
        fields = self._current_fields(opts, now)
        if standing and self._stands_at(guess, pts, fields, opts, stamp):
            return guess  # standing still: placing it at the match would add its jitter
        if wide:
            if now - self._reported_at < self.settle_s:  # not yet at the pose the report predicts
                return self._refuse("coasting", len(window))
            if now - self._search_at < _SEARCH_EVERY_S:
                return self._refuse("searching", len(window))
            self._search_at = now
            b = self.belief
            result = relocalise(fields, pts, guess, opts, turn_deg=min(180.0, b.heading95_deg),
                                max_shift_cm=max(opts.max_shift_cm, b.radius95_cm))
            at_mean = at_match = None
        else:
            result = match_scan(fields, pts, guess, opts)
            weighed = self._weigh_odometry(pts, result, now, stamp)
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
        fit = gate_fit(at_match, result.pose, guess, self.belief.covariance
                       + stamp - odometry_floor())
        if not fit.accepted:
            if fit.verdict in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS) and not wide:
                return guess
            return self._refuse(fit.verdict.value, len(window))
        info = face_information(self._distance, result.pose, pts, _SCAN)
        # this window's pose: the prediction (the belief and the stamp's own error) and the
        # match, weighed by what this one scan's hits say (each of its beams counted);
        # the belief (the correction's) counts each batch of the window as
        # `independent_hits` measurements (its errors repeat from scan to scan) and takes
        # the stamp's error as the match's, since it does not carry over to the next stamp
        beams = min(len(pts), MAX_BEAMS)
        every_beam = info * max(1.0, beams / _SCAN.independent_hits)
        placed = self.belief.widened(stamp).update(result.pose, every_beam).mean
        self.belief = self.belief.update(result.pose, info * len(window), stamp).moved_to(
            placed)
        self.matched += 1
        self.searched += wide
        self._last_odom = odom
        self.correction = compose(self.belief.mean, inverse(odom))
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
        return self.belief.distance2(result.pose, self.belief.covariance + stamp) <= GATE_CHI2

    def _weigh_odometry(self, pts: np.ndarray, result: MatchResult, now: float,
                        stamp: np.ndarray) -> tuple[ScanFit, ScanFit | None] | None:
        """Weigh this window's scan as evidence for "odometry broke unseen"
        (`odometry_fault`) and return its fit at the belief's mean and, when it was
        judged, at the match (`judge_fit` without the belief: `_place` gates it); when
        that hypothesis is the more probable, the belief becomes its wide component and
        None is returned (the window's pose is in doubt)."""
        assert self._distance is not None
        if self._weighed_at > -float("inf"):
            self.broken += (1.0 - self.broken) * hazard(now - self._weighed_at, self.fault_noise)
        self._weighed_at = now
        at_mean = judge_fit(self._distance, self.belief.mean, pts, _SCAN)
        if at_mean.verdict in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS):
            return at_mean, None  # nothing to judge the pose by
        narrow = self.belief.covariance + stamp
        spread = broken_spread(self.matching.max_shift_cm if self.matching else 12.0)
        wide = narrow + spread
        odom = self._belief_odom
        assert odom is not None
        alt = None if self._alt_correction is None else compose(self._alt_correction, odom)
        found: dict[str, float] = {}  # `FitEvidence`'s optional fields this batch fills
        if alt is not None:
            at_alt = judge_fit(self._distance, alt, pts, _SCAN)
            if at_alt.fit < MIN_FIT:
                alt = self._alt_correction = None  # the scan refutes it
            else:
                found["log_fit_alt"] = at_alt.log_fit
        at_match = None
        if result.accepted:
            at_match = judge_fit(self._distance, result.pose, pts, _SCAN)
            if at_match.verdict not in (FitVerdict.NEW_GROUND, FitVerdict.TOO_FEW_HITS):
                d2 = self.belief.distance2(result.pose, narrow)
                found.update(log_fit_match=at_match.log_fit, d2_match=d2,
                             d2_match_wide=self.belief.distance2(result.pose, wide))
                if alt is not None:
                    found["d2_match_alt"] = GaussianPose(alt, narrow).distance2(result.pose)
                if at_match.fit >= MIN_FIT and d2 > GATE_CHI2:
                    # a confident fit the narrow belief cannot hold: where "broken" would be
                    self._alt_correction = compose(result.pose, inverse(odom))
        ev = FitEvidence(min(float(at_mean.hits), _SCAN.independent_hits), at_mean.log_fit,
                         **found)
        step = evidence(ev, narrow, wide, _ACCEPTABLE, charged=self._charged)
        self._charged = step > 0.0  # a run of scans for "broken" pays its Occam factor once
        self.broken = posterior(self.broken, step)
        if self.broken <= 0.5:
            return at_mean, at_match
        # wide round the mean, not narrow round the learnt pose: one match (a scan blurred
        # by a turn) may have put it a few degrees off; the wide search's unambiguous fit
        # decides where the rover is
        self.belief = self.belief.widened(spread)
        self.broken = 0.0
        self._alt_correction = None
        self._charged = False
        self.switches += 1
        return None

    def _stamp_covariance(self, now: float, window: ScanWindow) -> np.ndarray:
        """The covariance of a window's stamps' own error: the encoders' rounding
        (`odometry_floor`), the motion within the last batch's tick, uniform over the step
        between two stamps (its variance: the step squared over 12; a tick with no Int E
        keeps the last step, since the rover moves on between interrupts, until the rover
        has stood ``settle_s``), and the odometry's error over the window's counted travel
        (the motion model's noise: it misplaces the earlier batches against the last;
        the window turns only by its heading's flicker, which it does not de-skew)."""
        ds, dtheta = self._step if now - self._still_since < self.settle_s else (0.0, 0.0)
        cov = odometry_floor() + np.diag([ds * ds / 12.0, ds * ds / 12.0,
                                          dtheta * dtheta / 12.0])
        if window.moved:  # a drive: its stamps hold the drive's heading (`scan_window`)
            travel = window.travel_cm
            within = GaussianPose(self.belief.mean, np.zeros((3, 3))).predict(
                travel, travel, self.track_width_cm, self.noise)
            cov += within.covariance
        return cov

    def _refuse(self, reason: str, batches: int) -> None:
        """Drop a window of ``batches`` batches, counting why (per batch)."""
        self.refusals[reason] += batches

    def _current_fields(self, opts: MatchOptions, now: float) -> MatchFields:
        """The matching fields, rebuilt first when stale for ``fields_s`` (or never built)."""
        if self._fields is None or (self._fields_stale and now - self._fields_at >= self.fields_s):
            self._build_fields(opts, now)
        assert self._fields is not None
        return self._fields

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
        snap = grid.snapshot()  # its classes are the log-odds' (occupied: over the threshold)
        known = snap.known_bounds()  # every occupied cell is known: one pass finds both
        res = grid.resolution_cm
        rows = cols = np.zeros(0, dtype=np.int64)
        if known is not None:
            kr0, kr1, kc0, kc1 = known
            occupied = snap.cells[kr0:kr1, kc0:kc1] == OCCUPIED
            rows = np.flatnonzero(occupied.any(axis=1)) + kr0
            cols = np.flatnonzero(occupied.any(axis=0)) + kc0
        if rows.size == 0:
            self._fields = MatchFields(np.zeros((1, 1), dtype=bool), grid.origin_cm, res)
        else:
            k = BLUR_WIDE + 2
            r0, r1 = max(0, int(rows[0]) - k), int(rows[-1]) + k + 1
            c0, c1 = max(0, int(cols[0]) - k), int(cols[-1]) + k + 1
            occupied = snap.cells[r0:r1, c0:c1] == OCCUPIED
            near_occ = _max3(occupied.astype(np.float32)) > 0
            hits = np.where(near_occ, grid.hit_counts()[r0:r1, c0:c1], 0.0)
            weights = hits / np.maximum(_max3(hits), 1.0)
            origin = (grid.origin_cm[0] + c0 * res, grid.origin_cm[1] + r0 * res)
            self._fields = MatchFields(weights, origin, res)
        self._distance = DistanceField.from_grid(snap, known_bounds=known)
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
