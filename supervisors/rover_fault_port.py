"""The `FaultPort` of a rover in its own process (``hideseek rover``): faults over the link.

A ``fault`` frame names a rover-local target (``lidar``, ``nav``, ``wifly``)
and a kind of the fault catalogue (`world.faults`); this port prefixes the
rover's role and hands it to the one path that breaks rovers
(`supervisors.fault_router`: device faults to the rover's world, actor faults
to its runtime). Without the opt-in (``--accept-faults``) a fault it knows is
``refused`` and hello lists none; one it does not know is ``unsupported``.
Every injection, clearance and refusal is reported through ``on_event``
(``fault_injected``, ``fault_cleared``, ``fault_refused``): the rover's log
and its ``tm_event`` stream.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from actors import ActorSystem
from server.protocol import FaultCommand
from supervisors.fault_router import FaultError, perform_actor_fault
from world.faults import (
    ACTOR_FAULTS,
    DEVICE_FAULTS,
    ROLE_ACTORS,
    ROLE_DEVICES,
    check_fault,
    is_actor_fault,
)
from world.world import World

__all__ = ["RoverFaultPort", "rover_catalogue"]

OnEvent = Callable[[str, str, str], None]
"""``on_event(kind, path, detail)``."""


def rover_catalogue(role: str) -> tuple[str, ...]:
    """Every ``TARGET/KIND`` of the catalogue that applies to a rover of ``role``."""
    out = [f"{dev}/{kind}" for dev, kinds in DEVICE_FAULTS.items()
           if role in ROLE_DEVICES.get(dev, (role,)) for kind in kinds]
    out += [f"{actor}/{kind}" for actor in ROLE_ACTORS[role] for kind in ACTOR_FAULTS]
    return tuple(out)


class RoverFaultPort:
    """Faults into this process's rover (see the module docstring).

    Args:
        world: the rover's world (its devices).
        actors: the rover's actor system.
        role: the rover's role (its actors are registered under it).
        accept: the opt-in: without it every known fault is refused.
        on_event: told of each injection, clearance and refusal.
    """

    def __init__(self, world: World, actors: ActorSystem, role: str, *, accept: bool,
                 on_event: OnEvent) -> None:
        self.world, self.actors, self.role = world, actors, role
        self.accept = accept
        self.on_event = on_event
        self._known = rover_catalogue(role)
        self._device_ids: dict[int, int] = {}  # fault_id -> the world's fault id

    def catalogue(self) -> tuple[str, ...]:
        return self._known if self.accept else ()

    def apply(self, command: FaultCommand) -> tuple[str, str]:
        target = f"{self.role}/{command.target}"
        if command.op == "clear":
            return self._clear(command, target)
        params = dict(command.params or {})
        duration = float(command.duration or 0.0)
        try:
            check_fault(target, command.kind, duration, params)
        except ValueError as exc:
            return "unsupported", str(exc)
        if not self.accept:
            detail = "this rover was not started with --accept-faults"
            self.on_event("fault_refused", target, f"{command.kind}: {detail}")
            return "refused", detail
        if is_actor_fault(command.kind):
            try:
                perform_actor_fault(self.actors, target, command.kind, duration, params)
            except FaultError as exc:
                return "unsupported", str(exc)
            self.on_event("fault_injected", target, command.kind)
            return "accepted", f"{command.kind} on {target}"
        fid = self.world.inject_fault(target, command.kind, duration, **params)
        self._device_ids[command.fault_id] = fid
        return "accepted", f"{command.kind} on {target}" + (
            f" for {duration:g} s" if duration else " until cleared")

    def _clear(self, command: FaultCommand, target: str) -> tuple[str, str]:
        kind = command.kind
        device = command.target
        if not any(k.split("/")[0] == device for k in self._known):
            return "unsupported", f"{self.role} has no {device!r}"
        if not self.accept:
            return "refused", "this rover was not started with --accept-faults"
        if kind == "*":
            n = self.world.clear_fault(target)
        else:
            n = 0
            for f in self.world.active_faults():
                if f.target == target and f.kind == kind:
                    n += self.world.clear_fault(f.id)
        return "accepted", f"{n} fault(s) cleared on {target}"

    def world_event(self, kind: str, target: str, detail: dict[str, Any]) -> None:
        """The world's event callback: its injections and clearances, as events."""
        if kind in ("fault_injected", "fault_cleared") and target.startswith(f"{self.role}/"):
            text = str(detail.get("kind", ""))
            if "reason" in detail:
                text += f" ({detail['reason']})"
            self.on_event(kind, target, text)
