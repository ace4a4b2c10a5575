"""What a structure's monitoring resumes from: the sources seen, the monitor state after the last
committed window (with the calibration), and the baselines (learning, active, superseded).

``StateStore`` is what the service needs of them, ``StateRepository`` implements it over one
SQLite connection (no transactions, no retries: the caller's)."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Sequence
from typing import Any, Protocol

__all__ = ["STATE_COLUMNS", "STATE_UPSERT", "StateRepository", "StateStore"]

#: A window's monitor state row (then ``updated_at``), and how it replaces the stored one (a
#: window without a calibration keeps the stored calibration); written by a window's transaction
#: and by the plain windows' trigger alike.
STATE_COLUMNS = ("source", "last_window_start_s", "data_time_s", "monitor", "calibration")
STATE_UPSERT = ("ON CONFLICT(source) DO UPDATE SET last_window_start_s=excluded.last_window_start_s, "
                "data_time_s=excluded.data_time_s, monitor=excluded.monitor, "
                "calibration=COALESCE(excluded.calibration, monitor_state.calibration), updated_at=excluded.updated_at")


class StateStore(Protocol):
    """Sources, monitor states and baselines of every source."""

    def touch_sources(self, sources: Sequence[tuple[str, str, str]], seen_at: float) -> None: ...

    def save_state(self, state: tuple, now: float) -> None: ...

    def load_state(self, source: str) -> dict[str, Any] | None: ...

    def save_calibration(self, source: str, calibration: dict, now: float) -> None: ...

    def request_baseline(self, source: str, now: float) -> int: ...

    def baselines(self, source: str | None) -> list[dict[str, Any]]: ...

    def store_baseline(self, source: str, baseline: dict, now: float) -> int: ...

    def learnt_baseline(self, source: str, baseline: dict, now: float) -> None: ...

    def active_baseline(self, source: str) -> dict | None: ...


class StateRepository:
    """``StateStore`` over the SQLite connection ``db`` (tables sources, monitor_state, baselines)."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db

    def touch_sources(self, sources: Sequence[tuple[str, str, str]], seen_at: float) -> None:
        """Record that each (source, kind, detail) delivered data at ``seen_at`` (UNIX s, wall
        clock). One statement of many rows: outside a transaction, the write lock is taken and
        released inside one call into SQLite (an executemany would wait for the GIL after every
        row while holding it). Chunks keep within SQLite's variables."""
        # one row per source (the last given, as successive upserts would leave it): PostgreSQL
        # refuses a statement that upserts one key twice
        latest = {source: (kind, detail) for source, kind, detail in sources}
        rows = [(source, kind, detail, seen_at, seen_at) for source, (kind, detail) in latest.items()]
        for start in range(0, len(rows), 1000):
            chunk = rows[start:start + 1000]
            self.db.execute(
                "INSERT INTO sources (id, kind, detail, first_seen_s, last_seen_s) VALUES "
                + ", ".join(["(?, ?, ?, ?, ?)"] * len(chunk))
                + " ON CONFLICT(id) DO UPDATE SET kind=excluded.kind, detail=excluded.detail, last_seen_s=excluded.last_seen_s",
                [value for row in chunk for value in row])

    def save_state(self, state: tuple, now: float) -> None:
        """A window's monitor state row (``STATE_COLUMNS``, monitor and calibration as JSON)."""
        self.db.execute(f"INSERT INTO monitor_state ({', '.join(STATE_COLUMNS)}, updated_at) "
                        f"VALUES ({', '.join('?' * (len(STATE_COLUMNS) + 1))}) {STATE_UPSERT}", (*state, now))

    def load_state(self, source: str) -> dict[str, Any] | None:
        row = self.db.execute("SELECT * FROM monitor_state WHERE source = ?", (source,)).fetchone()
        if row is None:
            return None
        return {"last_window_start_s": row["last_window_start_s"], "data_time_s": row["data_time_s"],
                "monitor": None if row["monitor"] is None else json.loads(row["monitor"]),
                "calibration": None if row["calibration"] is None else json.loads(row["calibration"])}

    def save_calibration(self, source: str, calibration: dict, now: float) -> None:
        self.db.execute("INSERT INTO monitor_state (source, calibration, updated_at) VALUES (?, ?, ?) "
                        "ON CONFLICT(source) DO UPDATE SET calibration=excluded.calibration, updated_at=excluded.updated_at",
                        (source, json.dumps(calibration), now))

    def request_baseline(self, source: str, now: float) -> int:
        """Supersede the active baseline; a new one is learnt (state 'learning'). Returns its id."""
        self.db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
        cur = self.db.execute("INSERT INTO baselines (source, state, requested_at) VALUES (?, 'learning', ?)", (source, now))
        # The monitor starts over: its stored state no longer applies.
        self.db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
        return int(cur.lastrowid or 0)

    def baselines(self, source: str | None) -> list[dict[str, Any]]:
        if source is None:
            rows = self.db.execute("SELECT * FROM baselines ORDER BY id DESC").fetchall()
        else:
            rows = self.db.execute("SELECT * FROM baselines WHERE source=? ORDER BY id DESC", (source,)).fetchall()
        out = []
        for r in rows:
            d = dict(r)
            d["data"] = None if d["data"] is None else json.loads(d["data"])
            out.append(d)
        return out

    def store_baseline(self, source: str, baseline: dict, now: float) -> int:
        """Store ``baseline`` as the active one (the previous superseded) and drop the stored
        monitor state, so that the monitor starts from it. Returns its id."""
        self.db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
        cur = self.db.execute(
            "INSERT INTO baselines (source, state, requested_at, learnt_at, start_s, end_s, data) VALUES (?, 'active', ?, ?, ?, ?, ?)",
            (source, now, now, baseline.get("start_s"), baseline.get("end_s"), json.dumps(baseline)))
        self.db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
        return int(cur.lastrowid or 0)

    def learnt_baseline(self, source: str, baseline: dict, now: float) -> None:
        """A baseline the monitor learnt in a window: the one it was learning becomes active."""
        row = self.db.execute("SELECT id FROM baselines WHERE source=? AND state='learning' ORDER BY id DESC LIMIT 1",
                              (source,)).fetchone()
        self.db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state='active'", (source,))
        args = (now, baseline.get("start_s"), baseline.get("end_s"), json.dumps(baseline))
        if row is None:
            self.db.execute("INSERT INTO baselines (source, state, requested_at, learnt_at, start_s, end_s, data) "
                            "VALUES (?, 'active', ?, ?, ?, ?, ?)", (source, now, *args))
        else:
            self.db.execute("UPDATE baselines SET state='active', learnt_at=?, start_s=?, end_s=?, data=? WHERE id=?",
                            (*args, row["id"]))

    def active_baseline(self, source: str) -> dict | None:
        """The data of the active baseline of ``source``, or None."""
        row = self.db.execute("SELECT data FROM baselines WHERE source=? AND state='active' AND data IS NOT NULL "
                              "ORDER BY id DESC LIMIT 1", (source,)).fetchone()
        return None if row is None else json.loads(row["data"])
