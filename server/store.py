"""SQLite storage of games, maps, rover sessions and the event log.

One file, WAL journal, autocommit: every write is its own transaction and is
on disk when the call returns, so a server killed mid-game loses nothing it
had written. On open, games still marked ``running`` are marked
``interrupted`` (their server died without ending them). Times are the
server's Trio clock [s] within a run; ``runs`` numbers server starts so times
of different runs are not confused.

Calls are synchronous and short (one statement); the server makes them from
its Trio task, which is fine for the few writes per second a game makes
(telemetry is not logged).
"""

from __future__ import annotations

import json
import pathlib
import sqlite3
from dataclasses import dataclass
from typing import Any

import numpy as np

from .protocol import MapGrid

__all__ = ["Store", "GameRow", "MapRow", "StoreError"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY, label TEXT NOT NULL DEFAULT '');
CREATE TABLE IF NOT EXISTS games (
    id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL,
    status TEXT NOT NULL,             -- running | finished | abandoned | interrupted
    phase TEXT NOT NULL, outcome TEXT NOT NULL DEFAULT '',
    started_t REAL NOT NULL, ended_t REAL);
CREATE TABLE IF NOT EXISTS maps (
    id INTEGER PRIMARY KEY, game_id INTEGER, t REAL NOT NULL,
    nx INTEGER NOT NULL, ny INTEGER NOT NULL, resolution_cm REAL NOT NULL,
    origin_x_cm REAL NOT NULL, origin_y_cm REAL NOT NULL, cells BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS rover_sessions (
    id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL, rover TEXT NOT NULL, role TEXT NOT NULL,
    link TEXT NOT NULL, opened_t REAL NOT NULL, closed_t REAL);
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL, game_id INTEGER, t REAL NOT NULL,
    kind TEXT NOT NULL, rover TEXT NOT NULL DEFAULT '', data TEXT NOT NULL DEFAULT '{}');
CREATE INDEX IF NOT EXISTS events_game ON events (game_id);
CREATE INDEX IF NOT EXISTS maps_game ON maps (game_id);
"""


class StoreError(RuntimeError):
    """Raised when the database cannot be opened or a stored item does not exist."""


@dataclass(frozen=True, slots=True)
class GameRow:
    """A stored game."""

    id: int
    run_id: int
    status: str
    phase: str
    outcome: str
    started_t: float
    ended_t: float | None


@dataclass(frozen=True, slots=True)
class MapRow:
    """A stored map's metadata (cells via `Store.load_map`)."""

    id: int
    game_id: int | None
    t: float
    nx: int
    ny: int
    resolution_cm: float
    origin_cm: tuple[float, float]


class Store:
    """The game database (see the module docstring).

    Args:
        path: database file, created when missing; ``":memory:"`` for tests.
        label: free text naming this server run (e.g. a date the caller supplies).

    Raises:
        StoreError: the file cannot be opened or is not a database.
    """

    def __init__(self, path: str | pathlib.Path, *, label: str = "") -> None:
        self.path = str(path)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"cannot open database {self.path}: {exc}") from None
        self.interrupted = self._recover()
        """Ids of games found running at open and marked interrupted."""
        self.run_id = self._db.execute("INSERT INTO runs (label) VALUES (?)", (label,)).lastrowid

    def close(self) -> None:
        """Close the database (idempotent)."""
        self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _recover(self) -> list[int]:
        ids = [r[0] for r in self._db.execute("SELECT id FROM games WHERE status = 'running'")]
        if ids:
            self._db.execute("UPDATE games SET status = 'interrupted' WHERE status = 'running'")
        return ids

    # -- games ------------------------------------------------------------------------

    def new_game(self, t: float) -> int:
        """Record a new running game; return its id."""
        return self._db.execute(
            "INSERT INTO games (run_id, status, phase, started_t) VALUES (?, 'running', 'idle', ?)",
            (self.run_id, t)).lastrowid

    def set_phase(self, game_id: int, phase: str) -> None:
        """Record the game's current phase."""
        self._db.execute("UPDATE games SET phase = ? WHERE id = ?", (phase, game_id))

    def end_game(self, game_id: int, status: str, outcome: str, t: float) -> None:
        """Close a game: ``status`` finished or abandoned, ``outcome`` free text."""
        if status not in ("finished", "abandoned"):
            raise ValueError(f"status must be finished or abandoned, got {status!r}")
        self._db.execute("UPDATE games SET status = ?, outcome = ?, ended_t = ? WHERE id = ?",
                         (status, outcome, t, game_id))

    def games(self) -> list[GameRow]:
        """Every stored game, oldest first."""
        rows = self._db.execute("SELECT id, run_id, status, phase, outcome, started_t, ended_t "
                                "FROM games ORDER BY id")
        return [GameRow(*r) for r in rows]

    def game(self, game_id: int) -> GameRow:
        """One game. Raises StoreError when there is no such game."""
        r = self._db.execute("SELECT id, run_id, status, phase, outcome, started_t, ended_t "
                             "FROM games WHERE id = ?", (game_id,)).fetchone()
        if r is None:
            raise StoreError(f"no game {game_id} in {self.path}")
        return GameRow(*r)

    # -- maps -------------------------------------------------------------------------

    def save_map(self, grid: MapGrid, *, game_id: int | None, t: float) -> int:
        """Store a map (cells as int8 bytes); return its id."""
        ny, nx = grid.shape
        return self._db.execute(
            "INSERT INTO maps (game_id, t, nx, ny, resolution_cm, origin_x_cm, origin_y_cm, cells)"
            " VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (game_id, t, nx, ny, float(grid.resolution_cm), float(grid.origin_cm[0]),
             float(grid.origin_cm[1]), np.ascontiguousarray(grid.cells, np.int8).tobytes()),
        ).lastrowid

    def maps(self) -> list[MapRow]:
        """Metadata of every stored map, oldest first."""
        rows = self._db.execute("SELECT id, game_id, t, nx, ny, resolution_cm, origin_x_cm, "
                                "origin_y_cm FROM maps ORDER BY id")
        return [MapRow(r[0], r[1], r[2], r[3], r[4], r[5], (r[6], r[7])) for r in rows]

    def load_map(self, map_id: int) -> MapGrid:
        """A stored map. Raises StoreError when there is no such map."""
        r = self._db.execute("SELECT nx, ny, resolution_cm, origin_x_cm, origin_y_cm, cells "
                             "FROM maps WHERE id = ?", (map_id,)).fetchone()
        if r is None:
            raise StoreError(f"no map {map_id} in {self.path}")
        nx, ny, res, ox, oy, blob = r
        cells = np.frombuffer(blob, dtype=np.int8).reshape(ny, nx).copy()
        return MapGrid(cells, res, (ox, oy))

    def latest_map_of_game(self, game_id: int) -> MapGrid:
        """The last map stored for a game. Raises StoreError when it has none."""
        r = self._db.execute("SELECT id FROM maps WHERE game_id = ? ORDER BY id DESC LIMIT 1",
                             (game_id,)).fetchone()
        if r is None:
            self.game(game_id)
            raise StoreError(f"game {game_id} has no map")
        return self.load_map(r[0])

    # -- rover sessions and events ------------------------------------------------------

    def open_rover_session(self, rover: str, role: str, link: str, t: float) -> int:
        """Record a rover's hello on a link; return the session row id."""
        return self._db.execute(
            "INSERT INTO rover_sessions (run_id, rover, role, link, opened_t) VALUES (?,?,?,?,?)",
            (self.run_id, rover, role, link, t)).lastrowid

    def close_rover_session(self, session_id: int, t: float) -> None:
        """Record the end of a rover session (link closed)."""
        self._db.execute("UPDATE rover_sessions SET closed_t = ? WHERE id = ?", (t, session_id))

    def rover_sessions(self) -> list[tuple]:
        """(id, run_id, rover, role, link, opened_t, closed_t) of every session."""
        return list(self._db.execute("SELECT * FROM rover_sessions ORDER BY id"))

    def log_event(self, kind: str, *, t: float, game_id: int | None = None, rover: str = "",
                  data: dict[str, Any] | None = None) -> None:
        """Append one event to the log."""
        self._db.execute(
            "INSERT INTO events (run_id, game_id, t, kind, rover, data) VALUES (?,?,?,?,?,?)",
            (self.run_id, game_id, t, kind, rover, json.dumps(data or {}, default=str)))

    def events(self, game_id: int | None = None) -> list[tuple[float, str, str, dict]]:
        """(t, kind, rover, data) of the events of one game (or all), in order."""
        if game_id is None:
            rows = self._db.execute("SELECT t, kind, rover, data FROM events ORDER BY id")
        else:
            rows = self._db.execute("SELECT t, kind, rover, data FROM events WHERE game_id = ? "
                                    "ORDER BY id", (game_id,))
        return [(t, k, r, json.loads(d)) for t, k, r, d in rows]
