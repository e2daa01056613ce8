"""Campaign results in SQLite: its own schema, beside (not inside) the server's game store."""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from typing import Any

from supervisors.harness.campaign.refs import CampaignConfig, CampaignError

_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaigns (
    id INTEGER PRIMARY KEY, seed INTEGER NOT NULL, config TEXT NOT NULL,
    started REAL NOT NULL, summary TEXT
);
CREATE TABLE IF NOT EXISTS campaign_games (
    campaign INTEGER NOT NULL REFERENCES campaigns(id), idx INTEGER NOT NULL,
    ref TEXT NOT NULL, room TEXT NOT NULL, outcome TEXT NOT NULL, reason TEXT NOT NULL,
    violations TEXT NOT NULL, faults TEXT NOT NULL, restarts INTEGER NOT NULL,
    resent INTEGER NOT NULL, sim_s REAL NOT NULL, wall_s REAL NOT NULL,
    trace_hash TEXT NOT NULL, replay_hash TEXT,
    PRIMARY KEY (campaign, idx)
);
"""


class CampaignStore:
    """Campaign results in SQLite: one row per campaign, one per game (committed as they come).

    Its own tables, in its own file by default, beside (not inside) the
    server's game store.
    """

    def __init__(self, path: str) -> None:
        try:
            self._db = sqlite3.connect(path)
            self._db.executescript(_SCHEMA)
        except sqlite3.Error as exc:
            raise CampaignError(f"cannot open campaign store {path!r}: {exc}") from None

    def __enter__(self) -> CampaignStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Commit and close."""
        self._db.commit()
        self._db.close()

    def new_campaign(self, config: CampaignConfig, started: float) -> int:
        """A campaign row; ``started`` is the wall time it began [s since the epoch]."""
        cfg = json.dumps({k: v for k, v in dataclasses.asdict(config).items()
                          if not k.startswith("_")})
        cur = self._db.execute("INSERT INTO campaigns (seed, config, started) VALUES (?, ?, ?)",
                               (config.seed, cfg, started))
        self._db.commit()
        return int(cur.lastrowid)

    def add_game(self, campaign: int, r: dict[str, Any]) -> None:
        """Store one game's result (as returned by `play_campaign_game`)."""
        self._db.execute(
            "INSERT OR REPLACE INTO campaign_games VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (campaign, r["index"], r["ref"], r["room"], r["outcome"], r["reason"],
             json.dumps(r["violations"]), json.dumps(r["faults"]), r["restarts"], r["resent"],
             r["sim_s"], r["wall_s"], r["trace_hash"], r["replay_hash"]))
        self._db.commit()

    def finish(self, campaign: int, summary: dict[str, Any]) -> None:
        """Attach the summary to the campaign row."""
        self._db.execute("UPDATE campaigns SET summary = ? WHERE id = ?",
                         (json.dumps(summary), campaign))
        self._db.commit()

    def games(self, campaign: int) -> list[tuple]:
        """(idx, outcome, violations JSON, trace_hash) per stored game, by index."""
        return self._db.execute("SELECT idx, outcome, violations, trace_hash FROM "
                                "campaign_games WHERE campaign = ? ORDER BY idx",
                                (campaign,)).fetchall()


_GAME_COLUMNS = ("index", "ref", "room", "outcome", "reason", "violations", "faults",
                 "restarts", "resent", "sim_s", "wall_s", "trace_hash", "replay_hash")


def read_campaign(path: str, campaign: int | None = None
                  ) -> tuple[int, dict[str, Any] | None, list[dict[str, Any]]]:
    """A stored campaign, read-only: (its id, its summary or None when it never finished,
    its games by index as dicts with `play_campaign_game`'s keys that the table holds).

    Args:
        path: the campaign store (``hideseek campaign --out``).
        campaign: the campaign's id; None: the newest.

    Raises:
        CampaignError: no such file, not a campaign store, or no such campaign.
    """
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    except sqlite3.Error as exc:
        raise CampaignError(f"cannot open campaign store {path!r}: {exc}") from None
    try:
        if campaign is None:
            row = db.execute("SELECT id, summary FROM campaigns ORDER BY id DESC").fetchone()
        else:
            row = db.execute("SELECT id, summary FROM campaigns WHERE id = ?",
                             (campaign,)).fetchone()
        if row is None:
            which = "no campaign" if campaign is None else f"no campaign {campaign}"
            raise CampaignError(f"{which} in {path}")
        cid, summary = row
        games = []
        for values in db.execute(
                "SELECT idx, ref, room, outcome, reason, violations, faults, restarts, resent, "
                "sim_s, wall_s, trace_hash, replay_hash FROM campaign_games "
                "WHERE campaign = ? ORDER BY idx", (cid,)):
            game = dict(zip(_GAME_COLUMNS, values, strict=True))
            game["violations"] = json.loads(game["violations"])
            game["faults"] = json.loads(game["faults"])
            games.append(game)
    except sqlite3.Error as exc:
        raise CampaignError(f"{path} is not a campaign store: {exc}") from None
    finally:
        db.close()
    return cid, (json.loads(summary) if summary else None), games
