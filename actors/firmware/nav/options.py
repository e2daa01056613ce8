"""Navigation's tunables (`NavOptions`) and the retained record of the server's
instructions (`NavMemory`) that survives a navigation restart."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from actors.firmware.localisation.motion_model import MotionNoise

__all__ = ["NavOptions", "NavMemory"]


@dataclass(frozen=True, slots=True)
class NavOptions:
    """Physical quantities of navigation; defaults suit the 20 x 15 cm rovers of the game.

    The turning radius is the body's half-diagonal (`planning.clearance.turning_radius_cm`
    of the hardware spec). Bounds (retries, nudges, holds, the outbox) and the fixed
    timings and geometry of the recovery behaviours are constants beside the code that
    uses them (`base`, `route`, `route_nav`, `recovery`, `nudge`, `tread_faults`).
    """

    tick_s: float = 0.25
    """Period of navigation's own timer (NAV_TIMER) [s]; ``pose`` telemetry goes every
    `base.POSE_REPORT_TICKS` ticks."""
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
    speed_cm_s: float = 20.0
    """Assumed travel speed for motion timeouts [cm/s]."""
    plan_margin_cm: float = 3.0
    """Clearance kept from obstacles when planning [cm]."""
    spot_margin_cm: float = 5.0
    """Clearance all round a hiding spot, for turning [cm]."""
    hide_within_cm: float = 30.0
    """How far from the spot it was sent to a hider may hide [cm] (`hider`): a spot that
    does not fit on the hider's map is moved to the nearest place within this that does
    (0 refuses it at once), and a hider that cannot reach its spot but stands this close
    to it, in the open in sight of it on its map, hides where it stands (0: never)."""
    narrow_margin_cm: float = 2.0
    """Clearance beyond half the body width in the last planning tier (narrow passages) [cm]."""
    backoff_cm: float = 6.0
    """Reverse this far after being blocked [cm]."""
    nudge_step_cm: float = 4.0
    """Lateral step of the search for a narrow passage missed by dead reckoning [cm]; it
    grows with the pose belief's 95 % radius (`drift_cm`) to at most
    `nudge.NUDGE_STEP_MAX_CM`."""
    tread_hold_s: float = 12.0
    """A tread fault (``NAV_TREAD_FAULT``) stops the motion and holds this long [s],
    doubled for a repeat within a minute: a slipping encoder or a weak motor lasts a
    few seconds to 20 s, and the small turns driven meanwhile may not be reported
    (a tread must travel about 5 cm for a short count to show) yet each turns the
    rover tens of degrees more than it believes."""
    settle_s: float = 1.0
    """After (re)start, no motion is commanded before this [s]: the end of a motion
    the previous incarnation commanded arrives meanwhile and is ignored."""
    motion: MotionNoise = field(default_factory=MotionNoise)
    """Noise levels of the pose belief's tread motion model (`localiser`)."""


@dataclass(slots=True)
class NavMemory:
    """What the server told navigation, in a retained RAM section (made by the rover tree).

    Like Motor Control's `PoseMemory`: C firmware keeps statics across a task
    restart, not across a rover reset. The server's small instructions live
    here (whether the game started, the origin, the destination being worked
    on), and the hider's and seeker's pose belief (`belief`): what they learned
    of where they are cannot be asked for again. Everything else a restarted
    navigation asks its neighbours for (pose, map) or the server (the map, again).
    """

    started: bool = False
    origin: tuple[float, float, float] | None = None
    goal: tuple[float, float, float | None] | None = None
    """The destination not yet answered (arrived / invalid_spot / found / not_found)."""
    within: float | None = None
    """The destination's ``within`` [cm]: how far round it a seeker searches (None: its
    IR range)."""
    given: tuple[float, float, float] | None = None
    """The server's ``origin`` (the rover's start pose, map frame) the pose belief started
    from: the same origin again is a retried destination, not a new placement."""
    belief: Any = None
    """The pose belief as it was last updated (`localiser.BeliefMemory`), None
    before the first."""
