"""Telemetry bounds: ``telemetry.asked``, ``telemetry.frames``, ``telemetry.rate``.

The frames' shapes are those agreed for the telemetry section of
docs/protocol.md (stream -> cmd, type and data below); unknown extra fields
are allowed, as everywhere in the protocol.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from ..protocol import MAX_LINE_BYTES
from .context import Checker
from .peer import Seen

__all__ = ["STREAM_FRAMES", "judge_telemetry"]

_N = Annotated[int, msgspec.Meta(ge=0)]
_F = Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]
_Text = Annotated[str, msgspec.Meta(max_length=200)]


class _Mailboxes(msgspec.Struct):
    t: float
    boxes: list[tuple[_Text, _N, _N, Annotated[float, msgspec.Meta(ge=0)], _N]]


class _Tree(msgspec.Struct):
    t: float
    nodes: list[tuple[_Text, Literal["supervisor", "worker"],
                      Literal["running", "restarting", "stopped"], _N,
                      Annotated[str, msgspec.Meta(max_length=80)] | None]]


class _MapDelta(msgspec.Struct):
    t: float
    nx: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    ny: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    resolution_cm: Annotated[float, msgspec.Meta(gt=0)]
    origin_cm: tuple[_F, _F]
    cells: list[tuple[_N, Literal[0, 1, 2]]]


class _PoseSpread(msgspec.Struct):
    t: float
    x: _F
    y: _F
    heading: _F
    sx: Annotated[float, msgspec.Meta(ge=0)]
    sy: Annotated[float, msgspec.Meta(ge=0)]
    sheading: Annotated[float, msgspec.Meta(ge=0)]


class _Event(msgspec.Struct):
    t: float
    kind: Literal["crash", "restart", "give_up", "fault_injected", "fault_cleared",
                  "fault_refused"]
    path: _Text
    detail: _Text


STREAM_FRAMES: dict[str, tuple[str, str, type]] = {
    "mailboxes": ("tm_mailboxes", "mailboxes", _Mailboxes),
    "tree": ("tm_tree", "tree", _Tree),
    "map": ("tm_map", "map_delta", _MapDelta),
    "pose": ("tm_pose", "pose_spread", _PoseSpread),
    "events": ("tm_event", "event", _Event),
}
"""stream -> (cmd, type, data schema) of its frames."""
_STREAM_OF = {cmd: stream for stream, (cmd, _, _) in STREAM_FRAMES.items()}
_RATE_SLACK = 1.25  # frames may come a quarter more often than asked (clock and ticks)


def _bad_shape(s: Seen, stream: str) -> str:
    cmd, type_, schema = STREAM_FRAMES[stream]
    f = s.frame
    if f.seq is not None:
        return f"{cmd} carries seq {f.seq} (telemetry is never reliable)"
    if s.size > MAX_LINE_BYTES:
        return f"{cmd} is {s.size} bytes, the limit is {MAX_LINE_BYTES}"
    if f.type != type_:
        return f"{cmd} has type {f.type!r}, not {type_!r}"
    try:
        body = msgspec.convert(f.data, schema)
    except msgspec.ValidationError as exc:
        return f"{cmd}: {exc}"
    if stream == "map":
        n = body.nx * body.ny
        if any(i >= n for i, _ in body.cells):
            return f"{cmd}: a cell index beyond {body.nx}x{body.ny}"
    return ""


def judge_telemetry(c: Checker) -> None:
    """The three telemetry rules over the transcript."""
    tx = c.tx
    tm = [s for s in tx.rover() if (s.frame is not None and s.frame.cmd in _STREAM_OF)
          or (s.frame is None and s.fault == "too_long")]
    if c.streams is None and not tm:
        for rule in ("telemetry.asked", "telemetry.frames", "telemetry.rate"):
            c.found.skip(rule, "hello lists no telemetry streams")
        return
    # too long lines can only be judged as telemetry when the rover sends telemetry
    oversize = [s for s in tm if s.frame is None]
    frames = [s for s in tm if s.frame is not None]
    first_welcome = c.welcomes[0][1] if c.welcomes else float("inf")
    early = [s for s in frames if s.t < first_welcome]
    listed = set(c.streams or ())
    unasked = [s for s in frames if _STREAM_OF[s.frame.cmd] not in c.asked]
    unlisted = [s for s in frames if _STREAM_OF[s.frame.cmd] not in listed]
    if early:
        c.found.fail("telemetry.asked", "telemetry before the welcome", early)
    elif unlisted:
        c.found.fail("telemetry.asked", f"stream {_STREAM_OF[unlisted[0].frame.cmd]!r} "
                     "was not listed in hello", unlisted)
    elif unasked:
        c.found.fail("telemetry.asked", f"stream {_STREAM_OF[unasked[0].frame.cmd]!r} "
                     f"was not asked for (asked: {', '.join(c.asked) or 'none'})", unasked)
    else:
        c.found.ok("telemetry.asked", f"asked {', '.join(c.asked) or 'none'}: "
                   f"{len(frames)} frames, none other")
    bad = [(s, why) for s in frames if (why := _bad_shape(s, _STREAM_OF[s.frame.cmd]))]
    if oversize:
        c.found.fail("telemetry.frames", f"{len(oversize)} line(s) over {MAX_LINE_BYTES} "
                     "bytes", oversize)
    elif bad:
        c.found.fail("telemetry.frames", bad[0][1], [b[0] for b in bad])
    elif not frames:
        c.found.skip("telemetry.frames", "no telemetry came")
    else:
        c.found.ok("telemetry.frames", f"{len(frames)} frames well-formed, the largest "
                   f"{max(s.size for s in frames)} bytes", frames[:1])
    _judge_rate(c, frames)


def _judge_rate(c: Checker, frames: list[Seen]) -> None:
    if not frames or not c.welcomes:
        c.found.skip("telemetry.rate", "no telemetry came")
        return
    t0 = c.welcomes[0][1]
    span = max(c.tx.now() - t0, 1e-3)
    for stream, interval in c.asked.items():
        if interval <= 0:
            continue
        cmd = STREAM_FRAMES[stream][0]
        stamps = {s.frame.data.get("t") for s in frames if s.frame.cmd == cmd
                  and isinstance(s.frame.data, dict)}
        most = span / interval * _RATE_SLACK + 2
        if len(stamps) > most:
            c.found.fail("telemetry.rate", f"{stream}: {len(stamps)} updates in {span:.1f} s, "
                         f"asked every {interval:g} s (at most {most:.0f})")
            return
    baud = c.link.spec.baud or c.opts.line_baud
    budget = c.opts.tm_share * baud / 10 * span * _RATE_SLACK + MAX_LINE_BYTES
    used = sum(s.size for s in frames)
    if used > budget:
        c.found.fail("telemetry.rate", f"{used} bytes of telemetry in {span:.1f} s: over "
                     f"{c.opts.tm_share:g} of a {baud}-baud line ({budget:.0f} bytes)")
    else:
        c.found.ok("telemetry.rate", f"{used} bytes in {span:.1f} s ({used / span:.0f} B/s, "
                   f"{used / span / (baud / 10):.1%} of a {baud}-baud line)")
