"""The mapper's tunables: exploration, the completion test, homing and the holds
for a faulty LIDAR or odometry (`MappingOptions`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MappingOptions"]


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
    either side of dead reckoning's heading for the pose (``MAP_POSE_LOST``) [deg]: one
    such turn can go 50 deg unseen, and backing off and turning again on two stuck
    encoders spins the rover several turns in a few seconds."""
    short_hold_s: float = 2.0
    """Hold still this long after Motor Control saw a tread (or both) count short [s]:
    about eight scan batches for scan matching to catch up with what was not counted."""
    min_gain_share: float = 0.003
    """...or fewer than this share of the cells already known (a big hall's ragged far
    edges give a few dozen cells per visit for ever). Counted per visit, not per
    minute: crossing a big hall to a far frontier reveals nothing for a while."""

