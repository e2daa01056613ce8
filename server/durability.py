"""Durability: the game and each rover's unacknowledged frames, kept in the store.

The game's phase, map, state and roles, and each rover's unacknowledged
frames, are stored as they change; a server opened with ``resume`` on a store
whose newest game is unfinished plays that game on (see `server.store`). A map
download in flight is stored as one mark and resent whole from the game's map.
"""

from __future__ import annotations

import contextlib
from typing import Any

import trio

from .core import ServerCore
from .game import Game
from .peers import Rover
from .protocol import MAP, Frame, OutboxFull
from .store import StoreError

__all__ = ["Durability"]


class Durability(ServerCore):
    """The storage side of a `Server`: what a later server needs to play on."""

    def _resume(self, now: float) -> None:
        row = self.store.resumable_game()
        if row is None:
            return
        try:
            grid = self.store.load_map(row.map_id) if row.map_id is not None else None
            state = self.store.game_state(row.id)
            game = Game.restored(self._start_poses, row.phase, state, grid)
        except (StoreError, ValueError, TypeError) as exc:
            self.store.end_game(row.id, "stopped", f"stopped: could not resume ({exc})", now)
            return
        self.game, self.game_id, self.resumed = game, row.id, row.id
        self._map_id = int(state.get("map_seq", 0))
        self.store.resume_game(row.id)
        for role, rid in dict(state.get("roles", {})).items():
            self._role[str(role)] = str(rid)
        for rid, role, pending in self.store.rover_states(row.id):
            rover = self._new_rover(rid, role, now)
            self._restore_pending(rover, pending)
            origin = self.config.origins.get(rid, self.config.origins.get(role))
            if origin is not None:
                self._start_poses[role] = origin
        self._emit("resumed", data={"game": row.id, "phase": str(game.phase)})

    def _end_game_for_new(self) -> None:
        now = trio.current_time()
        old = self.store.game(self.game_id)
        if old.status != "finished":
            self.store.end_game(self.game_id, "stopped",
                                f"stopped by the operator (new game) in phase {old.phase}", now)
        self.game_id = self.store.new_game(now)
        for rover in self._rovers.values():
            rover.stored = None
            self._persist(rover)

    def close_game(self) -> None:
        """Record that this server stops playing its game (clean shutdown): unless
        finished or stopped, it is interrupted, to be resumed by a later server."""
        now = trio.current_time()
        with contextlib.suppress(StoreError):
            if self.store.game(self.game_id).status == "running":
                self.store.end_game(self.game_id, "interrupted",
                                    f"interrupted: the server stopped in phase {self.game.phase}",
                                    now)
        for kind in self._bursts.pending():
            self._emit(kind + "_summary", data=self._bursts.take(kind, now))

    def _save_game(self) -> None:
        state = {**self.game.state(), "roles": dict(self._role), "map_seq": self._map_id}
        self.store.save_game_state(self.game_id, str(self.game.phase), state)

    def _persist(self, rover: Rover) -> None:
        """Store the rover's role and unacknowledged frames when they changed."""
        mark = (self.game_id, rover.session.pending_mark)
        if rover.stored == mark:
            return
        rover.stored = mark
        pending: list[dict[str, Any]] = []
        for f in rover.session.pending():
            if f.cmd == MAP:  # a download in flight: resent whole from the game's map
                if not any(p["cmd"] == MAP for p in pending):
                    pending.append({"cmd": MAP})
                continue
            pending.append({"cmd": f.cmd, "type": f.type, "data": f.data})
        self.store.save_rover_state(self.game_id, rover.id, rover.role, pending)

    def _restore_pending(self, rover: Rover, pending: list[dict[str, Any]]) -> None:
        for p in pending:
            try:
                if p.get("cmd") == MAP:
                    self._send_map(rover)
                else:
                    rover.session.send(Frame(p["cmd"], p["type"], p["data"]), reliable=True)
            except (KeyError, TypeError, ValueError, OutboxFull):
                continue
