"""Navigation's tunables (`NavOptions`) and the retained record of the server's
instructions (`NavMemory`) that survives a navigation restart."""

from __future__ import annotations

from dataclasses import dataclass, field

from actors.firmware.localisation.motion_model import MotionNoise

__all__ = ["NavOptions", "NavMemory"]


@dataclass(frozen=True, slots=True)
class NavOptions:
    """Tunables of navigation; defaults suit the 20 x 15 cm rovers of the game."""

    tick_s: float = 0.25
    """Period of navigation's own timer (NAV_TIMER) [s]."""
    pose_period_s: float = 0.75
    """Period of ``pose`` telemetry to the server [s] (about 1.3 Hz)."""
    step_cm: float = 20.0
    """Longest straight move of one ADP step [cm]."""
    waypoint_tol_cm: float = 5.0
    """An intermediate waypoint counts as reached this close [cm]."""
    goal_tol_cm: float = 2.0
    """The final waypoint counts as reached this close [cm]."""
    align_tol_deg: float = 3.0
    """Turn toward the next waypoint first when off by more than this [deg]."""
    heading_tol_deg: float = 2.0
    """Final heading counts as reached this close [deg]."""
    max_corrections: int = 6
    """Extra ADP steps allowed beyond the plan's length before giving up on a route."""
    motion_timeout_s: float = 4.0
    """A motion reporting nothing after this plus its nominal duration is stopped [s]."""
    pose_wait_s: float = 0.3
    """How long to wait for the pose at rest after a motion [s]."""
    send_timeout_s: float = 1.0
    """Longest wait for room in a neighbour's mailbox [s]."""
    speed_cm_s: float = 20.0
    """Assumed travel speed for motion timeouts [cm/s]."""
    robot_radius_cm: float | None = None
    """Turning radius for planning [cm]; None: the half-diagonal from the hardware spec."""
    plan_margin_cm: float = 3.0
    """Clearance kept from obstacles when planning [cm]."""
    spot_margin_cm: float = 5.0
    """Clearance all round a hiding spot, for turning [cm]."""
    spot_shift_cm: float = 30.0
    """A hiding spot that does not fit on the hider's map is moved to the nearest place
    within this that does (`hider`); 0 refuses it at once [cm]."""
    hide_near_cm: float = 30.0
    """A hider that cannot reach its spot but stands this close to it, in the open in
    sight of it on its map, hides where it stands (`hider`); 0 never [cm]."""
    narrow_margin_cm: float = 2.0
    """Clearance beyond half the body width in the last planning tier (narrow passages) [cm]."""
    replan_limit: int = 10
    """Replans after being blocked before a route is given up."""
    nudge_step_cm: float = 4.0
    """Lateral step of the search for a narrow passage missed by dead reckoning [cm]; it
    grows with the pose belief's 95 % radius (`drift_cm`) to at most ``nudge_step_max_cm``."""
    nudge_step_max_cm: float = 12.0
    """Largest lateral step of that search [cm]: below the free width a 35 cm gap leaves
    a 15 cm wide body (20 cm), so the offsets tried leave no hole between them. 12, not
    8: a seeker can reach a gap 21-36 cm off (measured against ground truth), beyond
    the +-24 cm six steps of 8 reach."""
    max_nudges: int = 6
    """Sideways offsets tried per route, at most."""
    nudge_reach_cm: float = 50.0
    """Waypoints this close to the block point are shifted by a nudge [cm]."""
    tread_hold_s: float = 12.0
    """A tread fault (``NAV_TREAD_FAULT``) stops the motion and holds this long [s],
    doubled for a repeat within a minute: a slipping encoder or a weak motor lasts a
    few seconds to 20 s, and the small turns driven meanwhile may not be reported
    (a tread must travel about 5 cm for a short count to show) yet each turns the
    rover tens of degrees more than it believes."""
    tread_holds: int = 2
    """Holds in a row (each report within a minute of the last), at most; a further
    report ends the motion as blocked: a tread stalled against a wall looks the same
    as one that does not count, and holding would not free it."""
    tread_contact_s: float = 15.0
    """A short count in a move this soon after a block ends it as blocked, not held [s]."""
    tread_stop_s: float = 1.0
    """A tread fault that ends its motion as blocked waits this long before deciding [s]."""
    map_retry_s: float = 20.0
    """Waiting for the map this long asks the server again, the wait doubling each time
    up to ``map_retry_max_s`` [s]. A map lost on the way (a chunk corrupted on the link
    is refused and the map never completes, and waiting for it could last the game)
    or refused ("no map yet", "outbox full; request the map later") comes again; the
    doubling lets a slow transfer finish before it is asked for once more."""
    map_retry_max_s: float = 160.0
    """See ``map_retry_s``."""
    probe_width_cm: float = 40.0
    """A block where the map's passage across the heading is narrower than this probes
    sideways at once (see `recovery.RouteRecovery._probe_plan`) [cm]."""
    probe_sidestep: bool = True
    """A probe's nudged route begins with a sidestep across the heading of the block
    (`recovery.RouteRecovery._with_sidestep`)."""
    probe_progress_cm: float = 25.0
    """A block this far from the last one starts a new sideways probe [cm]."""
    backoff_cm: float = 6.0
    """Reverse this far after being blocked [cm]."""
    backoff_repeat_cm: float = 20.0
    """Reverse this far after a second block at one place: room to come back sideways [cm]."""
    stall_turn_deg: float = 8.0
    """A back-off that ends blocked having turned more than this holds ``tread_hold_s``
    before the route goes on: a tread stalled (see
    `recovery.RouteRecovery._backoff_turned`) [deg]."""
    settle_s: float = 1.0
    """After (re)start, no motion is commanded before this [s]: the end of a motion
    the previous incarnation commanded arrives meanwhile and is ignored."""
    outbox: int = 16
    """Reports waiting for room in the pool or WiFly's mailbox, at most."""
    motion: MotionNoise = field(default_factory=MotionNoise)
    """Noise levels of the pose belief's tread motion model (`belief_tracking`)."""


@dataclass(slots=True)
class NavMemory:
    """What the server told navigation, in a retained RAM section (made by the rover tree).

    Like Motor Control's `PoseMemory`: C firmware keeps statics across a task
    restart, not across a rover reset. Only the server's small instructions
    live here (whether the game started, the origin, the destination being
    worked on); everything else a restarted navigation asks its neighbours for
    (pose, map) or the server (the map, again).
    """

    started: bool = False
    origin: tuple[float, float, float] | None = None
    goal: tuple[float, float, float | None] | None = None
    """The destination not yet answered (arrived / invalid_spot / found / not_found)."""
    within: float | None = None
    """The destination's ``within`` [cm]: how far round it a seeker searches (None: its
    IR range)."""
