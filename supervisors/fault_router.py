"""One place that breaks a rover: device faults to the world, actor faults to the runtime.

Used by the simulated system (`supervisors.system.SimSystem`: the console,
the command line, a scenario's ``[[faults]]``) and by a rover in its own
process (`supervisors.rover_fault_port`: faults that come over the protocol),
so both take the same catalogue (`world.faults`) the same way:

* ``crash`` / ``hang`` / ``flood`` target a registered actor (``mapper/nav``):
  the runtime crashes it, blocks its next message for the hang's seconds (its
  watchdog fires), or posts the flood's no-op messages without waiting;
* every other kind targets a device (``mapper/lidar dead``) and goes to the
  world's fault book.
"""

from __future__ import annotations

from typing import Any

from actors import ActorSystem, Message
from actors.firmware.commands import Cmd

__all__ = ["ACTOR_FAULTS", "FaultError", "perform_actor_fault"]

ACTOR_FAULTS = ("crash", "hang", "flood")
_FLOOD_DEFAULT = 100  # messages a flood fault posts when not given (world.faults.ACTOR_FAULTS)


class FaultError(ValueError):
    """A fault request the system cannot carry out (bad target, kind or parameter)."""


def perform_actor_fault(actors: ActorSystem, target: str, kind: str, duration_s: float,
                        params: dict[str, Any]) -> None:
    """Crash, hang or flood the actor registered as ``target`` now.

    ``hang`` lasts ``params['seconds']``, else ``duration_s``, else 5 s;
    ``flood`` posts ``params['messages']`` (default 100) no-op messages.

    Raises:
        FaultError: no such actor, an unknown kind, or a parameter out of range.
    """
    if actors.whereis(target) is None:
        known = ", ".join(n for n in actors.names() if "/" in n)
        raise FaultError(f"no actor {target!r} to {kind}; actors are: {known}")
    if kind == "crash":
        actors.inject_crash(target)
    elif kind == "hang":
        seconds = float(params.get("seconds", duration_s or 5.0))
        if not seconds > 0:
            raise FaultError(f"hang needs seconds > 0, got {seconds!r}")
        actors.inject_hang(target, seconds)
    elif kind == "flood":
        count = int(params.get("messages", _FLOOD_DEFAULT))
        if not 1 <= count <= 1_000_000:
            raise FaultError(f"flood count must be within 1..1000000, got {count!r}")
        actors.flood(target, count, Message.int(Cmd.NOOP, 0))
    else:
        raise FaultError(f"unknown actor fault {kind!r}; expected {', '.join(ACTOR_FAULTS)}")
