"""SQLite storage of games, maps, rover sessions and the event log.

One file, WAL journal, autocommit: every write is its own transaction and is
on disk when the call returns, so a server killed mid-game (``kill -9``) loses
nothing it had written. The game is the unit of storage: its phase, the map in
play, its state (hide spot, guesses, which rover plays which role) and each
rover's unacknowledged frames are written as they change, so a server
restarted on the same file can resume it (`Store.resumable_game`).

Game status: ``running`` (a server is playing it), ``finished`` (the hider was
found), ``stopped`` (the operator ended it: a new game, or a fresh start),
``interrupted`` (its server ended while it ran: stopped cleanly, or killed, in
which case the next read-write open marks it). ``outcome`` says what happened
in words. Maps keep every upload; ``accepted`` tells the one the game played
on from uploads the game ignored (``note`` says why).

Times are the server's Trio clock [s] within a run; ``runs`` numbers server
starts so times of different runs are not confused. Calls are synchronous and
short (one statement); the server makes them from its Trio task, which is fine
for the few writes per second a game makes (telemetry is not logged).

``readonly=True`` opens the file read-only (``maps``, ``export-map``): no
recovery, no run row, never a change to a game a live server is playing.
"""

from __future__ import annotations

import json
import pathlib
import sqlite3
from dataclasses import dataclass
from typing import Any

import numpy as np

from .protocol import GridMap

__all__ = ["Store", "GameRow", "MapRow", "StoreError", "STATUSES"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY, label TEXT NOT NULL DEFAULT '');
CREATE TABLE IF NOT EXISTS games (
    id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL,
    status TEXT NOT NULL,             -- running | finished | stopped | interrupted
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
CREATE TABLE IF NOT EXISTS rover_state (
    game_id INTEGER NOT NULL, rover TEXT NOT NULL, role TEXT NOT NULL,
    pending TEXT NOT NULL DEFAULT '[]', PRIMARY KEY (game_id, rover));
CREATE INDEX IF NOT EXISTS events_game ON events (game_id);
CREATE INDEX IF NOT EXISTS maps_game ON maps (game_id);
"""

# columns added to tables of older files: (table, column, definition)
_ADDED = (("games", "map_id", "INTEGER"), ("games", "state", "TEXT NOT NULL DEFAULT '{}'"),
          ("maps", "accepted", "INTEGER NOT NULL DEFAULT 1"),
          ("maps", "note", "TEXT NOT NULL DEFAULT ''"))
STATUSES = ("running", "finished", "stopped", "interrupted")
"""Every game status (see the module docstring)."""


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
    map_id: int | None = None
    """The map the game plays on (the last upload it accepted), None before one."""


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
    accepted: bool = True
    """True when the game took this upload as its map; False when it ignored it."""
    note: str = ""
    """Why an ignored upload was ignored."""


class Store:
    """The game database (see the module docstring).

    Args:
        path: database file, created when missing; ``":memory:"`` for tests.
        label: free text naming this server run (e.g. a date the caller supplies).
        readonly: open an existing file read-only (no recovery, no run row).

    Raises:
        StoreError: the file cannot be opened or is not a database.
    """

    def __init__(self, path: str | pathlib.Path, *, label: str = "",
                 readonly: bool = False) -> None:
        self.path = str(path)
        self.readonly = readonly
        self.interrupted: list[int] = []
        """Ids of games found running at open and marked interrupted."""
        self.run_id = 0
        try:
            if readonly:
                uri = f"{pathlib.Path(self.path).resolve().as_uri()}?mode=ro"
                self._db = sqlite3.connect(uri, uri=True, isolation_level=None)
                self._db.execute("SELECT count(*) FROM sqlite_master").fetchone()
            else:
                self._db = sqlite3.connect(self.path, isolation_level=None)
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
                self._db.executescript(_SCHEMA)
                self._migrate()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"cannot open database {self.path}: {exc}") from None
        self._cols = {t: self._columns(t) for t in ("games", "maps")}
        if not readonly:
            self.interrupted = self._recover()
            self.run_id = self._db.execute("INSERT INTO runs (label) VALUES (?)",
                                           (label,)).lastrowid

    def close(self) -> None:
        """Close the database (idempotent)."""
        self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _columns(self, table: str) -> set[str]:
        return {r[1] for r in self._db.execute(f"PRAGMA table_info({table})")}

    def _migrate(self) -> None:
        for table, column, definition in _ADDED:
            if column not in self._columns(table):
                self._db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {definition}")

    def _recover(self) -> list[int]:
        ids = [r[0] for r in self._db.execute("SELECT id FROM games WHERE status = 'running'")]
        for gid in ids:
            self._db.execute(
                "UPDATE games SET status = 'interrupted', outcome = 'interrupted: the server "
                "ended without closing it (killed or crashed) in phase ' || phase WHERE id = ?",
                (gid,))
        return ids

    def _select(self, table: str, names: tuple[str, ...]) -> str:
        """A select list that reads columns an older read-only file lacks as NULL."""
        return ", ".join(n if n in self._cols[table] else f"NULL AS {n}" for n in names)

    # -- games ------------------------------------------------------------------------

    _GAME_COLS = ("id", "run_id", "status", "phase", "outcome", "started_t", "ended_t",
                  "map_id")

    def new_game(self, t: float) -> int:
        """Record a new running game; return its id."""
        return self._db.execute(
            "INSERT INTO games (run_id, status, phase, started_t) VALUES (?, 'running', 'idle', ?)",
            (self.run_id, t)).lastrowid

    def set_phase(self, game_id: int, phase: str) -> None:
        """Record the game's current phase."""
        self._db.execute("UPDATE games SET phase = ? WHERE id = ?", (phase, game_id))

    def save_game_state(self, game_id: int, phase: str, state: dict[str, Any]) -> None:
        """Record the game's phase and state (a JSON object) in one write."""
        self._db.execute("UPDATE games SET phase = ?, state = ? WHERE id = ?",
                         (phase, json.dumps(state), game_id))

    def game_state(self, game_id: int) -> dict[str, Any]:
        """The state last saved by `save_game_state` (empty when none)."""
        r = self._db.execute("SELECT state FROM games WHERE id = ?", (game_id,)).fetchone()
        if r is None:
            raise StoreError(f"no game {game_id} in {self.path}")
        return json.loads(r[0] or "{}")

    def end_game(self, game_id: int, status: str, outcome: str, t: float) -> None:
        """Close a game: ``status`` one of `STATUSES` but running, ``outcome`` in words."""
        if status not in STATUSES[1:]:
            raise ValueError(f"status must be one of {', '.join(STATUSES[1:])}, got {status!r}")
        self._db.execute("UPDATE games SET status = ?, outcome = ?, ended_t = ? WHERE id = ?",
                         (status, outcome, t, game_id))

    def resume_game(self, game_id: int) -> None:
        """Mark an interrupted game running again (a restarted server plays it on)."""
        self._db.execute("UPDATE games SET status = 'running', outcome = '', ended_t = NULL, "
                         "run_id = ? WHERE id = ?", (self.run_id, game_id))

    def resumable_game(self) -> GameRow | None:
        """The newest game, when it is unfinished (interrupted); None otherwise."""
        games = self.games()
        if games and games[-1].status == "interrupted":
            return games[-1]
        return None

    def games(self) -> list[GameRow]:
        """Every stored game, oldest first."""
        rows = self._db.execute(f"SELECT {self._select('games', self._GAME_COLS)} "
                                "FROM games ORDER BY id")
        return [GameRow(*r) for r in rows]

    def game(self, game_id: int) -> GameRow:
        """One game. Raises StoreError when there is no such game."""
        r = self._db.execute(f"SELECT {self._select('games', self._GAME_COLS)} "
                             "FROM games WHERE id = ?", (game_id,)).fetchone()
        if r is None:
            raise StoreError(f"no game {game_id} in {self.path}")
        return GameRow(*r)

    # -- maps -------------------------------------------------------------------------

    def save_map(self, grid: GridMap, *, game_id: int | None, t: float, accepted: bool = True,
                 note: str = "") -> int:
        """Store a map (cells as int8 bytes); return its id.

        An accepted map becomes the game's map in play; an ignored one is kept
        apart, with ``note`` saying why.
        """
        ny, nx = grid.shape
        map_id = self._db.execute(
            "INSERT INTO maps (game_id, t, nx, ny, resolution_cm, origin_x_cm, origin_y_cm, cells,"
            " accepted, note) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (game_id, t, nx, ny, float(grid.resolution_cm), float(grid.origin_cm[0]),
             float(grid.origin_cm[1]), np.ascontiguousarray(grid.cells, np.int8).tobytes(),
             int(accepted), note),
        ).lastrowid
        if accepted and game_id is not None:
            self._db.execute("UPDATE games SET map_id = ? WHERE id = ?", (map_id, game_id))
        return map_id

    _MAP_COLS = ("id", "game_id", "t", "nx", "ny", "resolution_cm", "origin_x_cm",
                 "origin_y_cm", "accepted", "note")

    def maps(self) -> list[MapRow]:
        """Metadata of every stored map, oldest first."""
        rows = self._db.execute(f"SELECT {self._select('maps', self._MAP_COLS)} "
                                "FROM maps ORDER BY id")
        return [MapRow(r[0], r[1], r[2], r[3], r[4], r[5], (r[6], r[7]),
                       bool(1 if r[8] is None else r[8]), r[9] or "") for r in rows]

    def load_map(self, map_id: int) -> GridMap:
        """A stored map. Raises StoreError when there is no such map."""
        r = self._db.execute("SELECT nx, ny, resolution_cm, origin_x_cm, origin_y_cm, cells "
                             "FROM maps WHERE id = ?", (map_id,)).fetchone()
        if r is None:
            raise StoreError(f"no map {map_id} in {self.path}")
        nx, ny, res, ox, oy, blob = r
        cells = np.frombuffer(blob, dtype=np.int8).reshape(ny, nx).copy()
        return GridMap(cells, res, (ox, oy))

    def latest_map_of_game(self, game_id: int) -> GridMap:
        """The last map stored for a game, accepted or not. Raises StoreError when it has none."""
        r = self._db.execute("SELECT id FROM maps WHERE game_id = ? ORDER BY id DESC LIMIT 1",
                             (game_id,)).fetchone()
        if r is None:
            self.game(game_id)
            raise StoreError(f"game {game_id} has no map")
        return self.load_map(r[0])

    def game_map_id(self, game_id: int) -> int:
        """Id of the map a game played on. Raises StoreError when it has none."""
        game = self.game(game_id)
        if game.map_id is not None:
            return game.map_id
        if "map_id" not in self._cols["games"]:  # an older file: its last upload
            r = self._db.execute("SELECT id FROM maps WHERE game_id = ? ORDER BY id DESC "
                                 "LIMIT 1", (game_id,)).fetchone()
            if r is not None:
                return r[0]
        ignored = sum(1 for m in self.maps() if m.game_id == game_id)
        more = f" ({ignored} upload(s) it ignored; see 'hideseek maps')" if ignored else ""
        raise StoreError(f"game {game_id} has no map{more}")

    def game_map(self, game_id: int) -> GridMap:
        """The map a game played on. Raises StoreError when it has none."""
        return self.load_map(self.game_map_id(game_id))

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

    def save_rover_state(self, game_id: int, rover: str, role: str,
                         pending: list[dict[str, Any]]) -> None:
        """Record a rover's role in a game and the frames it has not acknowledged."""
        self._db.execute(
            "INSERT INTO rover_state (game_id, rover, role, pending) VALUES (?, ?, ?, ?) "
            "ON CONFLICT (game_id, rover) DO UPDATE SET role = excluded.role, "
            "pending = excluded.pending", (game_id, rover, role, json.dumps(pending)))

    def rover_states(self, game_id: int) -> list[tuple[str, str, list[dict[str, Any]]]]:
        """(rover, role, pending frames) of every rover recorded for a game."""
        rows = self._db.execute("SELECT rover, role, pending FROM rover_state WHERE game_id = ?"
                                " ORDER BY rover", (game_id,))
        return [(r, role, json.loads(p)) for r, role, p in rows]

    def log_event(self, kind: str, *, t: float, game_id: int | None = None, rover: str = "",
                  data: dict[str, Any] | None = None) -> None:
        """Append one event to the log."""
        self._db.execute(
            "INSERT INTO events (run_id, game_id, t, kind, rover, data) VALUES (?,?,?,?,?,?)",
            (self.run_id, game_id, t, kind, rover, json.dumps(data or {}, default=str)))

    def last_fault_id(self) -> int:
        """The highest ``fault_id`` of a ``fault_sent`` event in the store (0 when none), so a
        later server numbers its faults past every one a rover may remember."""
        row = self._db.execute("SELECT MAX(CAST(json_extract(data, '$.fault_id') AS INTEGER)) "
                               "FROM events WHERE kind = 'fault_sent'").fetchone()
        return int(row[0] or 0)

    def events(self, game_id: int | None = None) -> list[tuple[float, str, str, dict]]:
        """(t, kind, rover, data) of the events of one game (or all), in order."""
        if game_id is None:
            rows = self._db.execute("SELECT t, kind, rover, data FROM events ORDER BY id")
        else:
            rows = self._db.execute("SELECT t, kind, rover, data FROM events WHERE game_id = ? "
                                    "ORDER BY id", (game_id,))
        return [(t, k, r, json.loads(d)) for t, k, r, d in rows]

    def size_bytes(self) -> int:
        """Pages in use times page size [bytes]: what the file holds, WAL checkpointed or not."""
        pages = self._db.execute("PRAGMA page_count").fetchone()[0]
        free = self._db.execute("PRAGMA freelist_count").fetchone()[0]
        return (pages - free) * self._db.execute("PRAGMA page_size").fetchone()[0]
