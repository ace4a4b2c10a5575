"""SQLite storage of the service (WAL): trends, baselines, monitor state, alarms, the
notification outbox and its attempt log. The schema is versioned (``PRAGMA user_version``) and
upgraded by the migrations below, in order, each in one transaction.

Everything that one analysis window produces (its trend rows, the monitor state after it, alarm
changes, alarm events and the outbox rows of their notifications) is written in ONE transaction
(``commit_window``), so a crash at any instant leaves either all of it or none of it.
"""

from __future__ import annotations

import json
import math
import sqlite3
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from contract import AlarmDocument, AlarmEventDocument, TrendRow

__all__ = ["AlarmChange", "SCHEMA_VERSION", "Storage", "WindowCommit"]

_MIGRATIONS: tuple[str, ...] = (
    # 1: the first schema
    """
    CREATE TABLE meta (
        key TEXT PRIMARY KEY,
        value TEXT NOT NULL
    );
    INSERT INTO meta (key, value) VALUES ('instance', lower(hex(randomblob(8))));
    CREATE TABLE sources (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        detail TEXT NOT NULL DEFAULT '',
        first_seen_s REAL NOT NULL,
        last_seen_s REAL NOT NULL
    );
    CREATE TABLE trends (
        source TEXT NOT NULL,
        window_start_s REAL NOT NULL,
        window_end_s REAL NOT NULL,
        mode INTEGER NOT NULL,
        unit INTEGER NOT NULL,
        kind TEXT NOT NULL,
        frequency_hz REAL,
        damping_ratio REAL,
        amplitude REAL,
        confidence REAL,
        temperature_c REAL,
        curvature_index REAL,
        score_sigma REAL,
        level TEXT,
        created_at REAL NOT NULL,
        PRIMARY KEY (source, window_start_s, mode)
    ) WITHOUT ROWID;
    CREATE INDEX trends_time ON trends (window_start_s);
    CREATE TABLE baselines (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        source TEXT NOT NULL,
        state TEXT NOT NULL CHECK (state IN ('learning', 'active', 'superseded')),
        requested_at REAL NOT NULL,
        learnt_at REAL,
        start_s REAL,
        end_s REAL,
        data TEXT
    );
    CREATE TABLE monitor_state (
        source TEXT PRIMARY KEY,
        last_window_start_s REAL,
        data_time_s REAL,
        monitor TEXT,
        calibration TEXT,
        updated_at REAL NOT NULL
    );
    CREATE TABLE alarms (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        source TEXT NOT NULL,
        chart TEXT NOT NULL,
        kind TEXT NOT NULL,
        mode INTEGER,
        level TEXT NOT NULL CHECK (level IN ('warning', 'alarm')),
        state TEXT NOT NULL CHECK (state IN ('active', 'cleared')),
        raised_at_s REAL NOT NULL,
        cleared_at_s REAL,
        acknowledged_at REAL,
        acknowledged_by TEXT,
        value REAL,
        threshold REAL,
        message TEXT NOT NULL,
        UNIQUE (source, chart, raised_at_s)
    );
    CREATE TABLE alarm_events (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        alarm_id INTEGER NOT NULL REFERENCES alarms(id),
        event TEXT NOT NULL CHECK (event IN ('raised', 'escalated', 'cleared', 'acknowledged')),
        level TEXT NOT NULL,
        at_s REAL NOT NULL,
        created_at REAL NOT NULL
    );
    CREATE TABLE outbox (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        event_id INTEGER NOT NULL REFERENCES alarm_events(id),
        channel TEXT NOT NULL,
        target TEXT NOT NULL,
        payload TEXT NOT NULL,
        status TEXT NOT NULL CHECK (status IN ('pending', 'sent', 'failed')),
        attempts INTEGER NOT NULL DEFAULT 0,
        next_attempt_at REAL NOT NULL,
        created_at REAL NOT NULL,
        sent_at REAL,
        UNIQUE (event_id, channel, target)
    );
    CREATE INDEX outbox_pending ON outbox (status, next_attempt_at);
    CREATE TABLE notification_log (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        outbox_id INTEGER NOT NULL REFERENCES outbox(id),
        attempt INTEGER NOT NULL,
        at REAL NOT NULL,
        ok INTEGER NOT NULL,
        detail TEXT NOT NULL
    );
    """,
    # 2: one spelling of the acknowledgement time, like the alarm's other times (UNIX s)
    """
    ALTER TABLE alarms RENAME COLUMN acknowledged_at TO acknowledged_at_s;
    """,
    # 3: recordings reprocessed into the trends (shm reprocess): a file is done once its row is
    # committed with its trend rows; key = content hash + configuration (incl. the source)
    """
    CREATE TABLE reprocessed (
        key TEXT PRIMARY KEY,
        path TEXT NOT NULL,
        source TEXT NOT NULL,
        content_sha256 TEXT NOT NULL,
        configuration TEXT NOT NULL,
        windows INTEGER NOT NULL,
        start_s REAL,
        end_s REAL,
        done_at REAL NOT NULL
    );
    """,
)

SCHEMA_VERSION = len(_MIGRATIONS)

#: The trend table's columns are the trend row document's fields, the alarm table's the alarm document's.
TREND_COLUMNS = tuple(TrendRow.model_fields)
ALARM_COLUMNS = tuple(AlarmDocument.model_fields)


def _finite(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class AlarmChange:
    """What the alarm logic decided for one chart in one window.

    ``action``: "raise" (new alarm at ``level``), "escalate" (the active alarm of the chart goes
    to "alarm"), "clear" (the active alarm of the chart clears)."""

    action: str
    chart: str
    kind: str
    mode: int | None
    level: str
    at_s: float
    value: float | None
    threshold: float | None
    message: str


@dataclass
class WindowCommit:
    """Everything one window writes, committed atomically."""

    source: str
    window_start_s: float
    data_time_s: float
    rows: list[TrendRow]
    monitor_state: dict | None
    calibration: dict | None
    alarm_changes: list[AlarmChange] = field(default_factory=list)
    baseline: dict | None = None  # a newly learnt baseline to store as active


class Storage:
    """The service's database. Thread-safe: one connection guarded by a lock (writes are short
    transactions; WAL lets the dashboard and API read while the pipeline writes)."""

    def __init__(self, path: str | Path, *, notify_targets: Sequence[tuple[str, str]] = (),
                 notify_levels: Sequence[str] = ("warning", "alarm"), notify_cleared: bool = True, sync: str = "normal") -> None:
        self.path = Path(path)
        if str(path) != ":memory:":
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None, timeout=30.0)
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        # WAL + NORMAL: a committed transaction survives a crash of the process (SIGKILL);
        # only a power loss may roll back the last ones. Set storage_sync="full" for that too.
        self._db.execute(f"PRAGMA synchronous={'FULL' if sync == 'full' else 'NORMAL'}")
        self._db.execute("PRAGMA foreign_keys=ON")
        self.notify_targets = tuple(notify_targets)
        self.notify_levels = tuple(notify_levels)
        self.notify_cleared = notify_cleared
        self.migrate()

    # -- schema ---------------------------------------------------------------------------------

    @property
    def schema_version(self) -> int:
        with self._lock:
            return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    def migrate(self) -> None:
        """Bring the schema to ``SCHEMA_VERSION``; refuses a database of a newer version."""
        with self._lock:
            version = self.schema_version
            if version > SCHEMA_VERSION:
                raise RuntimeError(f"{self.path}: schema version {version} is newer than this program's {SCHEMA_VERSION}")
            for number in range(version + 1, SCHEMA_VERSION + 1):
                script = _MIGRATIONS[number - 1]
                self._db.execute("BEGIN IMMEDIATE")
                try:
                    for statement in (s.strip() for s in script.split(";")):
                        if statement:
                            self._db.execute(statement)
                    self._db.execute(f"PRAGMA user_version = {number}")
                    self._db.execute("COMMIT")
                except BaseException:
                    self._db.execute("ROLLBACK")
                    raise

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    def close(self) -> None:
        with self._lock:
            self._db.close()

    @property
    def instance(self) -> str:
        """A random id of this database (keys of notifications: unique across databases)."""
        with self._lock:
            return str(self._db.execute("SELECT value FROM meta WHERE key='instance'").fetchone()[0])

    # -- sources and state ----------------------------------------------------------------------

    def touch_source(self, source: str, kind: str, detail: str, data_time_s: float) -> None:
        with self.transaction() as db:
            db.execute(
                "INSERT INTO sources (id, kind, detail, first_seen_s, last_seen_s) VALUES (?, ?, ?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET kind=excluded.kind, detail=excluded.detail, last_seen_s=excluded.last_seen_s",
                (source, kind, detail, data_time_s, data_time_s),
            )

    def load_state(self, source: str) -> dict[str, Any] | None:
        with self._lock:
            row = self._db.execute("SELECT * FROM monitor_state WHERE source = ?", (source,)).fetchone()
        if row is None:
            return None
        return {
            "last_window_start_s": row["last_window_start_s"],
            "data_time_s": row["data_time_s"],
            "monitor": None if row["monitor"] is None else json.loads(row["monitor"]),
            "calibration": None if row["calibration"] is None else json.loads(row["calibration"]),
        }

    def save_calibration(self, source: str, calibration: dict) -> None:
        with self.transaction() as db:
            db.execute(
                "INSERT INTO monitor_state (source, calibration, updated_at) VALUES (?, ?, ?) "
                "ON CONFLICT(source) DO UPDATE SET calibration=excluded.calibration, updated_at=excluded.updated_at",
                (source, json.dumps(calibration), time.time()),
            )

    # -- baselines ------------------------------------------------------------------------------

    def request_baseline(self, source: str) -> int:
        """Supersede the active baseline; a new one is learnt (state 'learning'). Returns its id."""
        with self.transaction() as db:
            db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
            cur = db.execute(
                "INSERT INTO baselines (source, state, requested_at) VALUES (?, 'learning', ?)", (source, time.time())
            )
            # The monitor starts over: its stored state no longer applies.
            db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
            return int(cur.lastrowid)

    def baselines(self, source: str | None = None) -> list[dict[str, Any]]:
        with self._lock:
            if source is None:
                rows = self._db.execute("SELECT * FROM baselines ORDER BY id DESC").fetchall()
            else:
                rows = self._db.execute("SELECT * FROM baselines WHERE source=? ORDER BY id DESC", (source,)).fetchall()
        out = []
        for r in rows:
            d = dict(r)
            d["data"] = None if d["data"] is None else json.loads(d["data"])
            out.append(d)
        return out

    def store_baseline(self, source: str, baseline: dict) -> int:
        """Store ``baseline`` (``analytics.Baseline.to_dict()``) as the active baseline of
        ``source`` (the previous one superseded); the stored monitor state of the source is
        dropped so that the service starts its monitor from this baseline. Returns its id."""
        now = time.time()
        with self.transaction() as db:
            db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
            cur = db.execute(
                "INSERT INTO baselines (source, state, requested_at, learnt_at, start_s, end_s, data) "
                "VALUES (?, 'active', ?, ?, ?, ?, ?)",
                (source, now, now, baseline.get("start_s"), baseline.get("end_s"), json.dumps(baseline)),
            )
            db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
            return int(cur.lastrowid)

    def active_baseline(self, source: str) -> dict | None:
        """The data of the active baseline of ``source``, or None."""
        with self._lock:
            row = self._db.execute(
                "SELECT data FROM baselines WHERE source=? AND state='active' AND data IS NOT NULL ORDER BY id DESC LIMIT 1",
                (source,)).fetchone()
        return None if row is None else json.loads(row["data"])

    # -- reprocessed recordings ---------------------------------------------------------------

    def reprocessed(self, keys: Sequence[str]) -> set[str]:
        """Which of ``keys`` are done (committed by ``commit_reprocessed``)."""
        with self._lock:
            return {r["key"] for r in self._db.execute(
                f"SELECT key FROM reprocessed WHERE key IN ({', '.join('?' * len(keys))})", tuple(keys)).fetchall()}

    def commit_reprocessed(self, *, key: str, path: str, source: str, content_sha256: str, configuration: str,
                           windows: int, start_s: float | None, end_s: float | None, rows: list[TrendRow]) -> None:
        """A reprocessed recording's trend rows (replacing those of the same windows) and its
        ledger row, in one transaction: after a kill a file is either done or not started."""
        now = time.time()
        with self.transaction() as db:
            for r in rows:
                if r.source != source:
                    raise ValueError(f"trend row of source {r.source!r} for source {source!r}")
            db.executemany(
                f"INSERT OR REPLACE INTO trends ({', '.join(TREND_COLUMNS)}, created_at) VALUES ({', '.join('?' * (len(TREND_COLUMNS) + 1))})",
                [(*(getattr(r, c) for c in TREND_COLUMNS), now) for r in rows],
            )
            db.execute(
                "INSERT INTO sources (id, kind, detail, first_seen_s, last_seen_s) VALUES (?, 'reprocess', ?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET first_seen_s=MIN(first_seen_s, excluded.first_seen_s), "
                "last_seen_s=MAX(last_seen_s, excluded.last_seen_s)",
                (source, path, start_s if start_s is not None else now, end_s if end_s is not None else now),
            )
            db.execute(
                "INSERT OR REPLACE INTO reprocessed (key, path, source, content_sha256, configuration, windows, start_s, end_s, done_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (key, path, source, content_sha256, configuration, windows, start_s, end_s, now),
            )

    # -- windows --------------------------------------------------------------------------------

    def commit_window(self, commit: WindowCommit) -> list[int]:
        """Write a window's rows, state, alarm changes and their outbox rows in one transaction.
        Rows of a window already stored are ignored (replaying the same period). Returns the ids
        of the alarm events written."""
        now = time.time()
        events: list[int] = []
        with self.transaction() as db:
            for r in commit.rows:
                if r.source != commit.source:
                    raise ValueError(f"trend row of source {r.source!r} in a commit of source {commit.source!r}")
            db.executemany(
                f"INSERT OR IGNORE INTO trends ({', '.join(TREND_COLUMNS)}, created_at) VALUES ({', '.join('?' * (len(TREND_COLUMNS) + 1))})",
                [(*(getattr(r, c) for c in TREND_COLUMNS), now) for r in commit.rows],
            )
            db.execute(
                "INSERT INTO monitor_state (source, last_window_start_s, data_time_s, monitor, calibration, updated_at) "
                "VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(source) DO UPDATE SET last_window_start_s=excluded.last_window_start_s, "
                "data_time_s=excluded.data_time_s, monitor=excluded.monitor, "
                "calibration=COALESCE(excluded.calibration, monitor_state.calibration), updated_at=excluded.updated_at",
                (commit.source, commit.window_start_s, commit.data_time_s,
                 None if commit.monitor_state is None else json.dumps(commit.monitor_state),
                 None if commit.calibration is None else json.dumps(commit.calibration), now),
            )
            if commit.baseline is not None:
                self._store_baseline(db, commit.source, commit.baseline, now)
            for change in commit.alarm_changes:
                event = self._apply_alarm(db, commit.source, change, now)
                if event is not None:
                    events.append(event)
        return events

    def _store_baseline(self, db: sqlite3.Connection, source: str, baseline: dict, now: float) -> None:
        row = db.execute("SELECT id FROM baselines WHERE source=? AND state='learning' ORDER BY id DESC LIMIT 1", (source,)).fetchone()
        db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state='active'", (source,))
        args = (now, baseline.get("start_s"), baseline.get("end_s"), json.dumps(baseline))
        if row is None:
            db.execute(
                "INSERT INTO baselines (source, state, requested_at, learnt_at, start_s, end_s, data) VALUES (?, 'active', ?, ?, ?, ?, ?)",
                (source, now, *args),
            )
        else:
            db.execute("UPDATE baselines SET state='active', learnt_at=?, start_s=?, end_s=?, data=? WHERE id=?", (*args, row["id"]))

    def _apply_alarm(self, db: sqlite3.Connection, source: str, change: AlarmChange, now: float) -> int | None:
        active = db.execute(
            "SELECT * FROM alarms WHERE source=? AND chart=? AND state='active' ORDER BY id DESC LIMIT 1", (source, change.chart)
        ).fetchone()
        if change.action == "raise":
            if active is not None:
                return None
            cur = db.execute(
                "INSERT OR IGNORE INTO alarms (source, chart, kind, mode, level, state, raised_at_s, value, threshold, message) "
                "VALUES (?, ?, ?, ?, ?, 'active', ?, ?, ?, ?)",
                (source, change.chart, change.kind, change.mode, change.level, change.at_s, _finite(change.value),
                 _finite(change.threshold), change.message),
            )
            if not cur.rowcount:
                return None
            alarm_id, event = int(cur.lastrowid), "raised"
        elif change.action == "escalate":
            if active is None or active["level"] == "alarm":
                return None
            alarm_id, event = int(active["id"]), "escalated"
            db.execute("UPDATE alarms SET level='alarm', value=?, threshold=?, message=? WHERE id=?",
                       (_finite(change.value), _finite(change.threshold), change.message, alarm_id))
        elif change.action == "clear":
            if active is None:
                return None
            alarm_id, event = int(active["id"]), "cleared"
            db.execute("UPDATE alarms SET state='cleared', cleared_at_s=? WHERE id=?", (change.at_s, alarm_id))
        else:
            raise ValueError(f"unknown alarm action {change.action!r}")
        return self._event(db, alarm_id, event, change.level, change.at_s, now)

    def _event(self, db: sqlite3.Connection, alarm_id: int, event: str, level: str, at_s: float, now: float) -> int:
        cur = db.execute(
            "INSERT INTO alarm_events (alarm_id, event, level, at_s, created_at) VALUES (?, ?, ?, ?, ?)",
            (alarm_id, event, level, at_s, now),
        )
        event_id = int(cur.lastrowid)
        notify = (event in ("raised", "escalated") and level in self.notify_levels) or (event == "cleared" and self.notify_cleared)
        if notify and self.notify_targets:
            alarm = AlarmDocument.model_validate(dict(db.execute(
                f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms WHERE id=?", (alarm_id,)).fetchone()))
            payload = AlarmEventDocument(id=f"shm-{self.instance}-{event_id}", event=event, level=level, at_s=at_s,
                                         alarm=alarm).model_dump_json()
            db.executemany(
                "INSERT OR IGNORE INTO outbox (event_id, channel, target, payload, status, next_attempt_at, created_at) "
                "VALUES (?, ?, ?, ?, 'pending', ?, ?)",
                [(event_id, channel, target, payload, now, now) for channel, target in self.notify_targets],
            )
        return event_id

    # -- queries --------------------------------------------------------------------------------

    def trends(self, *, from_s: float | None = None, to_s: float | None = None, mode: int | None = None,
               source: str | None = None, limit: int = 100_000) -> list[TrendRow]:
        where, args = [], []
        if from_s is not None:
            where.append("window_start_s >= ?")
            args.append(from_s)
        if to_s is not None:
            where.append("window_start_s < ?")
            args.append(to_s)
        if mode is not None:
            where.append("mode = ?")
            args.append(mode)
        if source is not None:
            where.append("source = ?")
            args.append(source)
        sql = f"SELECT {', '.join(TREND_COLUMNS)} FROM trends"
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY window_start_s, source, mode LIMIT ?"
        args.append(int(limit))
        with self._lock:
            rows = self._db.execute(sql, args).fetchall()
        return [TrendRow.model_validate(dict(r)) for r in rows]

    def delete_trends_older_than(self, age_s: float) -> int:
        """Delete the trend rows whose window starts more than ``age_s`` before the newest window of
        their source (data time: a replay of old data keeps its rows). Returns how many went."""
        if not (math.isfinite(age_s) and age_s > 0):
            raise ValueError(f"{age_s=} must be a positive number of seconds")
        with self.transaction() as db:
            cur = db.execute(
                "DELETE FROM trends WHERE window_start_s < "
                "(SELECT MAX(t.window_start_s) FROM trends AS t WHERE t.source = trends.source) - ?", (float(age_s),))
            return int(cur.rowcount)

    def count(self, table: str) -> int:
        if table not in ("trends", "alarms", "alarm_events", "outbox", "notification_log", "baselines"):
            raise ValueError(table)
        with self._lock:
            return int(self._db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0])

    def alarms(self, *, state: str | None = None, limit: int = 1000) -> list[AlarmDocument]:
        """Alarms, newest first (only those in ``state``: "active" or "cleared")."""
        with self._lock:
            if state is None:
                rows = self._db.execute(f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms ORDER BY id DESC LIMIT ?", (limit,))
            else:
                rows = self._db.execute(
                    f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms WHERE state=? ORDER BY id DESC LIMIT ?", (state, limit)
                )
            rows = rows.fetchall()
        return [AlarmDocument.model_validate(dict(r)) for r in rows]

    def alarm(self, alarm_id: int) -> AlarmDocument | None:
        with self._lock:
            row = self._db.execute(f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms WHERE id=?", (alarm_id,)).fetchone()
        return None if row is None else AlarmDocument.model_validate(dict(row))

    def acknowledge(self, alarm_id: int, by: str) -> AlarmDocument | None:
        """Acknowledge an alarm (idempotent: a second acknowledgement keeps the first)."""
        now = time.time()
        with self.transaction() as db:
            row = db.execute("SELECT * FROM alarms WHERE id=?", (alarm_id,)).fetchone()
            if row is None:
                return None
            if row["acknowledged_at_s"] is None:
                db.execute("UPDATE alarms SET acknowledged_at_s=?, acknowledged_by=? WHERE id=?", (now, by, alarm_id))
                db.execute(
                    "INSERT INTO alarm_events (alarm_id, event, level, at_s, created_at) VALUES (?, 'acknowledged', ?, ?, ?)",
                    (alarm_id, row["level"], now, now),
                )
        return self.alarm(alarm_id)

    def alarm_events(self) -> list[dict[str, Any]]:
        with self._lock:
            return [dict(r) for r in self._db.execute("SELECT * FROM alarm_events ORDER BY id").fetchall()]

    # -- outbox ---------------------------------------------------------------------------------

    def due_notifications(self, now: float, limit: int = 20) -> list[dict[str, Any]]:
        with self._lock:
            rows = self._db.execute(
                "SELECT * FROM outbox WHERE status='pending' AND next_attempt_at <= ? ORDER BY id LIMIT ?", (now, limit)
            ).fetchall()
        return [dict(r) for r in rows]

    def record_attempt(self, outbox_id: int, ok: bool, detail: str, *, next_attempt_at: float | None, give_up: bool) -> None:
        """Log one delivery attempt and, in the same transaction, mark the row sent, failed or due again."""
        now = time.time()
        with self.transaction() as db:
            row = db.execute("SELECT attempts FROM outbox WHERE id=?", (outbox_id,)).fetchone()
            attempt = int(row["attempts"]) + 1
            db.execute("INSERT INTO notification_log (outbox_id, attempt, at, ok, detail) VALUES (?, ?, ?, ?, ?)",
                       (outbox_id, attempt, now, int(ok), detail[:500]))
            if ok:
                db.execute("UPDATE outbox SET status='sent', attempts=?, sent_at=? WHERE id=?", (attempt, now, outbox_id))
            elif give_up:
                db.execute("UPDATE outbox SET status='failed', attempts=? WHERE id=?", (attempt, outbox_id))
            else:
                db.execute("UPDATE outbox SET attempts=?, next_attempt_at=? WHERE id=?", (attempt, next_attempt_at, outbox_id))

    def outbox(self) -> list[dict[str, Any]]:
        with self._lock:
            return [dict(r) for r in self._db.execute("SELECT * FROM outbox ORDER BY id").fetchall()]

    def notification_log(self) -> list[dict[str, Any]]:
        with self._lock:
            return [dict(r) for r in self._db.execute("SELECT * FROM notification_log ORDER BY id").fetchall()]

    def outbox_counts(self) -> dict[str, int]:
        with self._lock:
            rows = self._db.execute("SELECT status, COUNT(*) AS n FROM outbox GROUP BY status").fetchall()
        return {r["status"]: int(r["n"]) for r in rows}
