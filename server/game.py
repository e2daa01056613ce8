"""The game state machine of DESIGN.md section 6: a pure class driven by events.

::

    idle --start_mapping--> mapping --map uploaded--> map_ready
    mapping --stop_mapping--> mapping (stop sent, waiting for the map)
    map_ready --hide(x, y, heading)--> hiding --arrived--> hidden
    hiding --invalid_spot(reason)--> map_ready
    hidden | not_found --seek(x, y[, heading])--> seeking --found--> found
    seeking --not_found--> not_found
    any --new_game--> idle

`Game` knows nothing of links or time: operator commands (`command`) and rover
reports (`on_rover`, `on_map`) return a `Result` saying whether they were
accepted (with the reason when not) and which frames to send to which role.
Spots are in the map frame (the mapper's start frame) unless the operator
gives ``frame="room"``; the rovers' room-frame start poses (configuration)
turn into the ``origin`` each rover receives.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field

from .protocol import (
    DESTINATION,
    MAX_WITHIN_CM,
    ORIGIN,
    START,
    STOP,
    ZERO_POSE,
    Frame,
    GridMap,
    Pose,
    compose,
    inverse,
    make_frame,
)

__all__ = ["Phase", "Send", "Result", "Game", "COMMANDS"]


class Phase(enum.StrEnum):
    """Where the game is."""

    IDLE = "idle"
    MAPPING = "mapping"
    MAP_READY = "map_ready"
    HIDING = "hiding"
    HIDDEN = "hidden"
    SEEKING = "seeking"
    FOUND = "found"
    NOT_FOUND = "not_found"


COMMANDS = ("start_mapping", "stop_mapping", "hide", "seek", "new_game")
"""Operator commands accepted by `Game.command`."""


@dataclass(frozen=True, slots=True)
class Send:
    """A frame the server must send to the rover playing ``role``."""

    role: str
    frame: Frame


@dataclass(frozen=True, slots=True)
class Result:
    """What a command or report did: accepted or refused (with the reason), and frames to send."""

    ok: bool
    reason: str = ""
    sends: tuple[Send, ...] = ()

    def __bool__(self) -> bool:
        return self.ok


def _refuse(reason: str) -> Result:
    return Result(False, reason)


@dataclass
class Game:
    """One game, from idle to found.

    Args:
        start_poses: each role's start pose in the ROOM frame [cm, deg], from
            configuration. The mapper's defines the map frame; a missing
            mapper pose means the map frame is the room frame.
    """

    start_poses: Mapping[str, Pose] = field(default_factory=dict)
    phase: Phase = Phase.IDLE
    map: GridMap | None = None
    """The mapper's last uploaded map, None before the first."""
    stopping: bool = False
    """Stop was sent to the mapper; its map upload will end mapping."""
    hide_spot: Pose | None = None
    """Where the hider was sent (map frame)."""
    hider_pose: Pose | None = None
    """Where the hider reported arriving (map frame)."""
    guesses: list[Pose] = field(default_factory=list)
    """The seeker's destinations, in order (map frame)."""
    last_reason: str = ""
    """Why the game is in its phase: the reason of the invalid_spot or not_found
    that put it there, empty in any other phase (so a phase never shows the
    reason of an earlier one)."""
    _seeker_started: bool = False

    def _enter(self, phase: Phase, reason: str = "") -> None:
        self.phase, self.last_reason = phase, reason

    # -- frames ------------------------------------------------------------------

    def mapper_room_pose(self) -> Pose:
        """The mapper's start pose in the room frame (identity when not configured)."""
        return self.start_poses.get("mapper", ZERO_POSE)

    def room_to_map(self, p: Pose) -> Pose:
        """A room-frame pose in the map frame."""
        return compose(inverse(self.mapper_room_pose()), p)

    def map_to_room(self, p: Pose) -> Pose:
        """A map-frame pose in the room frame."""
        return compose(self.mapper_room_pose(), p)

    def origin_of(self, role: str) -> Pose | None:
        """The start pose of ``role`` in the map frame, None when not configured."""
        if role == "mapper":
            return ZERO_POSE
        p = self.start_poses.get(role)
        return None if p is None else self.room_to_map(p)

    # -- operator ------------------------------------------------------------------

    def command(self, name: str, *, x: float | None = None, y: float | None = None,
                heading: float | None = None, frame: str = "map",
                within: float | None = None) -> Result:
        """Apply an operator command; illegal ones are refused with a reason.

        ``within`` [cm] belongs to ``seek`` only: the hider is believed within that of
        (x, y), so the seeker searches that far round it (a wider search after a guess
        failed); without it the seeker looks within its IR range of the point.
        """
        if name not in COMMANDS:
            return _refuse(f"unknown command {name!r}; expected one of {', '.join(COMMANDS)}")
        if frame not in ("map", "room"):
            return _refuse(f"frame must be 'map' or 'room', got {frame!r}")
        if within is not None:
            if name != "seek":
                return _refuse(f"within applies to seek only, not {name}")
            try:
                within = float(within)
            except (TypeError, ValueError):
                return _refuse(f"within must be a number of cm, got {within!r}")
            if not 0.0 < within <= MAX_WITHIN_CM:
                return _refuse(f"within must be in (0, {MAX_WITHIN_CM:g}] cm, got {within:g}")
            return self._cmd_seek(x, y, heading, frame, within)
        return getattr(self, f"_cmd_{name}")(x, y, heading, frame)

    def _cmd_start_mapping(self, x, y, heading, frame) -> Result:
        if self.phase is not Phase.IDLE:
            return _refuse(f"start_mapping needs phase idle, the game is {self.phase}")
        self._enter(Phase.MAPPING)
        self.stopping = False
        return Result(True, sends=(Send("mapper", make_frame(ORIGIN, MAP_FRAME_ORIGIN)),
                                   Send("mapper", make_frame(START))))

    def _cmd_stop_mapping(self, x, y, heading, frame) -> Result:
        if self.phase is not Phase.MAPPING:
            return _refuse(f"stop_mapping needs phase mapping, the game is {self.phase}")
        if self.stopping:
            return _refuse("stop already sent; waiting for the mapper's map")
        self.stopping = True
        return Result(True, "stop sent; waiting for the mapper's map",
                      (Send("mapper", make_frame(STOP)),))

    def _spot(self, x, y, heading, frame, what: str) -> Pose | str:
        if x is None or y is None:
            return f"{what} needs x and y [cm]"
        try:
            p = Pose(float(x), float(y), float(heading or 0.0))
        except (TypeError, ValueError):
            return (f"{what} needs finite numbers for x, y and heading, "
                    f"got {x!r}, {y!r}, {heading!r}")
        if frame == "room":
            p = self.room_to_map(p)
        if self.map is not None:
            (ny, nx), r = self.map.shape, self.map.resolution_cm
            ox, oy = self.map.origin_cm
            if not (ox <= p.x < ox + nx * r and oy <= p.y < oy + ny * r):
                return (f"{what} spot ({p.x:.0f}, {p.y:.0f}) cm (map frame) is outside the map "
                        f"[{ox:.0f}..{ox + nx * r:.0f}] x [{oy:.0f}..{oy + ny * r:.0f}]")
        return p

    def _origin_and_spot(self, role: str, what: str, x, y, heading,
                         frame) -> tuple[Pose, Pose] | str:
        """The rover's start pose and the checked spot, or the reason to refuse."""
        origin = self.origin_of(role)
        if origin is None:
            return f"start pose of the {role} is not configured (--origin ID=X,Y,HEADING)"
        spot = self._spot(x, y, heading, frame, what)
        if isinstance(spot, str):
            return spot
        return origin, spot

    def _cmd_hide(self, x, y, heading, frame) -> Result:
        if self.phase is not Phase.MAP_READY:
            return _refuse(f"hide needs phase map_ready, the game is {self.phase}")
        placed = self._origin_and_spot("hider", "hide", x, y, heading, frame)
        if isinstance(placed, str):
            return _refuse(placed)
        origin, spot = placed
        self.hide_spot = spot
        self._enter(Phase.HIDING)
        dest = {"x": spot.x, "y": spot.y, "heading": None if heading is None else spot.heading_deg}
        return Result(True, sends=(Send("hider", make_frame(ORIGIN, _pose(origin))),
                                   Send("hider", make_frame(START)),
                                   Send("hider", make_frame(DESTINATION, dest))))

    def _cmd_seek(self, x, y, heading, frame, within: float | None = None) -> Result:
        if self.phase not in (Phase.HIDDEN, Phase.NOT_FOUND):
            return _refuse(f"seek needs phase hidden or not_found, the game is {self.phase}")
        placed = self._origin_and_spot("seeker", "seek", x, y, heading, frame)
        if isinstance(placed, str):
            return _refuse(placed)
        origin, spot = placed
        self.guesses.append(spot)
        self._enter(Phase.SEEKING)
        dest = {"x": spot.x, "y": spot.y, "heading": None if heading is None else spot.heading_deg}
        if within is not None:  # absent, not null: a plain guess's frame stays as it was
            dest["within"] = within
        sends = []
        if not self._seeker_started:
            self._seeker_started = True
            sends += [Send("seeker", make_frame(ORIGIN, _pose(origin))),
                      Send("seeker", make_frame(START))]
        sends.append(Send("seeker", make_frame(DESTINATION, dest)))
        return Result(True, sends=tuple(sends))

    def _cmd_new_game(self, x, y, heading, frame) -> Result:
        busy = {Phase.MAPPING: "mapper", Phase.HIDING: "hider", Phase.SEEKING: "seeker"}
        role = busy.get(self.phase)
        sends = (Send(role, make_frame(STOP)),) if role else ()
        keep = self.start_poses
        self.__init__(start_poses=keep)  # type: ignore[misc]
        return Result(True, sends=sends)

    # -- rovers ------------------------------------------------------------------------

    def on_map(self, grid: GridMap) -> Result:
        """The mapper uploaded a complete map."""
        if self.phase not in (Phase.MAPPING, Phase.MAP_READY):
            return _refuse(f"map upload ignored in phase {self.phase}")
        self.map = grid
        self._enter(Phase.MAP_READY)
        self.stopping = False
        return Result(True)

    def on_rover(self, role: str, cmd: str, pose: Pose | None = None,
                 reason: str = "") -> Result:
        """A rover reported ``arrived``, ``invalid_spot``, ``found`` or ``not_found``."""
        expect = {"arrived": ("hider", Phase.HIDING), "invalid_spot": ("hider", Phase.HIDING),
                  "found": ("seeker", Phase.SEEKING), "not_found": ("seeker", Phase.SEEKING)}
        if cmd not in expect:
            return _refuse(f"{cmd!r} is not a game report")
        want_role, want_phase = expect[cmd]
        if role != want_role:
            return _refuse(f"{cmd} comes from the {want_role}, not the {role}")
        if self.phase is not want_phase:
            return _refuse(f"{cmd} ignored in phase {self.phase}")
        if cmd == "arrived":
            self.hider_pose = pose
            self._enter(Phase.HIDDEN)
        elif cmd == "invalid_spot":
            self._enter(Phase.MAP_READY, reason)
        elif cmd == "found":
            self._enter(Phase.FOUND)
        else:
            self._enter(Phase.NOT_FOUND, reason)
        return Result(True, reason)

    # -- storage -----------------------------------------------------------------------

    def state(self) -> dict:
        """What the game holds besides its phase and map, as JSON-ready values (for storage)."""
        def pose(p: Pose | None) -> list[float] | None:
            return None if p is None else [p.x, p.y, p.heading_deg]

        return {"stopping": self.stopping, "hide_spot": pose(self.hide_spot),
                "hider_pose": pose(self.hider_pose), "guesses": [pose(g) for g in self.guesses],
                "last_reason": self.last_reason, "seeker_started": self._seeker_started}

    @classmethod
    def restored(cls, start_poses: Mapping[str, Pose], phase: str, state: dict,
                 grid: GridMap | None) -> Game:
        """The game as `state` and the stored phase and map describe it.

        Raises:
            ValueError: an unknown phase, or a phase past mapping without a map.
        """
        def pose(v) -> Pose | None:
            return None if v is None else Pose(*(float(x) for x in v))

        game = cls(start_poses=start_poses, phase=Phase(phase), map=grid,
                   stopping=bool(state.get("stopping", False)),
                   hide_spot=pose(state.get("hide_spot")),
                   hider_pose=pose(state.get("hider_pose")),
                   guesses=[p for p in map(pose, state.get("guesses", [])) if p is not None],
                   last_reason=str(state.get("last_reason", "")))
        game._seeker_started = bool(state.get("seeker_started", False))
        if grid is None and game.phase not in (Phase.IDLE, Phase.MAPPING):
            raise ValueError(f"a game in phase {phase} needs its map")
        return game

    @property
    def finished(self) -> bool:
        """True once the hider was found."""
        return self.phase is Phase.FOUND


def _pose(p: Pose) -> dict:
    """A pose as the wire's ``pose`` payload."""
    return {"x": p.x, "y": p.y, "heading": p.heading_deg}


MAP_FRAME_ORIGIN = {"x": 0, "y": 0, "heading": 0}
"""The mapper's ``origin`` payload: its start pose is the map frame's origin by
definition, written as the exact integers 0."""
