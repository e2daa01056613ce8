"""A small fake rover speaking the protocol, standing in for the firmware in tests.

It uses only `server.protocol` (as real firmware will): hello until welcome,
a `ReliableSession`, map upload/download in chunks, and a scripted behaviour
per role:

* mapper: on ``start`` reports status, uploads ``room`` after ``map_after_s``
  (or at once on ``stop``);
* hider: on ``start`` requests the map; once it has the map and a
  destination it answers ``invalid_spot`` if the spot is on an occupied or
  unknown cell, else ``arrived`` there;
* seeker: like the hider, then ``found`` when the destination is within
  ``found_within_cm`` of ``hider_at`` (map frame), else ``not_found``.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable

import numpy as np
import trio

from server.protocol import (
    Frame,
    GridMap,
    MapAssembler,
    Pose,
    ReliableSession,
    make_frame,
    map_chunks,
    read_data,
)


def room_map() -> GridMap:
    """A 2 m x 1.5 m room at 5 cm, walls around, a box in the middle; map frame at (-50, -25)."""
    cells = np.zeros((30, 40), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    cells[12:18, 18:22] = 100
    cells[25:29, 30:39] = -1
    return GridMap(cells, 5.0, (-50.0, -25.0))


class FakeRover:
    """One scripted rover (see the module docstring)."""

    def __init__(self, rid: str, role: str, *, token: str | None = None,
                 room: GridMap | None = None, map_after_s: float = 5.0,
                 hider_at: Pose | None = None, found_within_cm: float = 40.0,
                 drive_s: float = 3.0) -> None:
        self.id, self.role, self.token = rid, role, token
        self.room = room or room_map()
        self.map_after_s = map_after_s
        self.hider_at = hider_at
        self.found_within_cm = found_within_cm
        self.drive_s = drive_s
        self.session = ReliableSession()
        self.welcomed = False
        self.received: list[Frame] = []
        """Every frame delivered by the session, in order."""
        self.map: GridMap | None = None
        self.origin: Pose | None = None
        self._assembler = MapAssembler()
        self._destination: dict | None = None
        self._action_at = math.inf
        self._action: str = ""
        self._kick = trio.Event()
        self.silent = False
        """While True the rover neither sends nor reads (a dead link)."""

    def _hello(self) -> None:
        self.session.send(make_frame("hello", {"id": self.id, "role": self.role,
                                               "token": self.token,
                                               "seq_base": self.session.seq_base}))

    async def run(self, receive: Callable[[], Awaitable[bytes]],
                  send: Callable[[bytes], Awaitable[None]]) -> None:
        """Speak the protocol over a byte pipe until cancelled."""
        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._reader, receive)
            next_hello = trio.current_time()
            while True:
                now = trio.current_time()
                if not self.welcomed and now >= next_hello:
                    self._hello()
                    next_hello = now + 1.0
                if now >= self._action_at:
                    self._action_at = math.inf
                    self._act(self._action)
                data = self.session.transmit(now)
                if data and not self.silent:
                    await send(data)
                deadline = min(self.session.next_deadline(now), self._action_at,
                               next_hello if not self.welcomed else math.inf)
                self._kick = trio.Event()
                with trio.move_on_at(max(deadline, now + 1e-3)):
                    await self._kick.wait()

    async def _reader(self, receive: Callable[[], Awaitable[bytes]]) -> None:
        while True:
            data = await receive()
            if not data:
                return
            if self.silent:
                continue
            for frame in self.session.feed(data, trio.current_time()):
                self.received.append(frame)
                self._on_frame(frame)
            self._kick.set()

    def _on_frame(self, frame: Frame) -> None:
        body = read_data(frame)
        if frame.cmd == "welcome":
            self.welcomed = True
            self.session.reset_peer(body.seq_base)
        elif frame.cmd == "error" and body.detail == "send hello first":
            self.welcomed = False
        elif frame.cmd == "origin":
            self.origin = Pose(body.x, body.y, body.heading)
        elif frame.cmd == "start":
            self.session.send(make_frame("status", {"state": "started"}))
            self.session.send(make_frame("pose", {"x": 0, "y": 0, "heading": 0}))
            if self.role == "mapper":
                self._later("upload", self.map_after_s)
            else:
                self.session.send(make_frame("map_request"))
        elif frame.cmd == "stop" and self.role == "mapper":
            self._later("upload", 0.0)
        elif frame.cmd == "map":
            grid = self._assembler.add(body)
            if grid is not None:
                self.map = grid
                self._maybe_drive()
        elif frame.cmd == "destination":
            self._destination = {"x": body.x, "y": body.y, "heading": body.heading}
            self._maybe_drive()

    def _later(self, action: str, delay: float) -> None:
        self._action, self._action_at = action, trio.current_time() + delay

    def _maybe_drive(self) -> None:
        if self.map is not None and self._destination is not None:
            self._later("report", self.drive_s)

    def _act(self, action: str) -> None:
        if action == "upload":
            for f in map_chunks(self.room, map_id=1):
                self.session.send(f, reliable=True)
            self.session.send(make_frame("status", {"state": "map_sent", "coverage": 0.97}))
            return
        d, grid = self._destination, self.map
        self._destination = None
        assert d is not None and grid is not None
        j = int((d["x"] - grid.origin_cm[0]) // grid.resolution_cm)
        i = int((d["y"] - grid.origin_cm[1]) // grid.resolution_cm)
        spot = {"x": d["x"], "y": d["y"], "heading": d["heading"] or 0.0}
        if self.role == "hider":
            cell = grid.cells[i, j]
            if cell != 0:
                why = "occupied" if cell == 100 else "unknown"
                self.session.send(make_frame("invalid_spot", {"reason": f"spot is {why}"}))
            else:
                self.session.send(make_frame("arrived", spot))
        elif self.role == "seeker":
            h = self.hider_at
            if h is not None and math.hypot(h.x - d["x"], h.y - d["y"]) <= self.found_within_cm:
                self.session.send(make_frame("found", {**spot, "ir": 3000}))
            else:
                self.session.send(make_frame("not_found", {"reason": "IR saw nothing"}))


def memory_pipe(server_link_factory) -> tuple[Callable, Callable, object]:
    """Connect a fake rover to ``server.attach_memory``: returns (receive, send, link)."""
    send_ch, recv_ch = trio.open_memory_channel[bytes](1000)
    link = server_link_factory(send_ch.send_nowait)

    async def send(data: bytes) -> None:
        link.feed(data)
        await trio.lowlevel.checkpoint()

    return recv_ch.receive, send, link


async def attach_outside(server, nursery: trio.Nursery, rover: FakeRover) -> None:
    """Run ``rover`` on an untrusted memory link of ``server`` (as from outside the
    process, named ``mem:ID``) in ``nursery``; return once it is welcomed."""
    receive, send, _ = memory_pipe(lambda out: server.attach_memory(
        out, trusted=False, name=f"mem:{rover.id}"))
    nursery.start_soon(rover.run, receive, send)
    with trio.fail_after(5):
        while not rover.welcomed:
            await trio.sleep(0.1)
