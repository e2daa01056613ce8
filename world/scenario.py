"""Scenarios: the room, its obstacles, the rovers' start poses and the game's choices.

A scenario is a TOML file (format in ``docs/scenarios.md``); built-in ones
live in ``world/scenarios/`` and are selected by name. Loading validates
everything a run relies on, and a bad file is refused with a `ScenarioError`
that names the file, the key and the rule, e.g.::

    my.toml: obstacles[2].circle: lies partly outside the room (600 x 450 cm)
"""

from __future__ import annotations

import math
import pathlib
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import shapely

from actors.firmware.hardware import ROLES
from world.faults import DEVICE_FAULTS, check_fault, is_actor_fault, split_target
from world.geometry import Pose, circle, footprint, room_polygon
from world.params import DeviceParams

__all__ = [
    "Scenario", "ScenarioError", "ScheduledFault", "load_scenario", "builtin_scenarios",
    "parse_scenario", "generate_scenario", "parse_generated", "ROOM_FAMILIES",
]

#: room sizes accepted [cm]
MIN_ROOM_CM, MAX_ROOM_CM = 50.0, 5000.0
#: at most this many obstacles / faults / seek guesses in a file
MAX_OBSTACLES, MAX_FAULTS, MAX_GUESSES = 500, 200, 50

TOP_KEYS = {"name", "description", "room", "obstacles", "rovers", "game", "devices", "faults"}

#: the target name of a rover's link in ``[[faults]]`` (the server's link-fault target,
#: ``server.link_faults.LINK_TARGET``; the world may not import the server)
LINK = "link"
#: the simulated device whose faults a link's are (the same kinds and parameters:
#: ``tests/test_link_faults.py`` checks that the two tables agree)
LINK_DEVICE = "wifly"


class ScenarioError(ValueError):
    """Raised by `load_scenario` / `parse_scenario` when a scenario is invalid.

    The message is ``<file>: <key>: <what is wrong>``, fit to show a user as is.
    """


@dataclass(frozen=True, slots=True)
class ScheduledFault:
    """A fault from the scenario's ``[[faults]]`` schedule."""

    at_s: float
    target: str
    kind: str
    duration_s: float = 0.0
    params: dict[str, float] = field(default_factory=dict)

    @property
    def is_actor_fault(self) -> bool:
        """True for crash/hang/flood: performed by the actor runtime, not the world."""
        return is_actor_fault(self.kind)

    @property
    def world_target(self) -> str:
        """The target in a simulated world: ``ROLE/link`` (a rover's link, broken by the
        server when the rover is attached) is the simulated rover's WiFly, whose faults
        have the same kinds and parameters."""
        role, _, device = self.target.partition("/")
        return f"{role}/{LINK_DEVICE}" if device == LINK else self.target


@dataclass(frozen=True, slots=True)
class Scenario:
    """A validated scenario (room frame, [cm] and [deg])."""

    name: str
    room_size: tuple[float, float]
    """Width, height [cm]; walls on all four sides."""
    obstacles: tuple[shapely.Geometry, ...]
    """Obstacles as shapely polygons (circles already polygonised) [cm]."""
    starts: dict[str, Pose]
    """Start pose per role (mapper, hider, seeker)."""
    hide_at: Pose | None = None
    """Where the hider goes in a headless run."""
    seek_at: tuple[tuple[float, float], ...] = ()
    """The seeker's guesses in a headless run, in order [cm]."""
    devices: dict[str, Any] = field(default_factory=dict)
    """Overrides of `DeviceParams` defaults."""
    faults: tuple[ScheduledFault, ...] = ()
    """Fault schedule, device and actor faults alike, sorted by time."""
    description: str = ""
    source: str = ""
    """Where it came from: a file path, ``builtin:<name>`` or ``generated:<seed>/<index>``."""

    def params(self) -> DeviceParams:
        """Device parameters with this scenario's overrides applied."""
        return DeviceParams().with_overrides(self.devices)

    @property
    def actor_faults(self) -> tuple[ScheduledFault, ...]:
        """The scheduled crash/hang/flood faults, for the system to hand to the runtime."""
        return tuple(f for f in self.faults if f.is_actor_fault)


def _check_scheduled(target: Any, kind: Any, duration_s: Any,
                     params: dict[str, Any]) -> dict[str, float]:
    """`check_fault` for a ``[[faults]]`` entry, which may also name ``ROLE/link`` with a
    link fault's kind (a WiFly device fault's)."""
    if isinstance(target, str) and target.endswith(f"/{LINK}"):
        role, _ = split_target(target)
        if kind not in DEVICE_FAULTS[LINK_DEVICE]:
            raise ValueError(f"link faults are {', '.join(DEVICE_FAULTS[LINK_DEVICE])}, "
                             f"got {kind!r}")
        return check_fault(f"{role}/{LINK_DEVICE}", kind, duration_s, params)
    return check_fault(target, kind, duration_s, params)


# --------------------------------------------------------------------- public API

def builtin_scenarios() -> list[str]:
    """Names of the built-in scenarios, roughly easiest first."""
    files = [p for p in resources.files("world.scenarios").iterdir() if p.name.endswith(".toml")]
    order = []
    for p in files:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
        order.append((data.get("difficulty", 99), p.name[:-5]))
    return [name for _, name in sorted(order)]


def load_scenario(name_or_path: str) -> Scenario:
    """Load and validate a built-in scenario by name, or a TOML file by path.

    Raises:
        ScenarioError: no such scenario, unreadable file, or invalid content.
    """
    if not isinstance(name_or_path, str) or not name_or_path:
        raise ScenarioError(f"scenario must be a name or a path, got {name_or_path!r}")
    res = resources.files("world.scenarios").joinpath(f"{name_or_path}.toml")
    if "/" not in name_or_path and not name_or_path.endswith(".toml") and res.is_file():
        return parse_scenario(res.read_text(encoding="utf-8"), f"builtin:{name_or_path}")
    path = pathlib.Path(name_or_path)
    if not path.is_file():
        raise ScenarioError(
            f"{name_or_path}: no such scenario file or built-in name "
            f"(built-ins: {', '.join(builtin_scenarios())})")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read: {exc}") from None
    return parse_scenario(text, str(path))


#: families of procedural rooms: the default (`world.generator`: boxes and round
#: obstacles) and ``passages`` (`world.passage_rooms`: parts joined by 25-45 cm gaps)
ROOM_FAMILIES = ("obstacles", "passages")


def generate_scenario(seed: int, index: int = 0, family: str = "obstacles") -> Scenario:
    """A seeded procedural room of ``family`` (`ROOM_FAMILIES`); valid by construction.

    Raises:
        ScenarioError: an unknown family.
    """
    # the generators build on this module: imported here
    if family == "obstacles":
        from world.generator import generate  # noqa: PLC0415

        return generate(seed, index)
    if family == "passages":
        from world.passage_rooms import generate_passages  # noqa: PLC0415

        return generate_passages(seed, index)
    raise ScenarioError(f"room family must be one of {', '.join(ROOM_FAMILIES)}, "
                        f"got {family!r}")


def parse_generated(text: str) -> tuple[int, int, str]:
    """Read ``SEED:INDEX`` (the default family) or ``FAMILY:SEED:INDEX`` into
    (seed, index, family), the arguments of `generate_scenario`.

    Raises:
        ScenarioError: malformed text or an unknown family.
    """
    parts = text.strip().split(":") if isinstance(text, str) else []
    family = parts.pop(0) if len(parts) == 3 else ROOM_FAMILIES[0]
    try:
        seed, index = (int(v) for v in parts)
    except ValueError:
        raise ScenarioError(f"a generated room must be [FAMILY:]SEED:INDEX, got {text!r}"
                            ) from None
    if family not in ROOM_FAMILIES:
        raise ScenarioError(f"room family must be one of {', '.join(ROOM_FAMILIES)}, "
                            f"got {family!r}")
    if seed < 0 or index < 0:
        raise ScenarioError(f"a generated room's seed and index must be >= 0, got {text!r}")
    return seed, index, family


def parse_scenario(text: str, source: str = "<string>") -> Scenario:
    """Parse and validate scenario TOML text; ``source`` names it in errors.

    Raises:
        ScenarioError: the text is not TOML or breaks a rule of the format.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    return _Parser(source).scenario(data)


# --------------------------------------------------------------------- validation

class _Parser:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, what: str) -> ScenarioError:
        return ScenarioError(f"{self.source}: {key}: {what}")

    def table(self, data: Any, key: str, allowed: set[str], required: set[str]) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, f"must be a table, got {type(data).__name__}")
        for k in data:
            if k not in allowed:
                raise self.fail(f"{key}.{k}" if key else k,
                                f"unknown key (allowed: {', '.join(sorted(allowed))})")
        for k in sorted(required):
            if k not in data:
                raise self.fail(f"{key}.{k}" if key else k, "missing")
        return data

    def numbers(self, value: Any, key: str, n: int) -> list[float]:
        if (not isinstance(value, list) or len(value) != n
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
            raise self.fail(key, f"must be a list of {n} numbers, got {value!r}")
        if any(not math.isfinite(v) for v in value):
            raise self.fail(key, f"must be finite numbers, got {value!r}")
        return [float(v) for v in value]

    def scenario(self, data: dict) -> Scenario:
        self.table(data, "", TOP_KEYS | {"difficulty"}, {"name", "room", "rovers"})
        name = data["name"]
        if not isinstance(name, str) or not name.strip():
            raise self.fail("name", f"must be a non-empty string, got {name!r}")
        desc = data.get("description", "")
        if not isinstance(desc, str):
            raise self.fail("description", f"must be a string, got {desc!r}")
        if "difficulty" in data and (isinstance(data["difficulty"], bool)
                                     or not isinstance(data["difficulty"], int)):
            raise self.fail("difficulty", f"must be an integer, got {data['difficulty']!r}")
        room = self.table(data["room"], "room", {"size_cm"}, {"size_cm"})
        w, h = self.numbers(room["size_cm"], "room.size_cm", 2)
        if not (MIN_ROOM_CM <= w <= MAX_ROOM_CM and MIN_ROOM_CM <= h <= MAX_ROOM_CM):
            raise self.fail("room.size_cm", f"each side must be {MIN_ROOM_CM:g}..{MAX_ROOM_CM:g} "
                                            f"cm, got {w:g} x {h:g}")
        floor = room_polygon(w, h)
        obstacles = self.obstacles(data.get("obstacles", []), floor, w, h)
        devices = self.table(data.get("devices", {}), "devices", set(DeviceParams.__slots__),
                             set())
        params = DeviceParams()
        for k, v in devices.items():
            try:
                params = params.with_overrides({k: v})
            except ValueError as exc:
                raise self.fail(f"devices.{k}", str(exc)) from None
        starts = self.rovers(data["rovers"], floor, obstacles, params, w, h)
        hide_at, seek_at = self.game(data.get("game", {}), floor)
        faults = self.faults(data.get("faults", []))
        return Scenario(
            name=name, room_size=(w, h), obstacles=tuple(obstacles), starts=starts,
            hide_at=hide_at, seek_at=tuple(seek_at), devices=dict(data.get("devices", {})),
            faults=tuple(sorted(faults, key=lambda f: f.at_s)), description=desc,
            source=self.source)

    def obstacles(self, items: Any, floor, w: float, h: float) -> list:
        if not isinstance(items, list):
            raise self.fail("obstacles", "must be an array of tables ([[obstacles]])")
        if len(items) > MAX_OBSTACLES:
            raise self.fail("obstacles", f"at most {MAX_OBSTACLES} obstacles, got {len(items)}")
        out = []
        for i, item in enumerate(items):
            key = f"obstacles[{i}]"
            self.table(item, key, {"box", "circle", "polygon"}, set())
            if len(item) != 1:
                raise self.fail(key, "must have exactly one of box, circle, polygon")
            (kind, value), = item.items()
            key = f"{key}.{kind}"
            if kind == "box":
                x, y, bw, bh = self.numbers(value, key, 4)
                if bw <= 0 or bh <= 0:
                    raise self.fail(key, f"width and height must be > 0, got {bw:g}, {bh:g}")
                geom = shapely.box(x, y, x + bw, y + bh)
            elif kind == "circle":
                cx, cy, r = self.numbers(value, key, 3)
                if r <= 0:
                    raise self.fail(key, f"radius must be > 0, got {r:g}")
                geom = circle(cx, cy, r)
            else:
                if not isinstance(value, list) or len(value) < 3:
                    raise self.fail(key, "must be a list of at least 3 [x, y] points, "
                                         f"got {value!r}")
                pts = [self.numbers(p, f"{key}[{j}]", 2) for j, p in enumerate(value)]
                geom = shapely.Polygon(pts)
                if not geom.is_valid or geom.area <= 0:
                    raise self.fail(key, "must be a simple polygon with non-zero area "
                                         "(edges must not cross)")
            if not floor.buffer(1e-6).contains(geom):
                raise self.fail(key, f"lies partly outside the room ({w:g} x {h:g} cm)")
            out.append(geom)
        return out

    def rovers(self, data: Any, floor, obstacles: list, params: DeviceParams,
               w: float, h: float) -> dict[str, Pose]:
        self.table(data, "rovers", set(ROLES), set(ROLES))
        starts: dict[str, Pose] = {}
        bodies = {}
        for role in ROLES:
            key = f"rovers.{role}"
            pose = Pose(*self.numbers(data[role], key, 3))
            body = footprint(pose, params.length_cm, params.width_cm)
            if not floor.contains(body):
                raise self.fail(key, f"rover at ({pose.x:g}, {pose.y:g}) does not fit inside the "
                                     f"room ({w:g} x {h:g} cm)")
            for i, obs in enumerate(obstacles):
                if body.intersects(obs):
                    raise self.fail(key, f"start pose ({pose.x:g}, {pose.y:g}) is inside or "
                                         f"touches obstacles[{i}]")
            for other, ob in bodies.items():
                if body.intersects(ob):
                    raise self.fail(key, f"overlaps the {other} rover's start pose")
            starts[role] = pose
            bodies[role] = body
        return starts

    def game(self, data: Any, floor) -> tuple[Pose | None, list[tuple[float, float]]]:
        self.table(data, "game", {"hide_at", "seek_at"}, set())
        hide_at = None
        if "hide_at" in data:
            hide_at = Pose(*self.numbers(data["hide_at"], "game.hide_at", 3))
            if not floor.contains(shapely.Point(hide_at.x, hide_at.y)):
                raise self.fail("game.hide_at",
                                f"({hide_at.x:g}, {hide_at.y:g}) is outside the room")
        guesses = data.get("seek_at", [])
        if not isinstance(guesses, list) or len(guesses) > MAX_GUESSES:
            raise self.fail("game.seek_at",
                            f"must be a list of at most {MAX_GUESSES} [x, y] points")
        seek_at = []
        for i, g in enumerate(guesses):
            x, y = self.numbers(g, f"game.seek_at[{i}]", 2)
            if not floor.contains(shapely.Point(x, y)):
                raise self.fail(f"game.seek_at[{i}]", f"({x:g}, {y:g}) is outside the room")
            seek_at.append((x, y))
        return hide_at, seek_at

    def faults(self, items: Any) -> list[ScheduledFault]:
        if not isinstance(items, list):
            raise self.fail("faults", "must be an array of tables ([[faults]])")
        if len(items) > MAX_FAULTS:
            raise self.fail("faults", f"at most {MAX_FAULTS} faults, got {len(items)}")
        out = []
        for i, item in enumerate(items):
            key = f"faults[{i}]"
            self.table(item, key, {"at_s", "target", "kind", "duration_s", "params"},
                       {"at_s", "target", "kind"})
            at = item["at_s"]
            if isinstance(at, bool) or not isinstance(at, (int, float)) or at < 0:
                raise self.fail(f"{key}.at_s", f"must be a number >= 0, got {at!r}")
            params = item.get("params", {})
            if not isinstance(params, dict):
                raise self.fail(f"{key}.params", "must be a table")
            try:
                full = _check_scheduled(item["target"], item["kind"], item.get("duration_s", 0),
                                        params)
            except ValueError as exc:
                raise self.fail(key, str(exc)) from None
            out.append(ScheduledFault(float(at), item["target"], item["kind"],
                                      float(item.get("duration_s", 0)), full))
        return out
