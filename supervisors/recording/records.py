"""The records a `Recorder` writes, built from what it sees.

The Foxglove messages (``time`` stamps, poses in metres, occupancy grids, log
lines) and the game's own records: the ``hideseek.Checkpoint`` a fork compares
(`checkpoint`) and the ``hideseek.GameState`` a replay of a recording starts
from (`game_state`). Each is a plain dict in the shape of its JSON Schema
(`supervisors.recording.schemas`).
"""

from __future__ import annotations

import base64
import math
from typing import Any

import numpy as np

from server.protocol import Pose
from supervisors.system import SimSystem

from .schemas import FRAME, LOG_LEVELS

__all__ = ["checkpoint", "game_state", "grid_msg", "log_msg", "pose_msg", "stamp"]


def stamp(t: float) -> dict[str, int]:
    """A Foxglove ``time`` record for ``t`` [s] (negative times clamp to 0)."""
    ns = max(0, round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def pose_msg(x_cm: float, y_cm: float, heading_deg: float) -> dict[str, Any]:
    """A ``foxglove.Pose`` in metres from a map-frame pose [cm, deg]."""
    h = math.radians(heading_deg) / 2.0
    return {"position": {"x": x_cm / 100.0, "y": y_cm / 100.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(h), "w": math.cos(h)}}


def grid_msg(t: float, cells: np.ndarray, resolution_cm: float,
             origin_cm: tuple[float, float]) -> dict[str, Any]:
    """A ``foxglove.Grid`` of an int8 occupancy raster (row 0 the lowest y)."""
    ny, nx = cells.shape
    return {"timestamp": stamp(t), "frame_id": FRAME,
            "pose": pose_msg(origin_cm[0], origin_cm[1], 0.0), "column_count": int(nx),
            "cell_size": {"x": resolution_cm / 100.0, "y": resolution_cm / 100.0},
            "row_stride": int(nx), "cell_stride": 1,
            "fields": [{"name": "occupancy", "offset": 0, "type": 2}],
            "data": base64.b64encode(np.ascontiguousarray(cells, np.int8).tobytes()).decode()}


def log_msg(t: float, level: str, name: str, text: str) -> dict[str, Any]:
    """A ``foxglove.Log``."""
    return {"timestamp": stamp(t), "level": LOG_LEVELS[level], "message": text, "name": name,
            "file": "", "line": 0}


def checkpoint(system: SimSystem, now: float) -> dict[str, Any]:
    """A ``hideseek.Checkpoint`` of ``system`` now (what a fork compares)."""
    return {"timestamp": stamp(now), "index": int(math.floor(now)),
            "trace_hash": system.actors.trace.hexdigest(), "messages": system.messages(),
            "phase": str(system.server.game.phase)}


def game_state(system: SimSystem, now: float) -> dict[str, Any]:
    """A ``hideseek.GameState`` of ``system`` now: what a replay of a recording that
    begins now starts from (the game's phase, hide spot, guesses, device faults in force)."""
    game = system.server.game
    injected = {f.get("id"): float(f.get("t", now)) for f in system.faults}
    faults = [{"id": f"w{f.id}", "target": f.target, "kind": f.kind,
               "start_s": injected.get(f"w{f.id}", now), "duration_s": float(f.duration_s)}
              for f in system.world.active_faults()]
    return {"timestamp": stamp(now), "phase": str(game.phase), "reason": game.last_reason,
            "hide_spot": _pose_cm(game.hide_spot), "hider_pose": _pose_cm(game.hider_pose),
            "guesses": [_pose_cm(g) for g in game.guesses], "faults": faults}


def _pose_cm(p: Pose | None) -> dict[str, float] | None:
    return None if p is None else {"x": p.x, "y": p.y, "heading": p.heading_deg}
