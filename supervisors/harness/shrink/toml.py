"""A scenario written back as TOML (docs/scenarios.md), so a shrunk game is a file.

Obstacles are written as polygons with every vertex as the scenario holds
it (circles already polygonised, floats in full), so reading the file back
gives the same room to the last bit. Only what `world.scenario` reads is
written: name, description, room, obstacles, rovers, game, devices, faults.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from typing import Any

from world.scenario import Scenario, ScheduledFault


def _value(v: Any) -> str:
    """One TOML value: a string, a boolean, an integer, a float in full, or an array."""
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a TOML basic string
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML scenario values must be finite, got {v!r}")
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML scenario value")


def _fault(f: ScheduledFault) -> list[str]:
    params = ", ".join(f"{k} = {_value(float(v))}" for k, v in sorted(f.params.items()))
    return ["", "[[faults]]", f"at_s = {_value(float(f.at_s))}", f"target = {_value(f.target)}",
            f"kind = {_value(f.kind)}", f"duration_s = {_value(float(f.duration_s))}",
            f"params = {{ {params} }}" if params else "params = {}"]


def scenario_toml(scenario: Scenario, *, header: Iterable[str] = (),
                  faults: Iterable[ScheduledFault] | None = None) -> str:
    """The scenario as TOML text that `world.scenario.parse_scenario` reads back.

    Args:
        scenario: the room, its rovers, game and devices.
        header: comment lines for the top of the file (without ``#``).
        faults: the schedule to write (default: the scenario's own).
    """
    out = [f"# {line}".rstrip() for line in header]
    out += [f"name = {_value(scenario.name)}"]
    if scenario.description:
        out.append(f"description = {_value(scenario.description)}")
    width, height = scenario.room_size
    out += ["", "[room]", f"size_cm = {_value([float(width), float(height)])}"]
    for obstacle in scenario.obstacles:
        ring = [[float(x), float(y)] for x, y in obstacle.exterior.coords]
        out += ["", "[[obstacles]]", f"polygon = {_value(ring)}"]
    out += ["", "[rovers]"]
    out += [f"{role} = {_value([float(c) for c in pose])}"
            for role, pose in scenario.starts.items()]
    game = []
    if scenario.hide_at is not None:
        game.append(f"hide_at = {_value([float(c) for c in scenario.hide_at])}")
    if scenario.seek_at:
        game.append(f"seek_at = {_value([[float(x), float(y)] for x, y in scenario.seek_at])}")
    if game:
        out += ["", "[game]", *game]
    if scenario.devices:
        out += ["", "[devices]"]
        out += [f"{k} = {_value(v)}" for k, v in sorted(scenario.devices.items())]
    for f in scenario.faults if faults is None else faults:
        out += _fault(f)
    return "\n".join(out) + "\n"
