"""The rover's failure-injection hook: what the WiFly asks when a ``fault`` frame comes.

PX4's ``failure`` command is the model: the firmware answers every request,
and breaks nothing unless it was built or started to allow it (PX4's
``SYS_FAILURE_EN``; here ``hideseek rover --accept-faults``). The WiFly actor
owns the protocol side (it answers ``fault_reply`` reliably); a `FaultPort`
given by whoever builds the rover's tree does the breaking, on the rover's own
devices and actors. Without a port every fault is ``unsupported``.
"""

from __future__ import annotations

from typing import Protocol

from server.protocol import FaultCommand

__all__ = ["FaultPort"]


class FaultPort(Protocol):
    """Applies faults to one rover's devices and actors."""

    def catalogue(self) -> tuple[str, ...]:
        """``TARGET/KIND`` faults the rover accepts now (empty unless it opted in)."""
        ...

    def apply(self, command: FaultCommand) -> tuple[str, str]:
        """Inject or clear one fault; returns ``(result, detail)`` with result
        ``accepted``, ``unsupported`` or ``refused``. Never raises for a bad request."""
        ...
