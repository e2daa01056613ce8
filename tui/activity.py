"""The console's record of activity: the message log and the timeline of events.

`ActivityLog` collects what the running system does, cheaply, while Trio runs:
every message sent (a trace tap), every drop, crash, restart, fault and kill (a
trace subscription), and the server's phase, link and report events. Messages
are kept raw and decoded into log lines only when a snapshot shows them: most
scroll out between two frames, and decoding each would cost the simulation time.
"""

from __future__ import annotations

import ast
import re
from collections import deque
from collections.abc import Callable
from itertools import islice
from typing import Any

import trio

from actors import EventKind, Message, TraceEvent, ValueType
from actors.firmware.commands import name_of
from actors.firmware.payloads import message_text

from .snapshot import MAX_LOG_LINES, MAX_TIMELINE, LogLine, TimelineEvent

__all__ = ["ActivityLog", "describe"]

_MESSAGE_RE = re.compile(r"command=[^,]*?(\d+)>?, type=[^,]*?(\d+)>?, value=([^)]+)\)")
_LIFECYCLE = {EventKind.CRASH, EventKind.RESTART, EventKind.HUNG, EventKind.ESCALATE,
              EventKind.FAULT, EventKind.KILLED, EventKind.POISON}


def _decode(message: str) -> str:
    """``Message(command=<Cmd.MOTOR_MOVE: 256>, type=2, value=12.5)`` (a dropped message's
    repr in its trace event) -> ``MOTOR_MOVE distance=12.5 cm``."""
    m = _MESSAGE_RE.search(message)
    if m is None:
        return message[:80]
    try:
        value = float(m.group(3)) if int(m.group(2)) == ValueType.FLOAT32 else int(m.group(3))
        return message_text(Message(int(m.group(1)), int(m.group(2)), value))
    except (ValueError, TypeError):
        return f"{name_of(int(m.group(1)))} {m.group(3)}"


def describe(message: Any) -> str:
    """A log line's text for a message object: ``MOTOR_MOVE distance=12.5 cm`` for the
    firmware's `Message` (`actors.firmware.payloads`), else its repr (at most 80
    characters)."""
    if type(message) is Message:
        return message_text(message)
    return repr(message)[:80]


def fault_text(target: str, detail: str) -> str:
    """A device fault's trace event for people (``fault_injected [('duration_s', 60.0), ('id',
    1), ('kind', 'slipping'), ...]`` -> ``slipping on hider/encoder for 60 s (w1)``); ``""``
    for any other detail (actor faults read well as they are)."""
    what, _, rest = detail.partition(" ")
    if what not in ("fault_injected", "fault_cleared"):
        return ""
    try:
        fields = dict(ast.literal_eval(rest))
    except (ValueError, SyntaxError, TypeError):
        return ""
    fid = f"w{fields.get('id', '?')}"
    kind = fields.get("kind", "?")
    if what == "fault_cleared":
        return f"{kind} on {target} cleared ({fields.get('reason', 'cleared')}, {fid})"
    duration = float(fields.get("duration_s") or 0.0)
    params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in sorted(dict(fields.get("params") or {}).items()))
    return (f"{kind} on {target}" + (f" {params}" if params else "")
            + (f" for {duration:g} s" if duration else " until cleared")
            + (", scheduled" if fields.get("scheduled") else "") + f" ({fid})")


class ActivityLog:
    """The message log (at most `MAX_LOG_LINES`) and the timeline (at most `MAX_TIMELINE`).

    Args:
        now: the system's clock [s], for the timeline's times.
    """

    def __init__(self, now: Callable[[], float]) -> None:
        self._now = now
        self._log: deque[LogLine] = deque(maxlen=MAX_LOG_LINES)
        # messages as tapped (time, queue, message object, dropped), decoded into `_log`
        # only when a snapshot shows them
        self._raw_log: deque[tuple[float, str, Any, bool]] = deque(maxlen=MAX_LOG_LINES)
        self._decoded_seq = 0
        self._timeline: deque[TimelineEvent] = deque(maxlen=MAX_TIMELINE)
        self._log_seq = 0
        self._event_seq = 0
        self.exits: dict[str, float] = {}
        """Actor -> time [s] of its last exit (crash, hang, kill)."""

    def timeline(self) -> tuple[TimelineEvent, ...]:
        """The timeline's events, oldest first."""
        return tuple(self._timeline)

    def event(self, kind: str, text: str) -> None:
        """Add one event to the timeline, at the system's time now."""
        self._event_seq += 1
        self._timeline.append(TimelineEvent(self._event_seq, self._now(), kind, text))

    def on_message(self, time: float, kind: EventKind, queue: str, message: Any,
                   depth: int) -> None:
        """A message tap (`actors.Trace.tap_messages`): runs for every message sent."""
        self._log_seq += 1
        self._raw_log.append((time, queue, message, False))

    def on_trace(self, event: TraceEvent) -> None:
        """A trace subscriber: drops go to the log, lifecycle events to the timeline."""
        if event.kind is EventKind.DROP:
            self._log_seq += 1
            self._raw_log.append((event.time, event.queue, event.message, True))
            return
        if event.kind in _LIFECYCLE:
            if event.kind in (EventKind.CRASH, EventKind.HUNG, EventKind.KILLED):
                self.exits[event.actor] = event.time
            kind = {EventKind.RESTART: "restart", EventKind.FAULT: "fault"}.get(event.kind, "crash")
            text = fault_text(event.actor, event.detail) if kind == "fault" else ""
            self.event(kind, text or f"{event.kind.value} {event.actor} {event.detail}".strip())

    def log_lines(self) -> tuple[LogLine, ...]:
        """The message log, decoding what was traced since the last snapshot."""
        raw = self._raw_log
        first = self._log_seq - len(raw) + 1  # seq of the oldest raw entry
        start = max(self._decoded_seq + 1, first)
        append = self._log.append
        # indexing a deque walks it: take the new entries from its end in one go
        for i, (time, queue, message, dropped) in enumerate(
                islice(raw, start - first, None), start):
            if dropped:  # a drop is a trace event: its message is a repr already
                text = "DROP overflow " + _decode(message)
            elif type(message) is Message:
                text = message_text(message)
            else:
                text = repr(message)[:80]
            append(LogLine(i, time, queue, queue, text))
        self._decoded_seq = self._log_seq
        return tuple(self._log)

    def drain_server_events(self, events: trio.MemoryReceiveChannel | None) -> None:
        """The server's events since the last snapshot, into the timeline (on the console's
        side: the channel only buffers, so no task wakes for it)."""
        while events is not None:
            try:
                e = events.receive_nowait()
            except (trio.WouldBlock, trio.EndOfChannel, trio.ClosedResourceError):
                return
            if e.kind == "phase":
                self.event("phase", f"phase {e.data.get('phase')}"
                            + (f": {e.data['reason']}" if e.data.get("reason") else ""))
            elif e.kind in ("link_up", "link_down"):
                self.event("link", f"{e.rover} {e.kind.replace('_', ' ')}")
            elif e.kind in ("link_open", "link_error"):  # a serial port opened, unplugged
                self.event("link", str(e.data.get("error") or e.data.get("detail") or e.kind))
            elif e.kind in ("report", "refused", "map"):
                body = " ".join(f"{k}={v}" for k, v in e.data.items())
                self.event("game", f"{e.kind} {e.rover} {body}".strip())
            elif e.kind == "rover_event":  # an attached rover's own runtime, by telemetry
                kind = {"restart": "restart", "crash": "crash", "give_up": "crash"}.get(
                    e.data.get("kind", ""), "fault")
                self.event(kind, f"{e.data.get('kind')} {e.data.get('path')} "
                                 f"{e.data.get('detail', '')}".strip())
            elif e.kind in ("fault_sent", "fault_reply", "link_fault", "link_fault_cleared"):
                body = " ".join(f"{k}={v}" for k, v in e.data.items())
                self.event("fault", f"{e.kind.replace('_', ' ')} {e.rover} {body}".strip())
