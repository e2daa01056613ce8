"""A window of LIDAR batches brought into one frame by the odometry counted between them.

Why
    A batch (one world tick of samples, about a hundred beams over a quarter turn of
    the rotor) is what LIDAR Control stamps and sends, but matching it, judging it,
    updating the belief with it and fusing it into the grid cost mostly per call
    (numpy's fixed cost on a hundred values), not per beam. So Map Management
    gathers consecutive batches into a window of about one revolution and does that
    work once per window. Each batch keeps its own odometry stamp: the window is
    de-skewed as a spinning LIDAR's driver de-skews a revolution, every batch moved
    into the last batch's frame by the counted odometry between their stamps
    (``relative(last, stamp)``, with the drive's heading: below). The matched pose
    is the last batch's; each beam is fused from its own batch's origin (the placed
    pose composed with that batch's relative odometry).

The drive's heading (why a straight drive's flicker does not cut a window)
    The dead-reckoned heading moves in quanta of one encoder interrupt of one tread
    (0.5 cm over the 13 cm track: 2.2 deg). On a straight drive both treads advance
    together, one tread's interrupt a little before the other's, so the stamps'
    heading flickers a quantum either side of the drive's while the rover's barely
    moves (about half a degree, as Motor Control steers back against the count): the
    flicker is the count's rounding, not a turn. A window therefore holds the heading
    of its first stamp, the drive's, and de-skews every batch by it: a stamp a quantum
    off is brought in with the drive's heading and its position as counted, so the
    batches are not rotated against each other, and the window's frame (`frame`) is
    the last batch's position with the drive's heading. A stamp is taken as a flicker
    only where the counts show a drive: it stepped to that quantum while its position
    advanced (a turn in place rotates the heading with the position still), or the
    stamp before it held the same quantum. De-skewing by each flicker's quantum, as if
    it were a turn, would rotate the batches 2.2 deg against each other and smear the
    window.

Where a window is cut (`ScanWindow.fits` before a batch, `ScanWindow.full` after it,
and Map Management's own cuts)
    * before a batch whose stamp turned: a heading other than the drive's or a
      quantum either side of it, or a step to another quantum with the position
      still (a turn in place); a turning rover's batches are matched one by one,
      each placed by its own fit;
    * once its beams swept a revolution (``WINDOW_SWEEP_DEG``): beyond it a direction
      is seen twice, from stamps that disagree by the odometry's error;
    * once its counted travel reached ``WINDOW_TRAVEL_CM`` (a drive after a gap in
      the batches), for the same reason;
    * Map Management cuts it at a motion's end (the third batch in a row whose stamp
      did not change after one that did), before a tread fault report (``MAP_TREAD_FAULT``),
      a restore, an upload's ``MAP_GET``, and when the rover starts or stops standing.

Measured (one game each, the map's accuracy against the room): hall seed 1, windows
of one batch 0.9989, of two 0.9960, of a revolution (about four batches) with turns
inside them 0.992 to 0.994; corridor seed 4, windows de-skewed by each flicker's
quantum 0.9868, windows of one heading 0.9961. Windows spanning a drive's flicker:
the 40 built-in games at least 0.992, where windows cut at each flicker gave at least
0.995.

Frame and units
    Stamps are odometry poses ([cm], [deg]); relative poses are in the last batch's
    frame; points in `hits_to_local`'s (n, 2) layout [cm].
"""

from __future__ import annotations

import math

import numpy as np

from actors.firmware.drivers.lidar import Scan
from actors.firmware.mapping.scan_match import MatchOptions, hits_to_local, usable_hits
from server.protocol.pose import Pose, angle_diff_deg, compose, relative

__all__ = ["ScanWindow", "WINDOW_SWEEP_DEG", "WINDOW_TURN_DEG",
           "WINDOW_TRAVEL_CM", "same_stamp"]

WINDOW_SWEEP_DEG = 360.0
"""A window holds at most about one revolution of the rotor's sweep [deg]."""
WINDOW_TURN_DEG = 0.3
"""Two stamps' headings this close are the same quantum [deg] (the odometry's heading
moves in quanta of 2.2 deg)."""
_STILL_CM = 0.5
"""Two stamps' positions this close are the same (positions come rounded to the cm) [cm]."""
WINDOW_TRAVEL_CM = 10.0
"""A window is cut once the odometry counted this much travel within it [cm]."""


class ScanWindow:
    """Consecutive batches with their odometry stamps, de-skewed into the last one's frame
    with the drive's heading (the module docstring).

    Add batches with `add`; read the window as one scan with `beams`, `local_points`
    and `beam_poses`. A window is used once (Map Management starts a new one).

    Args:
        quantum_deg: the dead-reckoned heading's quantum (one interrupt of one tread
            over the track: `hardware.HardwareSpec.heading_quantum_deg`) [deg].
    """

    __slots__ = ("scans", "sweep_deg", "travel_cm", "quantum_deg", "_beams", "_deskew",
                 "_relative")

    def __init__(self, quantum_deg: float) -> None:
        self.scans: list[Scan] = []
        """The batches, oldest first."""
        self.sweep_deg = 0.0
        """The rotor's sweep the batches cover together [deg]."""
        self.travel_cm = 0.0
        """Travel counted between the first and the last stamp, summed per step [cm]."""
        self.quantum_deg = quantum_deg
        self._beams: tuple[np.ndarray, np.ndarray] | None = None
        self._deskew: list[Pose] = []  # each stamp with the drive's heading
        self._relative: list[Pose] | None = None  # `relative_poses`, once read

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def moved(self) -> bool:
        """Whether any stamp's position differs from the one before it (the rover drove
        within; its heading is the drive's throughout)."""
        return self.travel_cm > 0.0

    @property
    def last(self) -> Pose:
        """The last batch's odometry stamp (as counted)."""
        return self.scans[-1].pose

    @property
    def frame(self) -> Pose:
        """The window's frame as an odometry stamp: the last batch's position with the
        drive's heading (its stamp, unless that is a flicker of the drive's heading)."""
        return self._deskew[-1]

    def _side(self, pose: Pose) -> int | None:
        """Where a stamp's heading lies against the drive's: 0 on it, +1 or -1 one
        quantum off, None elsewhere."""
        d = angle_diff_deg(pose.heading_deg, self.scans[0].pose.heading_deg)
        if abs(d) < WINDOW_TURN_DEG:
            return 0
        if abs(abs(d) - self.quantum_deg) < WINDOW_TURN_DEG:
            return 1 if d > 0 else -1
        return None

    def fits(self, scan: Scan) -> bool:
        """Whether ``scan`` may join the window: its stamp holds the drive's heading, or
        is a flicker of it (one quantum off, stepped there while the position advanced,
        or already there); an empty window takes any batch."""
        if not self.scans:
            return True
        side = self._side(scan.pose)
        if side is None:
            return False
        if side == 0:
            return True
        before = self.scans[-1].pose
        return self._side(before) == side or not _same_place(scan.pose, before)

    def add(self, scan: Scan) -> None:
        """Append a batch (taken after the ones already in; one that `fits`, or the
        first)."""
        pose = scan.pose
        if self.scans:
            before = self.scans[-1].pose
            self.travel_cm += math.hypot(pose.x - before.x, pose.y - before.y)
            drive = self._side(pose) is not None
            heading = self.scans[0].pose.heading_deg if drive else pose.heading_deg
            self._deskew.append(pose if heading == pose.heading_deg
                                else Pose(pose.x, pose.y, heading))
        else:
            self._deskew.append(pose)
        self.scans.append(scan)
        self.sweep_deg += scan.sweep_deg
        self._beams = self._relative = None

    def full(self) -> bool:
        """Whether the window swept a revolution or counted its travel budget."""
        return self.sweep_deg >= WINDOW_SWEEP_DEG or self.travel_cm >= WINDOW_TRAVEL_CM

    def beams(self) -> tuple[np.ndarray, np.ndarray]:
        """All beams' angles (each from its own batch's heading) [deg] and ranges [cm],
        batch after batch."""
        if self._beams is None:
            scans = self.scans
            if len(scans) == 1:
                self._beams = (scans[0].angles_deg, scans[0].ranges_cm)
            else:
                self._beams = (np.concatenate([s.angles_deg for s in scans]),
                               np.concatenate([s.ranges_cm for s in scans]))
        return self._beams

    def relative_poses(self) -> list[Pose]:
        """Each batch's de-skew stamp (its position, the drive's heading) seen from the
        last one's (the last is the identity)."""
        if self._relative is None:  # (read for the match, and again for the fusion)
            deskew = self._deskew
            last = deskew[-1]
            self._relative = [relative(last, p) for p in deskew]
        return self._relative

    def sizes(self) -> list[int]:
        """Beams per batch, in order."""
        return [s.angles_deg.size for s in self.scans]

    def _per_beam(self, poses: list[Pose]) -> np.ndarray:
        """The rows x [cm], y [cm], heading [deg] of each beam's batch pose, (3, n)."""
        rows = np.array([[p.x for p in poses], [p.y for p in poses],
                         [p.heading_deg for p in poses]])
        return rows.repeat(self.sizes(), axis=1)

    def local_points(self, options: MatchOptions) -> np.ndarray:
        """The hits usable for matching, (n, 2) [cm], in the last batch's frame: each
        batch's hits moved by its relative odometry (`hits_to_local` for one batch)."""
        angles, ranges = self.beams()
        if len(self.scans) == 1:
            return hits_to_local(angles, ranges, options)
        at = self._per_beam(self.relative_poses())
        pts = hits_to_local(at[2] + np.asarray(angles, dtype=np.float64), ranges, options)
        pts += at[:2].compress(usable_hits(ranges, options), axis=1).T
        return pts

    def beam_poses(self, placed: Pose) -> np.ndarray:
        """Each beam's origin when the last batch lies at ``placed``: the rows x [cm],
        y [cm], heading [deg], (3, n)."""
        return self._per_beam([compose(placed, r) for r in self.relative_poses()])


def _same_place(a: Pose, b: Pose) -> bool:
    """Whether two stamps' positions are the same (within their rounding)."""
    return abs(a.x - b.x) < _STILL_CM and abs(a.y - b.y) < _STILL_CM


def same_stamp(a: Pose, b: Pose | None) -> bool:
    """Whether two odometry stamps are the same: the same place and the same heading
    quantum (within 5 mm and 0.3 deg; headings compared across the wrap, so 179.9 and
    -179.9 deg are the same)."""
    return b is not None and _same_place(a, b) and abs(
        angle_diff_deg(a.heading_deg, b.heading_deg)) < WINDOW_TURN_DEG
