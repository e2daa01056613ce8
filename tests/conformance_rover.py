"""A configurable rover for `hideseek check-rover`'s tests, built on `server.protocol`.

`TestRover` speaks docs/protocol.md (and its telemetry and fault sections) the
way firmware should; ``breaks`` names one rule it breaks instead (`BREAKS`).
`PairLink` joins it to the checker over in-memory streams, as a rover that
waits for the server to connect (``tcpin:``): each (re)connection of the
checker is a new stream the rover serves. Both run in one Trio run, in
virtual time.
"""

from __future__ import annotations

import math
from typing import Any

import msgspec
import trio
import trio.testing

from server.conformance.role_rules import checker_map
from server.links import parse_link
from server.protocol import (
    TOO_LONG,
    Frame,
    FrameError,
    GridMap,
    LineBuffer,
    MapAssembler,
    ReliableSession,
    decode_line,
    encode_frame,
    make_frame,
    map_chunks,
    read_data,
)

BREAKS = {
    "": "nothing: follows every rule",
    "chatter": "sends a heartbeat before the welcome",
    "late_acks": "acknowledges 1 s late: no bare ack, the ack field a second behind",
    "resend_changes": "resends a frame with its seq but other data",
    "no_backoff": "resends every 1 s without doubling",
    "no_dedup": "acts on a duplicate frame again",
    "no_heartbeat": "sends a heartbeat only after 3 s idle (test it without telemetry)",
    "crash_on_malformed": "closes the link for good on a line that is not JSON",
    "big_chunks": "uploads its map in base64 pieces of 700 characters",
    "oversized_telemetry": "sends tm_map frames over 1024 bytes",
    "unasked_stream": "sends every stream it lists, asked for or not",
    "fault_without_opt_in": "lists no faults yet accepts lidar/dead",
    "new_session": "says a session in hello, a new one in every hello",
}
"""``breaks`` -> what the rover does wrong."""

_FAULTS = ("lidar/dead", "nav/crash")
_KNOWN_TARGETS = {f.split("/")[0] for f in _FAULTS}
STREAMS = ("mailboxes", "tree", "map", "pose", "events")


class PairLink:
    """The checker's link to a `TestRover` (duck-types `server.conformance.RoverLink`)."""

    def __init__(self) -> None:
        self.spec = parse_link("tcp:127.0.0.1:7")
        self.kind = "tcp_out"
        self.can_drop = True
        self.speaks_first = False
        self.send, self.streams = trio.open_memory_channel[Any](4)

    async def open(self, nursery: trio.Nursery, wait_s: float) -> Any:
        return self._new()

    async def reopen(self, wait_s: float) -> Any:
        return self._new()

    def _new(self) -> Any:
        checker_end, rover_end = trio.testing.memory_stream_pair()
        self.send.send_nowait(rover_end)
        return checker_end

    async def aclose(self) -> None:
        self.send.close()


class TestRover:
    """One rover of ``role`` (see the module docstring).

    Args:
        role: ``mapper``, ``hider`` or ``seeker``.
        breaks: a key of `BREAKS`.
        streams: telemetry streams listed in hello (None: the field is left out).
        accept_faults: the fault opt-in: lists `_FAULTS` and accepts them; without it
            the list is empty and every fault is refused (``faults=None`` leaves the
            field out).
    """

    __test__ = False  # not a pytest class

    def __init__(self, role: str, *, breaks: str = "", streams: tuple[str, ...] | None = STREAMS,
                 accept_faults: bool = True, faults: bool = True) -> None:
        if breaks not in BREAKS:
            raise ValueError(f"breaks must be one of {sorted(BREAKS)}, got {breaks!r}")
        self.role, self.breaks = role, breaks
        self.streams = streams
        self.accept_faults = accept_faults
        self.faults_field = faults
        rto = {"rto_max_s": 1.0} if breaks == "no_backoff" else {}
        hb = 3.0 if breaks == "no_heartbeat" else 1.0
        self.session = ReliableSession(now=trio.current_time(), heartbeat_s=hb, **rto)
        self.welcomed = False
        self.asked: dict[str, float] = {}
        self.next_tm: dict[str, float] = {}
        self.assembler = MapAssembler()
        self.map: GridMap | None = None
        self.destination: Any = None
        self.map_id = 0
        self.sent_seqs: set[int] = set()
        self._acks: list[tuple[float, int]] = []  # late_acks: (time, ack value) of a second
        self.dead = False
        self._stream: Any = None
        self._next_hello = 0.0
        self._hello_wait = 1.0
        self._kick = trio.Event()
        self.hellos_said = 0  # new_session: the session of the last hello

    # -- the link -------------------------------------------------------------------

    async def run(self, link: PairLink) -> None:
        """Serve each stream the checker opens, until cancelled or crashed."""
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._ticker)
            async for stream in link.streams:
                if self.dead:
                    return
                self._stream = stream
                self.welcomed = False
                self._next_hello = trio.current_time()
                self._kick.set()
                await self._read(stream)
                if self.dead:
                    nursery.cancel_scope.cancel()
                    return

    async def _read(self, stream: Any) -> None:
        lines = LineBuffer()
        while True:
            try:
                data = await stream.receive_some(4096)
            except (trio.BrokenResourceError, trio.ClosedResourceError):
                data = b""
            if not data:
                self._stream = None
                return
            now = trio.current_time()
            self.session.note_bytes_in(len(data))
            for line in lines.feed(data):
                if line is TOO_LONG:
                    self.session.reject(FrameError("too_long", "line exceeds 1024 bytes"))
                    continue
                try:
                    frame = decode_line(line)
                except FrameError as exc:
                    if self.breaks == "crash_on_malformed" and exc.fault == "not_json":
                        self.dead = True
                        await stream.aclose()
                        return
                    self.session.reject(exc)
                    continue
                self._take(frame, now)
            self._kick.set()

    def _take(self, frame: Frame, now: float) -> None:
        duplicate = frame.seq is not None and frame.seq <= self.session.ack_value
        envelope = frame
        if frame.cmd == "fault" and frame.seq is not None:
            # the session checks reliable frames against server.protocol's catalogue, which
            # may not list the fault section's cmds: it takes seq and ack on a stand-in
            envelope = Frame("stop", "none", None, seq=frame.seq, ack=frame.ack)
        try:
            delivered = self.session.receive(envelope, now)
        except FrameError as exc:
            self.session.reject(exc, frame)
            return
        if duplicate and self.breaks == "no_dedup":
            delivered = [envelope]
        for f in delivered:
            self._on_frame(frame if f is envelope else f, now)

    async def _ticker(self) -> None:
        while not self.dead:
            now = trio.current_time()
            stream = self._stream
            if stream is not None:
                data = self._due(now)
                if data:
                    try:
                        await stream.send_all(data)
                    except (trio.BrokenResourceError, trio.ClosedResourceError):
                        self._stream = None
            deadline = min(self.session.next_deadline(now), self._next_hello
                           if not self.welcomed else math.inf,
                           min(self.next_tm.values(), default=math.inf))
            self._kick = trio.Event()
            with trio.move_on_at(max(deadline, now + 0.01)):
                await self._kick.wait()

    # -- sending --------------------------------------------------------------------

    def _hello(self) -> Frame:
        data: dict[str, Any] = {"id": f"{self.role}-t", "role": self.role,
                                "seq_base": self.session.seq_base}
        if self.streams is not None:
            data["streams"] = list(self.streams)
        if self.faults_field:
            data["faults"] = list(_FAULTS) if self.accept_faults else []
        if self.breaks == "new_session":
            self.hellos_said += 1
            data["session"] = self.hellos_said
        return Frame("hello", "rover", data)

    def _due(self, now: float) -> bytes:
        if not self.welcomed:
            out = b""
            if now >= self._next_hello:
                self._next_hello = now + self._hello_wait
                self._hello_wait = min(self._hello_wait * 2, 8.0)
                out = self.session.transmit_alone(self._hello(), now)
            if self.breaks == "chatter" and out:
                out += encode_frame(Frame("heartbeat", "beat", None))
            return out
        extra = b""
        for stream, at in list(self.next_tm.items()):
            if now >= at:
                self.next_tm[stream] = now + self.asked.get(stream, 0.5) if stream != "events" \
                    else math.inf
                frame = self._telemetry(stream, now)
                if frame is None:
                    continue
                if self.breaks == "oversized_telemetry" and stream == "map":
                    extra += msgspec.json.encode(frame) + b"\n"  # past encode_frame's bound
                else:
                    self.session.send(frame, reliable=False)
        if self.breaks == "late_acks":
            return self._late_acks(now) + extra
        return self._rewrite(self.session.transmit(now)) + extra

    def _late_acks(self, now: float) -> bytes:
        """transmit, less the bare acks, each ack field as it was a second ago."""
        self._acks.append((now, self.session.ack_value))
        while len(self._acks) > 1 and self._acks[1][0] <= now - 1.0:
            self._acks.pop(0)
        late = self._acks[0][1] if self._acks[0][0] <= now - 1.0 else 0
        out = b""
        for x in self.session.transmit(now).split(b"\n"):
            f = decode_line(x) if x else None
            if f is not None and f.cmd != "ack":
                out += encode_frame(Frame(f.cmd, f.type, f.data, seq=f.seq,
                                          ack=late if f.ack is not None else None))
        return out

    def _rewrite(self, data: bytes) -> bytes:
        """``resend_changes``: a frame sent again with its seq carries other data."""
        if self.breaks != "resend_changes" or not data:
            return data
        out = []
        for x in data.split(b"\n"):
            if not x:
                continue
            f = decode_line(x)
            if f.seq is not None and f.seq in self.sent_seqs:
                body = {**f.data, "again": 1} if isinstance(f.data, dict) else {"again": 1}
                x = encode_frame(Frame(f.cmd, f.type, body, seq=f.seq, ack=f.ack))[:-1]
            elif f.seq is not None:
                self.sent_seqs.add(f.seq)
            out.append(x + b"\n")
        return b"".join(out)

    def _telemetry(self, stream: str, now: float) -> Frame | None:
        """One update of ``stream`` (events go as they happen, not here)."""
        t = round(now, 3)
        if stream == "pose":
            return Frame("tm_pose", "pose_spread", {"t": t, "x": 1.0, "y": 2.0, "heading": 3.0,
                                                    "sx": 2.0, "sy": 2.0, "sheading": 4.0})
        if stream == "mailboxes":
            boxes = [[n, 1, 64, 10.0, 0] for n in ("wifly", "motor", "lidar", "map", "nav")]
            return Frame("tm_mailboxes", "mailboxes", {"t": t, "boxes": boxes})
        if stream == "tree":
            nodes = [[self.role, "supervisor", "running", 0, None],
                     [f"{self.role}/nav", "worker", "running", 1, "crash"]]
            return Frame("tm_tree", "tree", {"t": t, "nodes": nodes})
        if stream == "map":
            n = 200 if self.breaks == "oversized_telemetry" else 8
            cells = [[i * 7, 1 + i % 2] for i in range(n)]
            return Frame("tm_map", "map_delta", {"t": t, "nx": 100, "ny": 100,
                                                 "resolution_cm": 5.0,
                                                 "origin_cm": [-250.0, -250.0], "cells": cells})
        return None

    def _event(self, kind: str, path: str, detail: str) -> None:
        if "events" in self.asked or (self.breaks == "unasked_stream" and self.streams):
            self.session.send(Frame("tm_event", "event", {
                "t": round(trio.current_time(), 3), "kind": kind, "path": path,
                "detail": detail}), reliable=False)

    # -- receiving ------------------------------------------------------------------

    def _on_frame(self, frame: Frame, now: float) -> None:
        cmd = frame.cmd
        if cmd == "fault":
            self._fault(frame)
            return
        try:
            body = read_data(frame)
        except FrameError as exc:
            self.session.reject(exc, frame)
            return
        if cmd == "welcome":
            self.session.reset_peer(body.seq_base, body.session)
            self.welcomed = True
            self._hello_wait = 1.0
            self.session.send(make_frame("status", {"state": "idle"}))
            asked = frame.data.get("telemetry") or {}
            listed = set(self.streams or ())
            every = self.breaks == "unasked_stream"
            self.asked = {s: float(v) for s, v in asked.items() if s in listed}
            self.next_tm = {s: now for s in (listed if every else self.asked)}
        elif cmd == "error" and body.detail == "send hello first":
            self.welcomed = False
            self._next_hello = now
        elif cmd == "start":
            self.session.send(make_frame("status", {"state": "started"}))
            if self.role != "mapper":
                self.session.send(make_frame("map_request"))
        elif cmd == "stop" and self.role == "mapper":
            self._upload()
        elif cmd == "map":
            grid = self.assembler.add(body)
            if grid is not None:
                self.map = grid
                self._report()
        elif cmd == "destination":
            self.destination = body
            self._report()

    def _upload(self) -> None:
        self.map_id += 1
        frames = map_chunks(checker_map(), self.map_id)  # two chunks
        if self.breaks == "big_chunks":
            text = "".join(f.data["b64"] for f in frames)
            pieces = [text[k:k + 700] for k in range(0, len(text), 700)]
            frames = [Frame("map", "chunk", {**frames[0].data, "index": k,
                                             "count": len(pieces), "b64": p})
                      for k, p in enumerate(pieces)]
        for f in frames:
            self.session.send(f, reliable=True)

    def _report(self) -> None:
        if self.map is None or self.destination is None:
            return
        d, self.destination = self.destination, None
        spot = {"x": d.x, "y": d.y, "heading": d.heading or 0.0}
        if self.role == "hider":
            self.session.send(make_frame("arrived", spot))
        else:
            self.session.send(make_frame("not_found", {"reason": "IR saw nothing"}))

    def _fault(self, frame: Frame) -> None:
        d = frame.data if isinstance(frame.data, dict) else {}
        target, kind, op = d.get("target"), d.get("kind"), d.get("op")
        known = f"{target}/{kind}" in _FAULTS or (op == "clear" and target in _KNOWN_TARGETS)
        if known and (self.accept_faults or self.breaks == "fault_without_opt_in"):
            result = "accepted"
            self._event("fault_injected" if op == "inject" else "fault_cleared",
                        f"{self.role}/{target}", str(kind))
        elif known:
            result = "refused"
        else:
            result = "unsupported"
        self.session.send(Frame("fault_reply", "fault_reply",
                                {"fault_id": d.get("fault_id"), "result": result}),
                          reliable=True)
