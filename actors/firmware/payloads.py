"""What each internal message's ``value`` means: field names and units, for people.

The 96-bit message (`actors.Message`, DESIGN.md section 3) carries one 32-bit
``value`` read as its ``type`` says; what it stands for is the command's
(`actors.firmware.commands.Cmd`). `PAYLOADS` writes that down as data, one row per
command, so a log line reads ``NAV_POSE_XY x=120 mm y=-40 mm`` instead of
``NAV_POSE_XY 4294377592``. Pairs are split by `Message.as_pair` (the message's own
decoding); a handle is shown as the buffer-pool slot it names (the data behind it
is the receiver's, and gone once taken). Used by the console's message log
(`tui.activity`) and the replay's (`tui.replay.index`); nothing in the firmware
reads it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from actors.message import Message, ValueType

from .commands import Cmd, name_of
from .hardware import decode_counter

__all__ = ["Field", "PAYLOADS", "payload_text", "message_text", "named_text"]


@dataclass(frozen=True, slots=True)
class Field:
    """One field of a value: its name, unit and the scale from the wire to that unit."""

    name: str
    unit: str = ""
    scale: float = 1.0


def _fields(*fields: Field) -> tuple[Field, ...]:
    return fields


_MM = ("mm", 1.0)
_XY_MM = _fields(Field("x", *_MM), Field("y", *_MM))
_LR_MM = _fields(Field("left", *_MM), Field("right", *_MM))
_HEADING = _fields(Field("heading", "deg"))


def _counter(value: int) -> str:
    tread, forward = decode_counter(value)
    return f"tread={'right' if tread else 'left'} {'forward' if forward else 'backward'}"


def _tread_fault(value: int) -> str:
    if value & 4:
        return "both treads " + ("count short" if value & 2 else "silent (turn blocked)")
    return (f"tread={'right' if value & 1 else 'left'} "
            + ("counts short" if value & 2 else "silent"))


def _choice(names: dict[int, str]) -> Callable[[int], str]:
    return lambda value: names.get(value, f"value={value}")


#: Command -> its value's fields (a pair has two; none: the value is unused), or a
#: function of the value for codes packed in bits.
PAYLOADS: dict[int, tuple[Field, ...] | Callable[[int], str]] = {
    Cmd.NOOP: (),
    Cmd.MOTOR_MOVE: _fields(Field("distance", "cm")),
    Cmd.MOTOR_TURN: _fields(Field("angle", "deg")),
    Cmd.MOTOR_STOP: (),
    Cmd.MOTOR_TICK: _counter,
    Cmd.MOTOR_CONTROL: (),
    Cmd.MOTOR_GET_POSE: (),
    Cmd.NAV_POSE_XY: _XY_MM,
    Cmd.NAV_POSE_HEADING: _HEADING,
    Cmd.NAV_MOTION_DONE: _fields(Field("done", "cm or deg")),
    Cmd.NAV_MOTION_BLOCKED: _fields(Field("done", "cm or deg")),
    Cmd.NAV_MAP_UPDATE: _fields(Field("map")),
    Cmd.NAV_SCAN_COUNT: _fields(Field("scans")),
    Cmd.NAV_NET: _fields(Field("frame")),
    Cmd.NAV_MAP_DOWNLOAD: _fields(Field("map")),
    Cmd.NAV_IR: _choice({0: "hider=out of range", 1: "hider=in range",
                         2: "no decision (sensor at a rail)"}),
    Cmd.NAV_TIMER: (),
    Cmd.NAV_LINK: _choice({0: "link=down", 1: "link=up"}),
    Cmd.NAV_MAP_LOST: (),
    Cmd.NAV_LIDAR_HEALTH: _fields(Field("health")),
    Cmd.NAV_TREAD_FAULT: _tread_fault,
    Cmd.NAV_MAP_ORIGIN_XY: _XY_MM,
    Cmd.NAV_MAP_ORIGIN_HEADING: _HEADING,
    Cmd.NAV_TREAD_DRIVEN: _LR_MM,
    Cmd.LIDAR_SAMPLE: _fields(Field("angle", "deg", 0.1), Field("distance", "cm")),
    Cmd.LIDAR_START: _fields(Field("duty")),
    Cmd.LIDAR_STOP: (),
    Cmd.LIDAR_RATE: _fields(Field("duty")),
    Cmd.LIDAR_POSE_XY: _fields(Field("x", "cm"), Field("y", "cm")),
    Cmd.LIDAR_POSE_HEADING: _HEADING,
    Cmd.LIDAR_SAMPLES: _fields(Field("samples")),
    Cmd.MAP_SCAN: _fields(Field("scan")),
    Cmd.MAP_GET: (),
    Cmd.MAP_RESTORE: _fields(Field("map")),
    Cmd.MAP_ORIGIN_XY: _XY_MM,
    Cmd.MAP_ORIGIN_HEADING: _HEADING,
    Cmd.MAP_TREAD_FAULT: _LR_MM,
    Cmd.WIFLY_RX: _fields(Field("bytes")),
    Cmd.WIFLY_SEND: _fields(Field("frame")),
    Cmd.WIFLY_SEND_UNRELIABLE: _fields(Field("frame")),
    Cmd.WIFLY_TIMER: (),
    Cmd.WIFLY_SEND_MAP: _fields(Field("map")),
    Cmd.WIFLY_LINK_OPEN: (),
    Cmd.IR_SAMPLE: _fields(Field("adc", "of 4095")),
    Cmd.IR_LEASE: _fields(Field("for", "s")),
}


def _number(v: float) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _field(f: Field, v: float) -> str:
    shown = v * f.scale if f.scale != 1.0 else v
    return f"{f.name}={_number(shown)}" + (f" {f.unit}" if f.unit else "")


def payload_text(command: int, vtype: int, value: int | float) -> str:
    """The value of a message with this ``command`` and ``type`` as ``name=value unit``
    fields (``x=120 mm y=-40 mm``); ``""`` for a value the command leaves unused; an
    unknown command's value as ``value=...`` (pairs as ``a=.. b=..``)."""
    layout = PAYLOADS.get(command)
    if callable(layout):
        return layout(int(value))
    if vtype == ValueType.HANDLE:
        name = layout[0].name if layout else "handle"
        return f"{name}=buffer {int(value) & 0xFFFF}"
    if vtype == ValueType.INT16X2:
        a, b = Message(command, vtype, int(value)).as_pair()
        first, second = layout if layout and len(layout) == 2 else (Field("a"), Field("b"))
        return f"{_field(first, a)} {_field(second, b)}"
    if layout == ():
        return "" if value == 0 else f"value={_number(value)}"
    return _field(layout[0] if layout else Field("value"), value)


def message_text(message: Message) -> str:
    """A log line's text for a message: its command's name and its fields."""
    fields = payload_text(message.command, message.type, message.value)
    return f"{name_of(message.command)} {fields}" if fields else name_of(message.command)


def named_text(command: str, type_name: str, value: int | float) -> str:
    """`message_text` from a message's names, as a recording keeps them (``command``
    ``NAV_POSE_XY``, ``type`` ``INT16X2``); names it does not know are shown as given."""
    try:
        code, vtype = Cmd[command], ValueType[type_name]
    except KeyError:
        return f"{command} {value!r}"
    fields = payload_text(code, vtype, value)
    return f"{command} {fields}" if fields else command
