"""The rover's failure-injection hook: what the WiFly asks when a ``fault`` frame comes.

PX4's ``failure`` command is the model: the firmware answers every request,
and breaks nothing unless it was built or started to allow it (PX4's
``SYS_FAILURE_EN``; here ``hideseek rover --accept-faults``). The WiFly actor
owns the protocol side (it answers ``fault_reply`` reliably); a `FaultPort`
given by whoever builds the rover's tree does the breaking, on the rover's own
devices and actors. Without a port every fault is ``unsupported``.

A fault is applied once: `AnsweredFaults` remembers the replies to the last
faults answered, and a ``fault`` the server sends again (a server restarted
before the rover's acknowledgement was stored resends it in a new frame) is
answered with the same reply and not applied again.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Protocol

from server.protocol import FaultCommand

__all__ = ["AnsweredFaults", "FaultPort"]


class FaultPort(Protocol):
    """Applies faults to one rover's devices and actors."""

    def catalogue(self) -> tuple[str, ...]:
        """``TARGET/KIND`` faults the rover accepts now (empty unless it opted in)."""
        ...

    def apply(self, command: FaultCommand) -> tuple[str, str]:
        """Inject or clear one fault; returns ``(result, detail)`` with result
        ``accepted``, ``unsupported`` or ``refused``. Never raises for a bad request."""
        ...


class AnsweredFaults:
    """The replies to the last ``capacity`` faults answered, by ``fault_id`` (bounded: the
    oldest is forgotten first).

    A fault whose id and request match a remembered one is a duplicate: answered with
    the remembered reply, not applied. The same id with another request is a new fault
    (from a server that numbers its faults afresh) and replaces the remembered one.

    Args:
        capacity: fault ids remembered at most.
    """

    __slots__ = ("capacity", "duplicates", "_replies")

    def __init__(self, capacity: int = 64) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.capacity = capacity
        self.duplicates = 0
        """Faults answered again without being applied."""
        self._replies: OrderedDict[int, tuple[FaultCommand, tuple[str, str]]] = OrderedDict()

    def answer(self, command: FaultCommand,
               apply: Callable[[FaultCommand], tuple[str, str]]) -> tuple[str, str]:
        """The reply to ``command``: the remembered one for a duplicate, else what
        ``apply(command)`` returns (then remembered)."""
        fid = command.fault_id
        seen = self._replies.get(fid)
        if seen is not None and seen[0] == command:
            self.duplicates += 1
            self._replies.move_to_end(fid)
            return seen[1]
        reply = apply(command)
        self._replies[fid] = (command, reply)
        self._replies.move_to_end(fid)
        while len(self._replies) > self.capacity:
            self._replies.popitem(last=False)
        return reply

    def __len__(self) -> int:
        return len(self._replies)
