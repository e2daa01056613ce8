"""Game frames: what a rover reports, turned into the game's moves and the server's replies.

Poses and statuses update the rover's view; map chunks from the mapper are
assembled, judged by the game and stored; reports (arrived, found, ...) go to
the game; a game result's frames are queued to the rovers by role. Maps are
sent to a hider or seeker in chunks that must fit its session's outbox at once.
"""

from __future__ import annotations

from typing import Any

import trio

from .core import ServerCore
from .game import Phase, Result
from .peers import Rover
from .protocol import (
    CATALOGUE,
    MAP,
    TELEMETRY_CMDS,
    Fault,
    Frame,
    FrameError,
    MapError,
    OutboxFull,
    Pose,
    map_chunks,
    read_data,
)

__all__ = ["GameFrames", "MAX_MAP_CHUNKS"]


MAX_MAP_CHUNKS = 256
"""Most chunks a map may have: the download to a hider or seeker must fit a session's
outbox at once, so a bigger upload is refused at its first chunk."""


class GameFrames(ServerCore):
    """The game side of a `Server`: frames delivered by the rovers' sessions."""

    def _on_frame(self, rover: Rover, frame: Frame, now: float) -> None:
        try:
            payload = read_data(frame)
            if CATALOGUE[frame.cmd].sender == "server":
                raise FrameError(Fault.NOT_ALLOWED, f"{frame.cmd!r} is sent by the server only")
        except FrameError as exc:
            if rover.conn is not None:
                self._bad(rover.conn, exc, frame)
            return
        cmd = frame.cmd
        if cmd in TELEMETRY_CMDS:
            taken = rover.telemetry is not None and rover.telemetry.take(cmd, payload, now)
            if taken and cmd == "tm_event":  # not asked for: ignored, no error
                self._emit("rover_event", rover.id, {"kind": payload.kind, "path": payload.path,
                                                     "detail": payload.detail}, log=False)
        elif cmd == "fault_reply":
            self._emit("fault_reply", rover.id, {"fault_id": payload.fault_id,
                                                 "result": payload.result,
                                                 "detail": payload.detail or ""})
        elif cmd == "pose":
            rover.pose = Pose(payload.x, payload.y, payload.heading)
            self._emit("pose", rover.id, {"x": payload.x, "y": payload.y,
                                          "heading": payload.heading}, log=False)
        elif cmd == "status":
            rover.status = {k: v for k, v in (("state", payload.state),
                            ("detail", payload.detail), ("coverage", payload.coverage),
                            ("battery", payload.battery)) if v is not None}
            self._emit("status", rover.id, dict(rover.status), log=False)
        elif cmd == "map_request":
            self._send_map(rover, frame)
        elif cmd == MAP:
            self._on_map_chunk(rover, frame, payload, now)
        elif cmd in ("arrived", "invalid_spot", "found", "not_found"):
            pose = (Pose(payload.x, payload.y, payload.heading)
                    if hasattr(payload, "x") else None)
            reason = getattr(payload, "reason", "")
            result = self.game.on_rover(rover.role, cmd, pose, reason)
            data: dict[str, Any] = {"report": cmd, "ok": result.ok, "reason": result.reason}
            if pose is not None:
                data.update(x=pose.x, y=pose.y, heading=pose.heading_deg)
            self._emit("report", rover.id, data)
            if result.ok:
                self._apply(result)
            else:
                rover.session.send_error(FrameError(Fault.NOT_ALLOWED, result.reason), frame)
        elif cmd == "error":
            self._emit("peer_error", rover.id, {"fault": payload.fault,
                                                "detail": payload.detail})

    def _on_map_chunk(self, rover: Rover, frame: Frame, chunk: Any, now: float) -> None:
        if rover.role != "mapper":
            rover.session.send_error(FrameError(
                Fault.NOT_ALLOWED, f"only the mapper uploads maps, not the {rover.role}"), frame)
            return
        if chunk.count > MAX_MAP_CHUNKS:
            exc = FrameError(Fault.BAD_DATA, f"map: {chunk.count} chunks, a map may have at "
                             f"most {MAX_MAP_CHUNKS} (send it coarser or smaller)")
            if rover.conn is not None:
                self._bad(rover.conn, exc, frame)
            return
        try:
            grid = rover.assembler.add(chunk)
        except MapError as exc:
            if rover.conn is not None:
                self._bad(rover.conn, FrameError(Fault.BAD_DATA, f"map: {exc}"), frame)
            return
        if grid is None:
            return
        result = self.game.on_map(grid)
        map_row = self.store.save_map(grid, game_id=self.game_id, t=now, accepted=result.ok,
                                      note=result.reason)
        known = int((grid.cells >= 0).sum())
        self._emit("map", rover.id, {"map": map_row, "nx": grid.shape[1], "ny": grid.shape[0],
                                     "known_cells": known, "accepted": result.ok,
                                     "reason": result.reason})
        if result.ok:
            self._apply(result)
        else:
            rover.session.send_error(FrameError(Fault.NOT_ALLOWED, result.reason), frame)

    def _send_map(self, rover: Rover, frame: Frame | None = None) -> None:
        grid = self.game.map
        if grid is None:
            rover.session.send_error(FrameError(Fault.NOT_ALLOWED, "no map yet"), frame)
            return
        chunks = map_chunks(grid, self._map_id + 1)
        if rover.session.outbox_room() < len(chunks):
            rover.session.send_error(FrameError(Fault.BUSY, "outbox full; request the map "
                                                "later"), frame)
            return
        self._map_id += 1
        for f in chunks:
            rover.session.send(f, reliable=True)
        self._persist(rover)
        self._save_game()  # the download's map_id: a restarted server counts on from it

    def _apply(self, result: Result) -> None:
        """Queue a result's frames to the rovers and record the phase."""
        for send in result.sends:
            rid = self._role.get(send.role)
            rover = self._rovers.get(rid) if rid else None
            if rover is None:
                self._emit("refused", data={"reason": f"no {send.role} to send "
                                            f"{send.frame.cmd} to"})
                continue
            try:
                rover.session.send(send.frame)
            except OutboxFull as exc:
                self._emit("link_error", rover.id, {"error": str(exc)})
            self._flush(rover)
            self._persist(rover)
        self._save_game()
        self._emit("phase", data={"phase": str(self.game.phase), "reason": self.game.last_reason})
        if self.game.phase is Phase.FOUND:
            self.store.end_game(self.game_id, "finished",
                                f"found after {len(self.game.guesses)} "
                                f"guess{'' if len(self.game.guesses) == 1 else 'es'}",
                                trio.current_time())
