"""Fault catalogue and the book of active faults.

A fault has a target ``rover/device`` (``mapper/lidar``, ``hider/motor_left``),
a kind, a start [s], a duration [s] (0 = until cleared) and parameters. Device
faults act inside the world; actor faults (``crash``, ``hang``, ``flood`` on a
firmware actor such as ``mapper/nav``) are only validated and passed on to the
runtime, which owns the actors.

The catalogue is data: device -> kind -> default parameters. ``encoder`` and
``motor`` without a side mean both treads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from world.params import ROLES

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
ACTOR_FAULTS: dict[str, dict[str, float]] = {
    "crash": {},
    "hang": {},
    "flood": {"messages": 100.0},
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

    Raises:
        ValueError: the target, kind, duration or a parameter is wrong; the message says which.
    """
    role, device = split_target(target)
    if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) or duration_s < 0:
        raise ValueError(f"fault duration_s must be a number >= 0, got {duration_s!r}")
    if not isinstance(kind, str):
        raise ValueError(f"fault kind must be a string, got {kind!r}")
    if kind in ACTOR_FAULTS and device not in DEVICE_FAULTS:
        defaults = ACTOR_FAULTS[kind]
    else:
        if device not in DEVICE_FAULTS:
            raise ValueError(
                f"unknown device {device!r} in fault target {target!r}; devices are "
                f"{', '.join(DEVICE_FAULTS)} (actor faults: {', '.join(ACTOR_FAULTS)})")
        if role not in ROLE_DEVICES.get(device, ROLES):
            raise ValueError(f"{role} has no {device} (fault target {target!r})")
        kinds = DEVICE_FAULTS[device]
        if kind not in kinds:
            raise ValueError(f"fault kind {kind!r} does not apply to {device}; "
                             f"kinds are {', '.join(kinds)}")
        defaults = kinds[kind]
    out = dict(defaults)
    for name, value in params.items():
        if name not in defaults:
            allowed = ", ".join(defaults) or "none"
            raise ValueError(f"fault {kind!r} has no parameter {name!r} (parameters: {allowed})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ValueError(f"fault parameter {name} must be a number >= 0, got {value!r}")
        out[name] = float(value)
    return out


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
