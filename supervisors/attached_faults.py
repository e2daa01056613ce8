"""A scenario's ``[[faults]]`` for rovers attached over a link: sent when they fall due.

A scheduled fault on a role that is not simulated here (``hideseek play
--rover mapper=...``, ``hideseek serve --rover mapper=...``) cannot act in this
process's world or runtime: at its time it goes to the attached rover through
the server (`server.rover_faults`: a ``fault`` frame, or a link fault for
target ``link``), exactly as the console's fault dialog sends it. A fault
whose rover is not attached at its time is reported (an event), not retried.
Scenarios and their faults are `world.scenario` records, taken by their fields
(this module is not wiring: it does not import the world).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import trio

__all__ = ["attached_schedule", "simulated_only", "send_scheduled_faults"]


def attached_schedule(scenario: Any, simulated: Sequence[str]) -> list[Any]:
    """The scheduled faults whose rover is not among the ``simulated`` roles."""
    return [f for f in scenario.faults if f.target.split("/")[0] not in simulated]


def simulated_only(scenario: Any, simulated: Sequence[str]) -> Any:
    """``scenario`` with only the faults of simulated roles (the same object when that is
    all of them)."""
    keep = tuple(f for f in scenario.faults if f.target.split("/")[0] in simulated)
    if len(keep) == len(scenario.faults):
        return scenario
    return dataclasses.replace(scenario, faults=keep)


async def send_scheduled_faults(server: Any, faults: Sequence[Any],
                                on_refused: Callable[[str], None]) -> None:
    """Send each fault to its attached rover at its time [s from now], in order."""
    t0 = trio.current_time()
    for f in sorted(faults, key=lambda f: f.at_s):
        await trio.sleep_until(t0 + f.at_s)
        role, _, target = f.target.partition("/")
        try:
            server.rover_fault(role, "inject", target, f.kind, f.duration_s, dict(f.params))
        except ValueError as exc:
            on_refused(f"scheduled {f.kind} on {f.target} at {f.at_s:g} s: {exc}")
