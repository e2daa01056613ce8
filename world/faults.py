"""Fault catalogue and the book of active faults.

A fault has a target, a kind, a start [s], a duration [s] (0 = until cleared)
and parameters. The kind decides what the target names:

* device faults (``dead``, ``stuck``, ``loss`` ...) target ``rover/device``
  (``mapper/lidar``, ``hider/motor_left``) and act inside the world;
* actor faults (``crash``, ``hang``, ``flood``) target ``rover/actor``, a
  firmware actor (``mapper/nav``, ``hider/motor``, ``seeker/ir``); the world
  only validates them and hands them to the runtime, which owns the actors.

Some names are both a device and an actor (``motor``, ``lidar``, ``ir``,
``wifly``): ``hider/motor stalled`` stalls the treads, ``hider/motor crash``
crashes the motor-control actor. The catalogue is data: device -> kind ->
default parameters, actor kind -> default parameters, role -> actors.
``encoder`` and ``motor`` without a side mean both treads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from actors.firmware.hardware import ROLES

#: device -> kind -> {parameter: default}
DEVICE_FAULTS: dict[str, dict[str, dict[str, float]]] = {
    "lidar": {
        "dead": {},
        "garbage": {},
        "stuck": {},
        "noisy": {"sigma_cm": 10.0},
    },
    **{dev: {"stuck": {}, "slipping": {"ratio": 0.5}}
       for dev in ("encoder", "encoder_left", "encoder_right")},
    **{dev: {"stalled": {}, "weak": {"strength": 0.5}}
       for dev in ("motor", "motor_left", "motor_right")},
    "ir": {"stuck_high": {}, "stuck_low": {}},
    "wifly": {
        "down": {},
        "loss": {"percent": 20.0},
        "corrupt": {"per_byte": 0.01},
        "latency": {"added_s": 0.2},
    },
}

#: devices only some roles have
ROLE_DEVICES = {"lidar": ("mapper",), "ir": ("seeker",)}

#: kinds the actor runtime performs on firmware actors, with their parameters
#: (a hang lasts ``duration_s``)
ACTOR_FAULTS: dict[str, dict[str, float]] = {
    "crash": {},
    "hang": {},
    "flood": {"messages": 100.0},
}

#: the firmware actors of each rover, as ``supervisors/rover.py`` starts them (the
#: world may not import it; ``tests/test_faults.py`` checks that the two agree)
ROLE_ACTORS: dict[str, tuple[str, ...]] = {
    "mapper": ("wifly", "motor", "lidar", "map", "nav"),
    "hider": ("wifly", "motor", "nav"),
    "seeker": ("wifly", "motor", "ir", "nav"),
}


@dataclass(frozen=True, slots=True)
class Fault:
    """One injected fault."""

    id: int
    target: str
    kind: str
    start_s: float
    duration_s: float
    """0 means until cleared."""
    params: dict[str, float] = field(default_factory=dict)

    @property
    def role(self) -> str:
        return self.target.split("/", 1)[0]

    @property
    def device(self) -> str:
        return self.target.split("/", 1)[1]

    def expired(self, now: float) -> bool:
        """True once a fault with a duration has run its course."""
        return self.duration_s > 0 and now >= self.start_s + self.duration_s


def split_target(target: Any) -> tuple[str, str]:
    """``"rover/device"`` -> (rover, device).

    Raises:
        ValueError: not of that form or an unknown rover.
    """
    if not isinstance(target, str) or target.count("/") != 1:
        raise ValueError(f"fault target must be 'rover/device', got {target!r}")
    role, device = target.split("/")
    if role not in ROLES:
        raise ValueError(f"fault target rover must be one of {', '.join(ROLES)}, got {role!r}")
    if not device:
        raise ValueError(f"fault target {target!r} names no device")
    return role, device


def is_actor_fault(kind: str) -> bool:
    """True for the kinds the actor runtime performs (crash, hang, flood)."""
    return kind in ACTOR_FAULTS


def check_fault(target: Any, kind: Any, duration_s: Any,
                params: dict[str, Any]) -> dict[str, float]:
    """Validate a fault and return its parameters with defaults filled in.

    The kind decides the target's meaning: ``crash``/``hang``/``flood`` need a
    firmware actor (`ROLE_ACTORS`), every other kind a device (`DEVICE_FAULTS`).

    Raises:
        ValueError: the target, kind, duration or a parameter is wrong, or the kind
            does not fit the target; the message says which and lists what fits.
    """
    role, name = split_target(target)
    if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) or duration_s < 0:
        raise ValueError(f"fault duration_s must be a number >= 0, got {duration_s!r}")
    if not isinstance(kind, str):
        raise ValueError(f"fault kind must be a string, got {kind!r}")
    if kind in ACTOR_FAULTS:
        defaults = _actor_kind(role, name, kind, target)
    else:
        defaults = _device_kind(role, name, kind, target)
    out = dict(defaults)
    for pname, value in params.items():
        if pname not in defaults:
            allowed = ", ".join(defaults) or "none"
            raise ValueError(f"fault {kind!r} has no parameter {pname!r} (parameters: {allowed})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ValueError(f"fault parameter {pname} must be a number >= 0, got {value!r}")
        out[pname] = float(value)
    return out


def _actor_kind(role: str, actor: str, kind: str, target: str) -> dict[str, float]:
    """Defaults of an actor fault on ``role/actor``, or why it does not fit."""
    actors = ROLE_ACTORS[role]
    if actor in actors:
        return ACTOR_FAULTS[kind]
    hint = ""
    if actor in DEVICE_FAULTS and role in ROLE_DEVICES.get(actor, ROLES):
        hint = f"; device faults on {actor} are {', '.join(DEVICE_FAULTS[actor])}"
    raise ValueError(f"{kind!r} is an actor fault but {target!r} is not an actor; "
                     f"{role}'s actors are {', '.join(actors)}{hint}")


def _device_kind(role: str, device: str, kind: str, target: str) -> dict[str, float]:
    """Defaults of a device fault on ``role/device``, or why it does not fit."""
    if device not in DEVICE_FAULTS:
        if device in ROLE_ACTORS[role]:
            raise ValueError(f"{target!r} is an actor and {kind!r} is no actor fault; "
                             f"actor faults are {', '.join(ACTOR_FAULTS)}")
        raise ValueError(
            f"unknown device {device!r} in fault target {target!r}; devices are "
            f"{', '.join(DEVICE_FAULTS)} (actor faults: {', '.join(ACTOR_FAULTS)})")
    if role not in ROLE_DEVICES.get(device, ROLES):
        raise ValueError(f"{role} has no {device} (fault target {target!r})")
    kinds = DEVICE_FAULTS[device]
    if kind not in kinds:
        also = f" (actor faults: {', '.join(ACTOR_FAULTS)})" if device in ROLE_ACTORS[role] else ""
        raise ValueError(f"fault kind {kind!r} does not apply to {device}; "
                         f"kinds are {', '.join(kinds)}{also}")
    return kinds[kind]


class FaultBook:
    """Active device faults, looked up per (role, device) every tick.

    Not thread-safe and not async: the world owns it and touches it from its step.
    """

    def __init__(self) -> None:
        self._active: dict[int, Fault] = {}
        self._next_id = 1
        self._index: dict[tuple[str, str, str], Fault] = {}
        """(role, device, kind) -> latest fault; ``motor``/``encoder`` entered for both sides."""

    def __len__(self) -> int:
        return len(self._active)

    def _reindex(self) -> None:
        self._index = {}
        for f in self._active.values():
            devs = [f.device]
            if f.device in ("motor", "encoder"):
                devs = [f.device + "_left", f.device + "_right"]
            for d in devs:
                self._index[(f.role, d, f.kind)] = f

    def add(self, target: str, kind: str, start_s: float, duration_s: float,
            params: dict[str, float]) -> Fault:
        """Record an (already validated) fault and return it with its new id."""
        fault = Fault(self._next_id, target, kind, float(start_s), float(duration_s), params)
        self._next_id += 1
        self._active[fault.id] = fault
        self._reindex()
        return fault

    def remove(self, key: int | str) -> list[Fault]:
        """Remove a fault by id, or all faults on a target; returns the removed ones."""
        if isinstance(key, int) and not isinstance(key, bool):
            gone = [self._active.pop(key)] if key in self._active else []
        else:
            gone = [f for f in self._active.values() if f.target == key]
            for f in gone:
                del self._active[f.id]
        self._reindex()
        return gone

    def expired(self, now: float) -> list[Fault]:
        """Remove and return the faults whose duration has passed."""
        gone = [f for f in self._active.values() if f.expired(now)]
        for f in gone:
            del self._active[f.id]
        if gone:
            self._reindex()
        return gone

    def active(self) -> list[Fault]:
        """Active faults in injection order."""
        return list(self._active.values())

    def find(self, role: str, device: str, kind: str) -> Fault | None:
        """The latest active fault of ``kind`` on a device (``motor`` covers both treads)."""
        return self._index.get((role, device, kind))
