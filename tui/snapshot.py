"""The console's contract with the system: what it is shown, and what it may ask.

The console never reaches into actors, the world or the server. A *system*
(the real one, wired in ``supervisors/``, or `tui.fake.FakeSystem`) gives it two
things, and this module is the whole of that contract:

1. **Snapshots** (system -> console). A `Snapshot` is a whole, immutable
   picture of the system at one simulated instant: time and speed, game phase,
   the mapper's map, rovers, queues, a tail of recent messages, the supervision
   tree, links, a timeline, faults. The console asks for one about 15 times per
   *wall* second (10 at "as fast as possible") by putting ``None`` into the
   ``requests`` channel it hands to `System.run`, never more than one at a time;
   the system answers each request by building a snapshot from its current
   state and calling ``publish(snapshot)``. A system may instead offer
   ``host_snapshot() -> Snapshot``, which the console then calls on its own
   side of the thread between two of Trio's batches (the state is consistent
   there, as in any task): no Trio task wakes for the console at all, so the
   console cannot change the order of events in a game. This pull makes the refresh
   rate independent of the simulation speed and of how many messages flow: at
   "as fast as possible" the system builds 15 snapshots per wall second, not one
   per simulated tick.
2. **Commands** (console -> system). `Controller` methods are *synchronous and
   non-blocking*: they are called from Textual handlers on the asyncio side of
   the one thread that hosts Trio in guest mode. An implementation queues the
   command with ``send_nowait`` into a bounded Trio memory channel and returns
   (this wakes Trio even when it is idle). The outcome comes back later as a
   `CommandResult` through the same ``publish`` callable: ``ok``, ``refused``
   (the command is not valid now, with a reason a person can read) or ``error``
   (it failed). The console shows refusals and errors as notifications. A
   controller method must never raise to the console; a full command queue is
   a ``refused`` result with reason ``"busy"``.

Frames and units
----------------
All positions are in the **map frame**: the mapping rover's start pose, x
forward along its start heading, y to its left, in [cm]; headings in [deg],
counter-clockwise from +x. The occupancy
grid `GridView` is a raster: ``cells[row, col]`` with row 0 at the *bottom*
(lowest y) and col 0 at the left (lowest x); cell ``[0, 0]`` has its
lower-left corner at ``origin_cm``. Ground truth, when the room is simulated,
is given in the same frame and convention (the adapter transforms it), so the
console can overlay the two without knowing anything about the world.

Immutability
------------
Records are frozen dataclasses with slots. The arrays inside them
(``GridView.cells``, ``Snapshot.lidar_points``) are read-only by contract: a
publisher must hand over arrays it will never write again (a copy, or a fresh
array per snapshot). The constructors check dtype and shape, so a wrong array
fails where it is made with a clear message, not later in a widget.

Sequence numbers
----------------
`LogLine.seq` and `TimelineEvent.seq` increase by one per line/event across
the whole run. Snapshots carry only a bounded tail (the newest
`MAX_LOG_LINES` / `MAX_TIMELINE`); the console appends the lines whose ``seq``
it has not seen, so nothing is shown twice and a gap shows as "... N lines
skipped" rather than as silence.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
import trio

__all__ = [
    "PHASES",
    "NODE_STATES",
    "RESULT_STATUSES",
    "MAX_LOG_LINES",
    "MAX_TIMELINE",
    "UNKNOWN",
    "FREE",
    "OCCUPIED",
    "Pose",
    "GridView",
    "RoverView",
    "QueueStats",
    "LogLine",
    "TreeNode",
    "LinkStats",
    "TimelineEvent",
    "ActiveFault",
    "FaultTarget",
    "Snapshot",
    "CommandResult",
    "Publish",
    "Controller",
    "System",
]

#: Game phases, in the order of DESIGN.md section 6.
PHASES: tuple[str, ...] = (
    "idle", "mapping", "map_ready", "hiding", "hidden", "seeking", "found", "not_found",
)
#: States of a supervision-tree node.
NODE_STATES: tuple[str, ...] = ("running", "restarting", "stopped")
#: Outcomes of a command.
RESULT_STATUSES: tuple[str, ...] = ("ok", "refused", "error")
#: Most log lines a snapshot carries (the newest).
MAX_LOG_LINES = 200
#: Most timeline events a snapshot carries (the newest).
MAX_TIMELINE = 200

#: Occupancy values of `GridView.cells` (the map_server / ROS convention).
UNKNOWN, FREE, OCCUPIED = -1, 0, 100

Point = tuple[float, float]
"""A position (x, y) [cm] in the map frame."""


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise ValueError(message)


@dataclass(frozen=True, slots=True)
class Pose:
    """A position and heading in the map frame."""

    x_cm: float
    """x [cm]."""
    y_cm: float
    """y [cm]."""
    heading_deg: float
    """Heading [deg], counter-clockwise from +x; any value, the console wraps it."""


@dataclass(frozen=True, slots=True)
class GridView:
    """An occupancy grid as a raster (see the module docstring for the frame).

    Raises:
        TypeError: when ``cells`` is not a 2-D ``numpy.int8`` array.
        ValueError: when ``resolution_cm`` is not positive.
    """

    cells: np.ndarray
    """``int8`` array (ny, nx): -1 unknown, 0 free, 100 occupied; row 0 is the lowest y."""
    resolution_cm: float
    """Side of one square cell [cm]."""
    origin_cm: Point
    """Lower-left corner (x, y) of cell [0, 0] in the map frame [cm]."""

    def __post_init__(self) -> None:
        if not isinstance(self.cells, np.ndarray) or self.cells.ndim != 2:
            raise TypeError(f"cells must be a 2-D numpy array, got {type(self.cells).__name__}"
                            f"{getattr(self.cells, 'shape', '')}")
        if self.cells.dtype != np.int8:
            raise TypeError(f"cells must have dtype int8, got {self.cells.dtype}")
        _check(self.resolution_cm > 0,
               f"resolution_cm must be > 0, got {self.resolution_cm!r}")

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) [cells]."""
        return self.cells.shape  # type: ignore[return-value]

    def cell_of(self, x_cm: float, y_cm: float) -> tuple[int, int]:
        """(row, col) of the cell holding a map-frame point; may lie outside the grid."""
        col = int(np.floor((x_cm - self.origin_cm[0]) / self.resolution_cm))
        row = int(np.floor((y_cm - self.origin_cm[1]) / self.resolution_cm))
        return row, col

    def value_at(self, x_cm: float, y_cm: float) -> int:
        """The cell value at a map-frame point; `UNKNOWN` outside the grid."""
        row, col = self.cell_of(x_cm, y_cm)
        ny, nx = self.cells.shape
        if 0 <= row < ny and 0 <= col < nx:
            return int(self.cells[row, col])
        return UNKNOWN

    def extent_cm(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the grid in the map frame [cm]."""
        ny, nx = self.cells.shape
        x0, y0 = self.origin_cm
        return x0, y0, x0 + nx * self.resolution_cm, y0 + ny * self.resolution_cm


@dataclass(frozen=True, slots=True)
class RoverView:
    """What the console knows about one rover."""

    id: str
    """Rover id, e.g. ``"mapper"``."""
    role: Literal["mapper", "hider", "seeker"]
    """The rover's role in the game."""
    pose: Pose | None
    """Pose the rover *believes* (dead reckoning), map frame; None before its first report."""
    true_pose: Pose | None = None
    """Ground-truth pose in the map frame (simulated rovers only), for showing drift."""
    path: tuple[Point, ...] = ()
    """Planned path, from the rover towards its goal, map frame [cm]."""
    target: Point | None = None
    """Current goal: the mapper's viewpoint, or the hider's / seeker's destination."""
    link: str = "memory"
    """How the rover is attached: ``memory``, ``serial:/dev/pts/3``, ``tcp:...``."""


@dataclass(frozen=True, slots=True)
class QueueStats:
    """One mailbox, as its `statistics()` reports it."""

    rover: str
    """Owning rover id, or ``"server"`` / ``"world"``."""
    name: str
    """Mailbox name, e.g. ``"mapper/lidar"``."""
    depth: int
    """Messages waiting now."""
    capacity: int
    """Maximum depth."""
    rate_hz: float
    """Messages received per simulated second, recent average [msg/s]."""
    drops: int
    """Overflow drops since start."""


@dataclass(frozen=True, slots=True)
class LogLine:
    """One traced message, already decoded to names (never raw integers)."""

    seq: int
    """Run-wide increasing number (see module docstring)."""
    time_s: float
    """Simulated time [s]."""
    actor: str
    """Receiving (or acting) actor, e.g. ``"mapper/motor"``."""
    queue: str
    """Queue it went through, e.g. ``"mapper/motor"``; ``""`` for non-queue events."""
    text: str
    """Decoded message, e.g. ``"MOTOR_MOVE 12.5 cm"`` or ``"DROP overflow LIDAR_SAMPLE"``."""


@dataclass(frozen=True, slots=True)
class TreeNode:
    """A supervisor or worker in the supervision tree, with its children in start order."""

    name: str
    """Registered name, e.g. ``"mapper/lidar"``."""
    kind: Literal["supervisor", "worker"]
    """Node kind."""
    state: Literal["running", "restarting", "stopped"]
    """Current state; a hung actor being cancelled is ``restarting``."""
    restarts: int = 0
    """Restarts since the system started."""
    last_exit: str | None = None
    """Reason of the last exit (``crashed: ZeroDivisionError``, ``hung``, ...), None if never."""
    last_exit_s: float | None = None
    """Simulated time of the last exit [s]; the console flashes a node for a while after it."""
    children: tuple[TreeNode, ...] = ()
    """Children in start order (empty for workers)."""

    def walk(self, depth: int = 0):
        """Yield (depth, node) depth-first, this node first."""
        yield depth, self
        for child in self.children:
            yield from child.walk(depth + 1)


@dataclass(frozen=True, slots=True)
class LinkStats:
    """The server's view of one rover link."""

    rover: str
    """Rover id."""
    up: bool
    """Heartbeats arriving."""
    rtt_ms: float | None
    """Round-trip time, recent average [ms]; None when unknown."""
    lost: int = 0
    """Frames known lost (gaps in seq)."""
    resent: int = 0
    """Frames resent for lack of an ack."""
    bad_frames: int = 0
    """Frames rejected (not JSON, too long, no cmd)."""
    frames_in: int = 0
    """Frames received by the server."""
    frames_out: int = 0
    """Frames sent by the server."""


@dataclass(frozen=True, slots=True)
class TimelineEvent:
    """A game event or fault on the timeline."""

    seq: int
    """Run-wide increasing number (see module docstring)."""
    time_s: float
    """Simulated time [s]."""
    kind: str
    """``phase``, ``fault``, ``clear``, ``crash``, ``restart``, ``link``, ``game``, ``export``."""
    text: str
    """One line for a person."""


@dataclass(frozen=True, slots=True)
class ActiveFault:
    """A fault in force now."""

    id: str
    """Fault id, accepted by `Controller.clear_fault`."""
    target: str
    """What it acts on (``mapper/lidar`` actor or ``mapper.lidar`` device)."""
    kind: str
    """Fault kind from the catalogue, e.g. ``crash``, ``dead``, ``drop``."""
    started_s: float
    """Simulated start time [s]."""
    until_s: float | None
    """Simulated end time [s]; None until cleared."""


@dataclass(frozen=True, slots=True)
class FaultTarget:
    """One entry of the fault catalogue: a target and the kinds it accepts."""

    target: str
    """Actor name (``mapper/lidar``) or device (``mapper.lidar``)."""
    kinds: tuple[str, ...]
    """Fault kinds valid for this target."""
    params: dict[str, dict[str, float]] = field(default_factory=dict)
    """Kind -> its parameters with their defaults (kinds without parameters may be absent)."""


@dataclass(frozen=True, slots=True)
class Snapshot:
    """Everything the console shows, at one simulated instant (see module docstring)."""

    time_s: float
    """Simulated time [s]."""
    speed: float | None
    """Clock rate (1, 4, 16 ...), None for "as fast as possible"."""
    paused: bool
    """Simulated time stopped."""
    scenario: str
    """Scenario name."""
    seed: int
    """Seed of the run's generator."""
    phase: str
    """Game phase, one of `PHASES`."""
    speed_reached: float | None = None
    """Simulated seconds per wall second actually reached lately (None: not measured);
    below ``speed`` when the machine cannot keep up."""
    guesses: int = 0
    """Seek guesses made so far in this game."""
    map: GridView | None = None
    """The mapper's occupancy grid; None before its first update."""
    truth: GridView | None = None
    """Ground truth in the same frame (simulated rooms only)."""
    rovers: tuple[RoverView, ...] = ()
    """All rovers, in a stable order."""
    lidar_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """Latest LIDAR revolution, float array (n, 2) of (x, y) in the map frame [cm]."""
    hide_spot: Pose | None = None
    """Chosen hide spot, once chosen."""
    seek_guesses: tuple[Point, ...] = ()
    """Places the seeker was sent to look, oldest first."""
    queues: tuple[QueueStats, ...] = ()
    """Every mailbox, grouped by rover."""
    log: tuple[LogLine, ...] = ()
    """Newest traced messages, oldest first, at most `MAX_LOG_LINES`."""
    tree: TreeNode | None = None
    """Root of the supervision tree."""
    links: tuple[LinkStats, ...] = ()
    """One per rover."""
    timeline: tuple[TimelineEvent, ...] = ()
    """Newest events, oldest first, at most `MAX_TIMELINE`."""
    faults: tuple[ActiveFault, ...] = ()
    """Faults in force now."""
    catalogue: tuple[FaultTarget, ...] = ()
    """Fault targets and kinds the system accepts (for the fault dialog)."""
    refused: tuple[str, ...] = ()
    """`Controller` methods refused whatever the phase (a rover attached: ``pause``,
    ``resume``, ``set_speed``; an auto game: the game commands); their keys are greyed."""

    def __post_init__(self) -> None:
        _check(self.phase in PHASES,
               f"phase must be one of {', '.join(PHASES)}, got {self.phase!r}")
        _check(self.speed is None or self.speed > 0,
               f"speed must be > 0 or None, got {self.speed!r}")
        pts = self.lidar_points
        if not isinstance(pts, np.ndarray) or pts.ndim != 2 or pts.shape[1] != 2:
            raise TypeError(f"lidar_points must be a numpy array (n, 2), got "
                            f"{type(pts).__name__}{getattr(pts, 'shape', '')}")
        _check(len(self.log) <= MAX_LOG_LINES,
               f"log holds at most {MAX_LOG_LINES} lines, got {len(self.log)}")
        _check(len(self.timeline) <= MAX_TIMELINE,
               f"timeline holds at most {MAX_TIMELINE} events, got {len(self.timeline)}")

    def rover(self, rover_id: str) -> RoverView | None:
        """The rover with this id, or None."""
        for r in self.rovers:
            if r.id == rover_id:
                return r
        return None


@dataclass(frozen=True, slots=True)
class CommandResult:
    """The outcome of one `Controller` call, published when known.

    Raises:
        ValueError: when ``status`` is not one of `RESULT_STATUSES`.
    """

    command: str
    """Controller method name, e.g. ``"hide_at"``."""
    status: Literal["ok", "refused", "error"]
    """``ok``; ``refused`` (not valid now: wrong phase, bad spot, busy); ``error`` (failed)."""
    reason: str = ""
    """For a person: why refused or what failed; for ``ok`` an optional detail (a path)."""

    def __post_init__(self) -> None:
        _check(self.status in RESULT_STATUSES,
               f"status must be ok, refused or error, got {self.status!r}")


Publish = Callable[[Snapshot | CommandResult], None]
"""Given to `System.run`: hand a snapshot or a command result to the console.
Synchronous, never blocks, safe to call from any Trio task."""


@runtime_checkable
class Controller(Protocol):
    """Commands from the console. Every method is synchronous and non-blocking and
    never raises; its outcome arrives later as a `CommandResult` (see module docstring)."""

    def start_mapping(self) -> None:
        """Start the mapping phase (valid in ``idle``)."""

    def stop_mapping(self) -> None:
        """Stop mapping early and use the map as it is (valid in ``mapping``)."""

    def hide_at(self, x_cm: float, y_cm: float, heading_deg: float) -> None:
        """Send the hider to a spot (valid in ``map_ready``); refused when the spot is invalid."""

    def seek_at(self, x_cm: float, y_cm: float, within_cm: float | None = None) -> None:
        """Send the seeker to look at a place (valid in ``hidden`` and ``not_found``);
        ``within_cm`` asks for a wider search: the hider is believed within that of it."""

    def new_game(self) -> None:
        """Reset the game to ``idle`` (the map may be kept or re-made by the system)."""

    def pause(self) -> None:
        """Stop simulated time."""

    def resume(self) -> None:
        """Restart simulated time at the current speed."""

    def set_speed(self, rate: float | None) -> None:
        """Clock rate: 1, 4, 16 ... or None for "as fast as possible"."""

    def inject_fault(self, target: str, kind: str, duration_s: float | None,
                     params: Mapping[str, Any]) -> None:
        """Inject a catalogue fault on a target for ``duration_s`` simulated [s]
        (None: until cleared). ``params`` are kind-specific (e.g. ``{"loss": 0.3}``)."""

    def clear_fault(self, fault: str) -> None:
        """Clear a fault by its id, or every fault on a target by the target's name."""

    def export_map(self, directory: str) -> None:
        """Save the current map (PGM + YAML, PNG) into a directory; ``ok`` names the files."""


@runtime_checkable
class System(Controller, Protocol):
    """What the console runs: a `Controller` plus its Trio side.

    The console starts Trio in guest mode with ``clock`` and calls `run` as the
    root task; cancelling that run is how the console shuts the system down.
    """

    clock: trio.abc.Clock
    """The clock the Trio run uses. The system owns it: speed changes and pause
    are done by the system, from inside Trio for a `trio.testing.MockClock`
    (its ``rate`` and ``autojump_threshold``: changing it from outside would not
    wake a sleeping run), or at once for a `tui.governor.GovernedClock`, which
    looks at its rate again at least every `tui.governor.POLL_S`."""

    async def run(self, publish: Publish, requests: trio.abc.ReceiveChannel[None]) -> None:
        """Run the system until cancelled.

        Args:
            publish: hands a `Snapshot` or a `CommandResult` to the console.
            requests: yields ``None`` each time the console wants a fresh
                snapshot; answer each with one ``publish(snapshot)``.
        """
