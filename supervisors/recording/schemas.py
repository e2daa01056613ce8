"""The channels of a hideseek recording and their JSON Schemas.

Every channel uses JSON message encoding with a JSON Schema (``jsonschema``
schema encoding). Where Foxglove defines a schema for the data, the channel
uses it under Foxglove's exact name, so Foxglove and Lichtblick draw it
(``foxglove.Grid`` as a map, ``foxglove.PoseInFrame`` as an arrow,
``foxglove.LaserScan`` as points, ``foxglove.Log`` in the log panel); the
schema texts follow the published ones (github.com/foxglove/schemas,
``schemas/jsonschema``), reduced to the fields used here. The rest have
``hideseek.*`` schemas defined below.

Frames and units: Foxglove schemas are in metres and radians, in the frame
``map`` (the mapping rover's start pose, x forward, y to its left; the
console's map frame scaled from [cm] to [m]). ``hideseek.*`` schemas keep the
project's units, named in each field.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

__all__ = ["ChannelSpec", "CHANNELS", "SCHEMAS", "FRAME", "LOG_LEVELS", "channel",
           "role_channels", "schema_bytes"]

FRAME = "map"
"""The frame every Foxglove message is in."""

#: foxglove.Log levels used here
LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4}

_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_XYZ = {"type": "object", "title": "foxglove.Vector3",
        "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "title": "foxglove.Quaternion",
         "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "title": "foxglove.Pose",
         "properties": {"position": _XYZ, "orientation": _QUAT}}
_POSE_CM = {"type": "object", "title": "pose",
            "properties": {"x": {"type": "number", "description": "[cm]"},
                           "y": {"type": "number", "description": "[cm]"},
                           "heading": {"type": "number", "description": "[deg]"}}}
_NUMERIC_TYPES = ("UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32", "INT32", "FLOAT32",
                  "FLOAT64")


_MESSAGE = {
    "queue": {"type": "string", "description": "mailbox, e.g. mapper/motor"},
    "command": {"type": "string", "description": "command name, e.g. MOTOR_MOVE"},
    "type": {"type": "string",
             "description": "value type: INT32, UINT32, FLOAT32, INT16X2, HANDLE"},
    "value": {"type": "number", "description": "the 32-bit value"},
    "depth": {"type": "integer", "description": "queue depth after it [messages]"},
}


def _obj(title: str, description: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "description": description, "type": "object",
            "properties": properties}


SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.Grid": _obj("foxglove.Grid", "A 2D grid of data", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE,
        "column_count": {"type": "integer", "minimum": 0},
        "cell_size": {"type": "object", "title": "foxglove.Vector2",
                      "properties": {"x": {"type": "number"}, "y": {"type": "number"}}},
        "row_stride": {"type": "integer", "minimum": 0},
        "cell_stride": {"type": "integer", "minimum": 0},
        "fields": {"type": "array", "items": {
            "type": "object", "title": "foxglove.PackedElementField",
            "properties": {"name": {"type": "string"},
                           "offset": {"type": "integer", "minimum": 0},
                           "type": {"title": "foxglove.NumericType",
                                    "oneOf": [{"title": t, "const": i}
                                              for i, t in enumerate(_NUMERIC_TYPES)]}}}},
        "data": {"type": "string", "contentEncoding": "base64"},
    }),
    "foxglove.PoseInFrame": _obj("foxglove.PoseInFrame", "A timestamped pose in a named frame", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE}),
    "foxglove.PosesInFrame": _obj(
        "foxglove.PosesInFrame", "An array of timestamped poses in a named frame",
        {"timestamp": _TIME, "frame_id": {"type": "string"},
         "poses": {"type": "array", "items": _POSE}}),
    "foxglove.LaserScan": _obj(
        "foxglove.LaserScan", "A single scan from a planar laser range-finder",
        {"timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE,
         "start_angle": {"type": "number"}, "end_angle": {"type": "number"},
         "ranges": {"type": "array", "items": {"type": "number"}},
         "intensities": {"type": "array", "items": {"type": "number"}}}),
    "foxglove.Log": _obj("foxglove.Log", "A log message", {
        "timestamp": _TIME,
        "level": {"oneOf": [{"title": t, "const": i} for i, t in enumerate(
            ("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL"))]},
        "message": {"type": "string"}, "name": {"type": "string"},
        "file": {"type": "string"}, "line": {"type": "integer", "minimum": 0}}),
    "hideseek.Message": _obj(
        "hideseek.Message", "One internal 96-bit message dropped at a full mailbox",
        {"timestamp": _TIME, **_MESSAGE}),
    "hideseek.MessageBatch": _obj(
        "hideseek.MessageBatch",
        "The internal 96-bit messages sent to mailboxes since the last batch (about 0.2 s), "
        "decoded, oldest first",
        {"timestamp": _TIME,
         "messages": {"type": "array", "items": {
             "type": "object", "properties": {
                 "t": {"type": "number", "description": "simulated time [s]"}, **_MESSAGE}}}}),
    "hideseek.LinkFrame": _obj(
        "hideseek.LinkFrame", "One JSON line on a rover's WiFly link, as the server's end saw it",
        {"timestamp": _TIME, "rover": {"type": "string"},
         "direction": {"enum": ["up", "down"],
                       "description": "up: rover to server (received); down: server to rover "
                                      "(sent)"},
         "text": {"type": "string", "description": "the line, without its newline"}}),
    "hideseek.GameState": _obj(
        "hideseek.GameState",
        "The game as it stood when the recording began (a recording started mid-game "
        "replays from it); map frame [cm, deg], times simulated [s]",
        {"timestamp": _TIME, "phase": {"type": "string"},
         "reason": {"type": "string", "description": "why the game is in its phase"},
         "hide_spot": {"oneOf": [{"type": "null"}, _POSE_CM],
                       "description": "where the hider was sent"},
         "hider_pose": {"oneOf": [{"type": "null"}, _POSE_CM],
                        "description": "where the hider reported arriving"},
         "guesses": {"type": "array", "items": _POSE_CM,
                     "description": "the seeker's destinations so far, in order"},
         "faults": {"type": "array", "description": "device faults in force", "items": {
             "type": "object", "properties": {
                 "id": {"type": "string"}, "target": {"type": "string"},
                 "kind": {"type": "string"},
                 "start_s": {"type": "number", "description": "when it was injected [s]"},
                 "duration_s": {"type": "number", "description": "0: until cleared [s]"}}}}}),
    "hideseek.Checkpoint": _obj(
        "hideseek.Checkpoint",
        "The run's fingerprint so far, every second of simulated time (a fork checks it)",
        {"timestamp": _TIME, "index": {"type": "integer", "description": "whole seconds"},
         "trace_hash": {"type": "string", "description": "the runtime trace hash so far"},
         "messages": {"type": "integer", "description": "messages delivered so far"},
         "phase": {"type": "string"}}),
}


@dataclass(frozen=True, slots=True)
class ChannelSpec:
    """One channel: its topic, schema name and what it carries."""

    topic: str
    schema: str
    description: str


def channel(topic: str, schema: str, description: str) -> ChannelSpec:
    """A `ChannelSpec` (checks that the schema is one of `SCHEMAS`)."""
    if schema not in SCHEMAS:
        raise ValueError(f"schema must be one of {', '.join(SCHEMAS)}, got {schema!r}")
    return ChannelSpec(topic, schema, description)


def role_channels(role: str) -> tuple[ChannelSpec, ...]:
    """The channels of one rover."""
    return (
        channel(f"/{role}/pose/true", "foxglove.PoseInFrame",
                "ground-truth pose (simulated rooms), 5 Hz"),
        channel(f"/{role}/pose/believed", "foxglove.PoseInFrame",
                "the pose the rover believes (its navigation's dead reckoning), 5 Hz, "
                "once it knows its place in the map frame"),
        channel(f"/{role}/path", "foxglove.PosesInFrame",
                "the planned path from the rover to its goal, when it changes "
                "(no poses: no path)"),
        channel(f"/{role}/link", "hideseek.LinkFrame", "every JSON line on the rover's link"),
    )


ROLES = ("mapper", "hider", "seeker")

#: every channel of a recording, in registration order
CHANNELS: tuple[ChannelSpec, ...] = (
    channel("/map/working", "foxglove.Grid",
            "the mapper's occupancy grid as it grows (cropped to the known cells), "
            "when it changed, at most 1 Hz; int8 cells: -1 unknown, 0 free, 100 occupied"),
    channel("/map/uploaded", "foxglove.Grid", "the map the mapper uploaded to the server"),
    channel("/mapper/scan", "foxglove.LaserScan",
            "one LIDAR revolution as the sensor measured it, at the mapper's true pose"),
    *(c for role in ROLES for c in role_channels(role)),
    channel("/actors/messages", "hideseek.MessageBatch",
            "every internal message sent to a mailbox, in batches of about 0.2 s"),
    channel("/actors/drops", "hideseek.Message", "every message dropped at a full mailbox"),
    channel("/actors/events", "foxglove.Log",
            "the actor runtime's lifecycle: start, stop, crash, hung, restart, escalate, "
            "fault (name: the event kind)"),
    channel("/faults", "foxglove.Log", "every fault injected (name: its id)"),
    channel("/game/events", "foxglove.Log",
            "the server's game events: phase, command, refused, report, map, link "
            "(name: the event kind)"),
    channel("/checkpoints", "hideseek.Checkpoint", "the run's fingerprint, 1 Hz"),
    channel("/game/state", "hideseek.GameState",
            "the game when the recording began: phase, hide spot, guesses, faults in force "
            "(one message, at the start)"),
)


def schema_bytes(name: str) -> bytes:
    """The JSON Schema text of a schema name, as stored in the file."""
    return json.dumps(SCHEMAS[name], separators=(",", ":")).encode()
