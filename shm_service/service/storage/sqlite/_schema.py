"""The schema of the service's database, versioned (``PRAGMA user_version``) and upgraded by
the migrations below, in order, each in one transaction."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from .._fatigue import FATIGUE_SCHEMA

__all__ = ["SCHEMA_VERSION", "migrate"]

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
    # 3: events with a per-alarm sequence number and a UUID (notification ids that cannot repeat),
    # re-notifications ('repeated') and stale alarms; the outbox knows its alarm (in-order
    # delivery per alarm and target) and its last error. alarm_events is rebuilt (its CHECK
    # grows), the documented way: new table, copy, drop, rename (foreign keys off meanwhile).
    """
    ALTER TABLE alarms ADD COLUMN stale INTEGER NOT NULL DEFAULT 0;
    CREATE TABLE alarm_events_new (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        alarm_id INTEGER NOT NULL REFERENCES alarms(id),
        seq INTEGER NOT NULL,
        uuid TEXT NOT NULL UNIQUE,
        event TEXT NOT NULL CHECK (event IN ('raised', 'escalated', 'cleared', 'acknowledged', 'repeated', 'stale')),
        level TEXT NOT NULL,
        at_s REAL NOT NULL,
        created_at REAL NOT NULL,
        UNIQUE (alarm_id, seq)
    );
    INSERT INTO alarm_events_new (id, alarm_id, seq, uuid, event, level, at_s, created_at)
        SELECT e.id, e.alarm_id, (SELECT COUNT(*) FROM alarm_events AS p WHERE p.alarm_id = e.alarm_id AND p.id <= e.id),
               lower(hex(randomblob(16))), e.event, e.level, e.at_s, e.created_at FROM alarm_events AS e;
    DROP TABLE alarm_events;
    ALTER TABLE alarm_events_new RENAME TO alarm_events;
    CREATE INDEX alarm_events_alarm ON alarm_events (alarm_id, seq);
    ALTER TABLE outbox ADD COLUMN alarm_id INTEGER;
    ALTER TABLE outbox ADD COLUMN last_error TEXT;
    ALTER TABLE outbox ADD COLUMN permanent INTEGER NOT NULL DEFAULT 0;
    UPDATE outbox SET alarm_id = (SELECT alarm_id FROM alarm_events WHERE alarm_events.id = outbox.event_id);
    CREATE INDEX outbox_order ON outbox (channel, target, alarm_id, status, id);
    """,
    # 4: recordings reprocessed into the trends (shm reprocess): a file is done once its row is
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
    # 5: the hot spots' loads and life per window
    FATIGUE_SCHEMA,
    # 6: the bending plane of each trend row (a biaxial beam's ζ and ξ modes): part of the key, so
    # the table is rebuilt (new table, copy, drop, rename); the rows stored before are the ζ plane's
    """
    CREATE TABLE trends_new (
        source TEXT NOT NULL,
        window_start_s REAL NOT NULL,
        window_end_s REAL NOT NULL,
        mode INTEGER NOT NULL,
        -- beside the key's other columns: SQLite 3.40's integrity_check misreads a WITHOUT ROWID
        -- row whose key column follows columns outside the key (it reports NOT NULL columns as NULL)
        plane TEXT NOT NULL DEFAULT 'zeta' CHECK (plane IN ('zeta', 'xi')),
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
        PRIMARY KEY (source, window_start_s, mode, plane)
    ) WITHOUT ROWID;
    INSERT INTO trends_new (source, window_start_s, window_end_s, mode, unit, kind, frequency_hz, damping_ratio, amplitude,
                            confidence, temperature_c, curvature_index, score_sigma, level, created_at, plane)
        SELECT source, window_start_s, window_end_s, mode, unit, kind, frequency_hz, damping_ratio, amplitude,
               confidence, temperature_c, curvature_index, score_sigma, level, created_at, 'zeta' FROM trends;
    DROP TABLE trends;
    ALTER TABLE trends_new RENAME TO trends;
    CREATE INDEX trends_time ON trends (window_start_s);
    """,
)

SCHEMA_VERSION = len(_MIGRATIONS)


def migrate(db: sqlite3.Connection, path: str | Path) -> None:
    """Bring the schema of ``db`` (the file ``path``, for messages) to ``SCHEMA_VERSION``; refuses
    a database of a newer version. A migration may rebuild a table others refer to: foreign keys
    are checked once at the end of each."""
    version = int(db.execute("PRAGMA user_version").fetchone()[0])
    if version > SCHEMA_VERSION:
        raise RuntimeError(f"{path}: schema version {version} is newer than this program's {SCHEMA_VERSION}")
    if version == SCHEMA_VERSION:
        return
    db.execute("PRAGMA foreign_keys=OFF")
    try:
        for number in range(version + 1, SCHEMA_VERSION + 1):
            db.execute("BEGIN IMMEDIATE")
            try:
                for statement in (s.strip() for s in _MIGRATIONS[number - 1].split(";")):
                    if statement:
                        db.execute(statement)
                problems = db.execute("PRAGMA foreign_key_check").fetchall()
                if problems:
                    raise RuntimeError(f"{path}: migration {number} breaks foreign keys: {[tuple(p) for p in problems][:5]}")
                db.execute(f"PRAGMA user_version = {number}")
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
    finally:
        db.execute("PRAGMA foreign_keys=ON")
