"""One frame of the message layer: a JSON object on one line.

Every frame is ``{"cmd": str, "type": str, "data": any JSON, "seq"?: int,
"ack"?: int}`` encoded as UTF-8 JSON and terminated by ``\\n``. ``cmd`` says
what the frame is, ``type`` how to read ``data`` (as in the seed's message
``{"cmd": "store", "type": "sensor_value", "data": 12345.678}``). ``seq`` is
present on frames the sender wants acknowledged (see `session`), ``ack`` is
the receiver's cumulative acknowledgement and may ride on any frame.

This module is pure: no I/O, no clock. A frame that is too long, not UTF-8,
not JSON, or lacks a field raises `FrameError` whose ``fault`` is one of the
`Fault` codes, so a receiver can answer with `error_frame` and keep the link up.
Unknown extra fields are ignored (forward compatibility).
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any

import msgspec

__all__ = [
    "MAX_LINE_BYTES",
    "MAX_SEQ",
    "Fault",
    "Frame",
    "FrameError",
    "encode_frame",
    "decode_line",
    "error_frame",
]

MAX_LINE_BYTES = 1024
"""Longest frame on the wire, newline included [bytes]: fits a WiFly buffer."""

MAX_SEQ = 2**31 - 1
"""Largest ``seq`` / ``ack`` value (int32, so C firmware can hold it)."""

_Name = Annotated[str, msgspec.Meta(min_length=1, max_length=32)]
_Seq = Annotated[int, msgspec.Meta(ge=1, le=MAX_SEQ)]
_Ack = Annotated[int, msgspec.Meta(ge=0, le=MAX_SEQ)]


class Fault:
    """Fault codes carried in ``error`` frames (``data.fault``)."""

    TOO_LONG = "too_long"
    """The line exceeded `MAX_LINE_BYTES`; it was discarded up to the next newline."""
    NOT_UTF8 = "not_utf8"
    """The line is not valid UTF-8."""
    NOT_JSON = "not_json"
    """The line is not a JSON document."""
    BAD_FRAME = "bad_frame"
    """JSON, but not an object with string ``cmd``/``type`` and a ``data`` field."""
    UNKNOWN_CMD = "unknown_cmd"
    """``cmd`` is not in the catalogue."""
    BAD_TYPE = "bad_type"
    """``type`` does not match the one the catalogue gives for ``cmd``."""
    BAD_DATA = "bad_data"
    """``data`` does not fit the schema of ``cmd``."""
    NOT_ALLOWED = "not_allowed"
    """Valid frame, but not acceptable now (before ``hello``, wrong role or direction)."""
    AUTH = "auth"
    """``hello`` with a missing or wrong token."""
    BUSY = "busy"
    """The receiver had no room and dropped the frame; send it again later."""

    ALL = (TOO_LONG, NOT_UTF8, NOT_JSON, BAD_FRAME, UNKNOWN_CMD, BAD_TYPE, BAD_DATA,
           NOT_ALLOWED, AUTH, BUSY)


class Frame(msgspec.Struct, omit_defaults=True, frozen=True):
    """One message-layer frame (see the module docstring)."""

    cmd: _Name
    """What the frame is (a name from `catalogue`)."""
    type: _Name
    """How to read ``data`` (fixed per ``cmd`` by the catalogue)."""
    data: Any
    """The payload: any JSON value, ``null`` when there is none."""
    seq: _Seq | None = None
    """Sender's message number when the frame must be acknowledged, else absent."""
    ack: _Ack | None = None
    """Highest ``seq`` of the peer received in order (cumulative), when known."""


class FrameError(ValueError):
    """Raised by `decode_line` for a bad frame; ``fault`` is a `Fault` code."""

    def __init__(self, fault: str, detail: str) -> None:
        super().__init__(f"{fault}: {detail}")
        self.fault = fault
        self.detail = detail


_encoder = msgspec.json.Encoder()
_decoder = msgspec.json.Decoder(Frame)


def encode_frame(frame: Frame) -> bytes:
    """The frame as one line of UTF-8 JSON, newline included.

    Raises:
        ValueError: when the line would exceed `MAX_LINE_BYTES` (a sender bug:
            large payloads go in chunks, see `mapcodec`).
    """
    line = _encoder.encode(frame) + b"\n"
    if len(line) > MAX_LINE_BYTES:
        raise ValueError(
            f"frame {frame.cmd!r} is {len(line)} bytes, the limit is {MAX_LINE_BYTES}")
    return line


def decode_line(line: bytes) -> Frame:
    """Parse one line (with or without its trailing newline) into a `Frame`.

    Raises:
        FrameError: naming the fault (too long, not UTF-8, not JSON, bad frame).
    """
    if len(line) > MAX_LINE_BYTES:
        raise FrameError(Fault.TOO_LONG, f"{len(line)} bytes, the limit is {MAX_LINE_BYTES}")
    try:
        line.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FrameError(Fault.NOT_UTF8, f"invalid UTF-8 at byte {exc.start}") from None
    try:
        return _decoder.decode(line)
    except msgspec.ValidationError as exc:
        raise _diagnose(line) or FrameError(Fault.BAD_FRAME, str(exc)) from None
    except msgspec.DecodeError as exc:
        raise _diagnose(line) or FrameError(Fault.NOT_JSON, str(exc)) from None


def _diagnose(line: bytes) -> FrameError | None:
    """Name the field of a line JSON rejects for a number or a string it cannot hold.

    NaN, Infinity and numbers beyond a double (``1e400``) are not JSON numbers,
    and a lone UTF-16 surrogate escape (``"\\ud800"``) is not a character;
    msgspec reports them without naming the field. Python's parser accepts
    all of them, so it finds the field (only on the error path).
    """
    found: list[str] = []

    def walk(value: Any, path: str) -> None:
        if found:
            return
        if isinstance(value, float) and not math.isfinite(value):
            found.append(f"{path}: {value} is not a finite JSON number (NaN, Infinity and "
                         "numbers beyond ±1.8e308 are refused)")
        elif isinstance(value, str) and any(0xD800 <= ord(c) <= 0xDFFF for c in value):
            found.append(f"{path}: a lone UTF-16 surrogate escape (\\ud800-\\udfff without "
                         "its pair) is not a character; send UTF-8 text")
        elif isinstance(value, dict):
            for k, v in value.items():
                walk(v, f"{path}.{k}")
        elif isinstance(value, list):
            for i, v in enumerate(value):
                walk(v, f"{path}[{i}]")

    try:
        walk(json.loads(line), "$")
    except (ValueError, RecursionError):
        return None
    return FrameError(Fault.BAD_DATA, found[0]) if found else None


def error_frame(fault: str, detail: str, *, cmd: str | None = None,
                seq: int | None = None) -> Frame:
    """An ``error`` frame naming a fault; ``cmd``/``seq`` identify the offending frame."""
    data: dict[str, Any] = {"fault": fault, "detail": detail[:200]}
    if cmd is not None:
        data["cmd"] = cmd[:32]
    if seq is not None:
        data["seq"] = seq
    return Frame("error", "fault", data)
