"""SQLite store: round trips, crash recovery after a killed server process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from server.protocol import GridMap
from server.store import Store, StoreError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_map_and_events_round_trip(tmp_path) -> None:
    """A stored map and events read back identical; WAL mode is on."""
    cells = np.array([[-1, 0], [100, 0], [0, 0]], dtype=np.int8)
    with Store(tmp_path / "g.db") as store:
        gid = store.new_game(t=1.5)
        mid = store.save_map(GridMap(cells, 5.0, (-10.0, 20.0)), game_id=gid, t=2.0)
        store.log_event("phase", t=2.0, game_id=gid, data={"phase": "map_ready"})
        assert store._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        back = store.load_map(mid)
        assert back.same_as(GridMap(cells, 5.0, (-10.0, 20.0)))
        assert store.events(gid) == [(2.0, "phase", "", {"phase": "map_ready"})]
        with pytest.raises(StoreError, match="no map 99 in "):
            store.load_map(99)
        empty = store.new_game(t=3.0)
        with pytest.raises(StoreError, match=f"game {empty} has no map"):
            store.latest_map_of_game(empty)


def test_killed_server_keeps_maps_and_marks_game_interrupted(tmp_path) -> None:
    """A process killed (SIGKILL) mid-game leaves its map and events; the game is interrupted."""
    db = tmp_path / "crash.db"
    child = textwrap.dedent(f"""
        import sys, time, numpy as np
        sys.path.insert(0, {ROOT!r})
        from server.store import Store
        from server.protocol import GridMap
        s = Store({str(db)!r})
        gid = s.new_game(t=0.0)
        s.save_map(GridMap(np.full((4, 5), 100, np.int8), 5.0, (0.0, 0.0)), game_id=gid, t=1.0)
        s.set_phase(gid, "hiding")
        s.log_event("phase", t=1.0, game_id=gid, data={{"phase": "hiding"}})
        print("ready", flush=True)
        time.sleep(60)
    """)
    proc = subprocess.Popen([sys.executable, "-c", child], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    with Store(db) as store:
        assert store.interrupted == [1]
        (game,) = store.games()
        assert (game.status, game.phase) == ("interrupted", "hiding")
        assert store.latest_map_of_game(1).cells.tolist() == [[100] * 5] * 4
        assert [k for _, k, _, _ in store.events(1)] == ["phase"]
    with Store(db) as again:
        assert again.interrupted == []  # marked once, stays marked


def test_end_game_refuses_unknown_status(tmp_path) -> None:
    """Only finished, stopped and interrupted close a game."""
    with Store(":memory:") as store:
        gid = store.new_game(t=0)
        with pytest.raises(ValueError, match="status must be one of finished, stopped, "
                                             "interrupted, got 'won'"):
            store.end_game(gid, "won", "", t=1)


def test_unreadable_file_gives_store_error(tmp_path) -> None:
    """A file that is not a database is refused with a clear message."""
    bad = tmp_path / "bad.db"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(StoreError, match="cannot open database"):
        Store(bad)


OLD_SCHEMA = """
CREATE TABLE runs (id INTEGER PRIMARY KEY, label TEXT NOT NULL DEFAULT '');
CREATE TABLE games (id INTEGER PRIMARY KEY, run_id INTEGER NOT NULL, status TEXT NOT NULL,
    phase TEXT NOT NULL, outcome TEXT NOT NULL DEFAULT '', started_t REAL NOT NULL,
    ended_t REAL);
CREATE TABLE maps (id INTEGER PRIMARY KEY, game_id INTEGER, t REAL NOT NULL,
    nx INTEGER NOT NULL, ny INTEGER NOT NULL, resolution_cm REAL NOT NULL,
    origin_x_cm REAL NOT NULL, origin_y_cm REAL NOT NULL, cells BLOB NOT NULL);
INSERT INTO runs (label) VALUES ('');
INSERT INTO games (run_id, status, phase, started_t) VALUES (1, 'finished', 'found', 0);
INSERT INTO maps (game_id, t, nx, ny, resolution_cm, origin_x_cm, origin_y_cm, cells)
    VALUES (1, 1.0, 2, 1, 5.0, 0.0, 0.0, X'0064');
"""


def test_a_file_of_the_older_schema_reads_read_only_and_migrates(tmp_path) -> None:
    """Read-only, an older file's games and maps read (its last upload is the game's
    map); opened read-write it gains the new columns and keeps its rows."""
    import sqlite3

    db = tmp_path / "old.db"
    con = sqlite3.connect(db)
    con.executescript(OLD_SCHEMA)
    con.close()
    with Store(db, readonly=True) as store:
        (game,) = store.games()
        assert (game.status, game.map_id) == ("finished", None)
        assert store.game_map(1).cells.tolist() == [[0, 100]]
        assert store.maps()[0].accepted
    with Store(db) as store:
        assert store.game(1).phase == "found"
        store.save_map(GridMap(np.zeros((1, 2), np.int8), 5.0, (0.0, 0.0)), game_id=1, t=2.0,
                       accepted=False, note="ignored")
        assert [m.accepted for m in store.maps()] == [True, False]


def test_read_only_store_refuses_writes_and_leaves_running_games(tmp_path) -> None:
    """A read-only open neither recovers nor records a run; writing through it fails."""
    db = tmp_path / "live.db"
    with Store(db) as live:
        gid = live.new_game(t=0.0)
        with Store(db, readonly=True) as ro:
            assert ro.games()[0].status == "running" and ro.interrupted == []
            with pytest.raises(Exception, match="readonly"):
                ro.new_game(t=1.0)
        assert live.game(gid).status == "running"
