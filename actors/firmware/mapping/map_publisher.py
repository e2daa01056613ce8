"""What Map Management tells navigation, and how often.

`MapPublisher` sends, at most once per ``publish_s`` of Trio time, a snapshot
of the grid when a cell changed class (``NAV_MAP_UPDATE``, by handle), the
count of scan batches taken (``NAV_SCAN_COUNT``: "map unchanged while scans
keep arriving" is not "LIDAR stalled"), and the correction (odometry -> map
frame, navigation's origin: ``NAV_MAP_ORIGIN_XY`` + ``NAV_MAP_ORIGIN_HEADING``)
when it moved by a stamp's own error (a cm, a degree). A change that comes too
soon arms a timer (``MAP_GET`` of value 1 back to Map Management), so the last
one is sent even when no scan follows.
"""

from __future__ import annotations

from collections.abc import Callable

from actors import BufferPool, Message
from actors.firmware.commands import Cmd
from actors.firmware.handles import post
from actors.firmware.localisation.scan_likelihood import FLOOR_CM, FLOOR_DEG
from actors.firmware.mapping.occupancy import OccupancyGrid
from actors.firmware.origin_wire import pose_messages
from server.protocol.pose import Pose

__all__ = ["MapPublisher", "CORRECTION_STEP_CM", "CORRECTION_STEP_DEG"]

CORRECTION_STEP_CM = FLOOR_CM
"""The correction is sent again once it moved this far in x or y [cm]: a stamp's own error
(`localisation.scan_likelihood.FLOOR_CM`); a smaller move is within the error of the
poses it was found from, and below what navigation steers by."""
CORRECTION_STEP_DEG = FLOOR_DEG
"""... or turned this much [deg]: a stamp's own heading error
(`localisation.scan_likelihood.FLOOR_DEG`, the encoders' quantisation)."""

Send = Callable[[Message], bool]
"""Sends a message to navigation without waiting; False when it could not."""


class MapPublisher:
    """Map Management's updates to navigation (see the module docstring).

    Args:
        pool: the rover's buffer pool (snapshots go by handle).
        publish_s: at most one update per this much Trio time [s].
    """

    def __init__(self, pool: BufferPool, publish_s: float) -> None:
        self.pool = pool
        self.publish_s = publish_s
        self.changed = True
        """A cell changed class since the last snapshot sent."""
        self.updates = 0
        """Snapshots sent to navigation."""
        self.dropped_updates = 0
        """Snapshots navigation's queue or the pool refused (the next one supersedes)."""
        self.sent_correction = Pose()
        """The correction navigation has (as far as Map Management knows)."""
        self.timer_armed = False
        """A deferred update is due (the timer's ``MAP_GET`` of value 1)."""
        self._counted = 0  # scan count last sent
        self._last = -float("inf")  # when the last update went

    def due(self, scans: int, now: float) -> float | None:
        """Whether an update is due with ``scans`` batches taken at ``now``: None when
        nothing changed, else the wait before it may go [s] (0 or less: now)."""
        if not self.changed and scans == self._counted:
            return None
        return self._last + self.publish_s - now

    def publish(self, send: Send, grid: OccupancyGrid, scans: int, correction: Pose,
                now: float, *, force: bool = True) -> None:
        """Send a snapshot (when something changed, or ``force``), the scan count and the
        correction (when it moved)."""
        self._last = now
        self._counted = scans
        if self.changed or force:
            self.changed = False
            if post(self.pool, send, Cmd.NAV_MAP_UPDATE, grid.snapshot()):
                self.updates += 1
            else:
                self.dropped_updates += 1
        send(Message.uint(Cmd.NAV_SCAN_COUNT, scans))
        old = self.sent_correction
        if abs(correction.x - old.x) < CORRECTION_STEP_CM and \
                abs(correction.y - old.y) < CORRECTION_STEP_CM and \
                abs(correction.heading_deg - old.heading_deg) < CORRECTION_STEP_DEG:
            return
        xy, heading = pose_messages(Cmd.NAV_MAP_ORIGIN_XY, Cmd.NAV_MAP_ORIGIN_HEADING,
                                    correction)
        if send(xy) and send(heading):
            self.sent_correction = correction
