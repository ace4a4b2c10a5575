"""SQLite storage of the service (WAL): trends, baselines, monitor state, alarms, the
notification outbox and its attempt log. The schema is versioned (``PRAGMA user_version``) and
upgraded by the migrations below, in order, each in one transaction.

Everything that one analysis window produces (its trend rows, the monitor state after it, alarm
changes, alarm events and the outbox rows of their notifications) is written in ONE transaction
(``commit_window``), so a crash at any instant leaves either all of it or none of it.

Group commit: the windows that threads of one process hand to ``commit_window`` while a write is
under way are written together by one of those threads. A fleet's worker process thus takes the
database's write lock once for all its structures' windows of the moment, from one thread, and
not once per window from as many threads as it hosts structures.

The windows that change no alarm and store no baseline (nearly all) are staged in TEMP tables of
the writing connection first, which takes no lock of the database, and then moved in ONE
statement (a TEMP trigger on ``stage_flush``: trend rows, monitor states, the stale flags, all or
nothing). The write lock is then taken and released inside that one call into SQLite, with no
return to Python in between. Why: Python's sqlite3 gives up the GIL around every step of every
statement. Under a saturated CPU, a transaction of several statements waits for its process's GIL
after each one, behind every other runnable thread, while it holds the lock the other processes
wait for. Measured with 20 busy threads in the process: one such transaction of 19 windows held
the lock for 0.1 to 16 s; without the busy threads, for 2 ms. Windows that change alarms are
written in one transaction, each in a savepoint of its own, so a bad window is rolled back alone.

Durability: a transaction that writes alarms or the outbox is committed with
``synchronous = FULL`` (it survives a power loss, not only a crash of the process); trend rows
alone may use NORMAL (``sync``). Every alarm event has a UUID, so a notification's id
(``shm-{instance}-{uuid}``) never repeats for a different event, even after a power loss rolled
back the last AUTOINCREMENT ids.

Faults: transient errors (the database locked by another process, disk full, an I/O error) are
retried inside ``Storage`` with jittered exponential back-off for up to ``retry_s``; then
``StorageUnavailable`` is raised and nothing of the transaction is kept. Reads use a
connection of their own (WAL readers never wait for a writer), so a held write lock delays no
status query.
"""

from __future__ import annotations

import json
import logging
import math
import random
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from contract import AlarmDocument, Page, TrendRow

from ._store_alarms import AlarmChange, AlarmQuery, AlarmRepository, NotifyPolicy
from ._store_paging import decode_cursor, open_page
from ._store_trends import TREND_COLUMNS, TrendQuery, TrendRepository

__all__ = ["AlarmChange", "SCHEMA_VERSION", "Storage", "StorageUnavailable", "WindowCommit", "is_transient"]

log = logging.getLogger("shm.serve.storage")

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
)

SCHEMA_VERSION = len(_MIGRATIONS)

#: A window's monitor state row (then ``updated_at``), and how it replaces the stored one (a
#: window without a calibration keeps the stored calibration); written by a window's transaction
#: and by the plain windows' trigger alike.
_STATE_COLUMNS = ("source", "last_window_start_s", "data_time_s", "monitor", "calibration")
_STATE_UPSERT = ("ON CONFLICT(source) DO UPDATE SET last_window_start_s=excluded.last_window_start_s, "
                 "data_time_s=excluded.data_time_s, monitor=excluded.monitor, "
                 "calibration=COALESCE(excluded.calibration, monitor_state.calibration), updated_at=excluded.updated_at")


class StorageUnavailable(RuntimeError):
    """The database stayed locked or failing (disk full, I/O error) for the whole retry period."""


#: SQLite result codes that may pass: another connection holds a lock, the disk is full, an I/O
#: error (a disk being remounted, a network file system), the file cannot be opened for now.
_TRANSIENT = ("SQLITE_BUSY", "SQLITE_LOCKED", "SQLITE_FULL", "SQLITE_IOERR", "SQLITE_CANTOPEN", "SQLITE_PROTOCOL")


def is_transient(exc: BaseException) -> bool:
    """Whether an error of SQLite may pass when the transaction is tried again."""
    if isinstance(exc, StorageUnavailable):
        return True
    if not isinstance(exc, sqlite3.OperationalError):
        return False
    name = getattr(exc, "sqlite_errorname", "") or ""
    if name.startswith(_TRANSIENT):
        return True
    text = str(exc).lower()
    return "locked" in text or "disk is full" in text or "disk i/o" in text


def _conditions(pairs: Sequence[tuple[str, Any]]) -> tuple[list[str], list[Any]]:
    """The SQL conditions (and their arguments) of the pairs whose value is not None."""
    kept = [(sql, value) for sql, value in pairs if value is not None]
    return [sql for sql, _ in kept], [value for _, value in kept]


@dataclass(eq=False)
class _Ticket:
    """A window handed to the group commit: its statements, and what became of them."""

    run: Any  # fn(db) -> list[int], the window's statements
    durable: bool
    retry_s: float
    plain: tuple[list[tuple], tuple] | None = None  # (trend rows, monitor state row): no alarm, no baseline
    done: bool = False
    result: list[int] | None = None
    error: BaseException | None = None


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
    """The service's database. Thread-safe. Writes go through one connection under a lock, in
    short transactions retried on transient errors (``retry_s``, jittered exponential back-off
    from ``retry_initial_s``); reads through a second connection under a lock of its own (WAL: a
    reader sees the last committed state and never waits for a writer).

    ``sync`` is the synchronous mode of transactions that only write trend rows and state;
    ``alarm_sync`` that of transactions writing alarms, alarm events or the outbox."""

    def __init__(self, path: str | Path, *, notify_targets: Sequence[tuple[str, str]] = (),
                 notify_levels: Sequence[str] = ("warning", "alarm"), notify_cleared: bool = True, notify_stale: bool = True,
                 sync: str = "normal", alarm_sync: str = "full", retry_s: float = 10.0, retry_initial_s: float = 0.05,
                 busy_timeout_s: float = 0.5) -> None:
        for name, value in (("sync", sync), ("alarm_sync", alarm_sync)):
            if value not in ("normal", "full"):
                raise ValueError(f"{name}={value!r} must be 'normal' or 'full'")
        if not (retry_s >= 0 and retry_initial_s > 0 and busy_timeout_s >= 0):
            raise ValueError(f"{retry_s=}, {retry_initial_s=} and {busy_timeout_s=} must be >= 0 (retry_initial_s > 0)")
        self.path = Path(path)
        memory = str(path) == ":memory:"
        if not memory:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self.sync = sync.upper()
        self.alarm_sync = alarm_sync.upper()
        self.retry_s = float(retry_s)
        self.retry_initial_s = float(retry_initial_s)
        self.retries = 0  # transient errors retried since the start
        self.failures = 0  # transactions given up after retry_s
        self.last_error: str | None = None
        self._lock = threading.RLock()
        # the group commit of windows (see the module's docstring): those waiting, and whether a
        # thread is writing a group
        self._group = threading.Condition(threading.Lock())
        self._queued: list[_Ticket] = []
        self._leading = False
        self.groups = 0  # group transactions written
        self.grouped_windows = 0  # windows written in them
        self._busy_timeout_s = float(busy_timeout_s)
        self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None, timeout=busy_timeout_s)
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute(f"PRAGMA synchronous={self.sync}")
        self._db.execute("PRAGMA foreign_keys=ON")
        self._synchronous = self.sync
        self.notify_targets = tuple(notify_targets)
        self.notify_levels = tuple(notify_levels)
        self.notify_cleared = notify_cleared
        self.notify_stale = notify_stale
        self._call_with_retry(self.migrate)
        if memory:
            self._rdb, self._rlock = self._db, self._lock
        else:
            self._rdb = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None, timeout=busy_timeout_s)
            self._rdb.row_factory = sqlite3.Row
            self._rdb.execute("PRAGMA query_only=ON")
            self._rlock = threading.RLock()
        self._stage()
        self._instance = self._read(lambda db: str(db.execute("SELECT value FROM meta WHERE key='instance'").fetchone()[0]))
        self.policy = NotifyPolicy(self._instance, self.notify_targets, self.notify_levels, bool(notify_cleared),
                                   bool(notify_stale))

    def _stage(self) -> None:
        """The writing connection's TEMP tables and trigger of the plain windows (module docstring):
        staged rows are moved into the database's tables by one ``INSERT INTO stage_flush``."""
        cols = ", ".join(TREND_COLUMNS)
        state = ", ".join(_STATE_COLUMNS)
        with self._lock:
            self._db.execute("PRAGMA temp_store=MEMORY")
            self._db.execute(f"CREATE TEMP TABLE IF NOT EXISTS stage_trends ({cols})")
            self._db.execute(f"CREATE TEMP TABLE IF NOT EXISTS stage_state ({state})")
            self._db.execute("CREATE TEMP TABLE IF NOT EXISTS stage_flush (at REAL NOT NULL)")
            # Unqualified targets: a trigger may not name a schema; these tables exist in main only.
            self._db.execute(f"""
                CREATE TEMP TRIGGER IF NOT EXISTS stage_flush_windows AFTER INSERT ON stage_flush BEGIN
                    INSERT OR IGNORE INTO trends ({cols}, created_at) SELECT {cols}, NEW.at FROM stage_trends;
                    INSERT INTO monitor_state ({state}, updated_at) SELECT {state}, NEW.at FROM stage_state WHERE true
                        ORDER BY rowid {_STATE_UPSERT};
                    UPDATE alarms SET stale=0 WHERE stale=1 AND source IN (SELECT source FROM stage_state);
                    DELETE FROM stage_trends;
                    DELETE FROM stage_state;
                    DELETE FROM stage_flush;
                END""")

    # -- retries --------------------------------------------------------------------------------

    def _call_with_retry(self, fn: Any, retry_s: float | None = None) -> Any:
        """``fn()`` again after a transient error, with jittered exponential back-off (the
        lock is not held while waiting), until ``retry_s`` has passed."""
        budget = self.retry_s if retry_s is None else retry_s
        deadline = time.monotonic() + budget
        delay = self.retry_initial_s
        attempt = 0
        while True:
            try:
                return fn()
            except (sqlite3.OperationalError, sqlite3.DatabaseError) as exc:
                if not is_transient(exc):
                    raise
                attempt += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                now = time.monotonic()
                if now >= deadline:
                    self.failures += 1
                    raise StorageUnavailable(f"{self.path}: {exc} (still after {attempt} attempts in {budget:g} s)") from exc
                self.retries += 1
                if attempt == 1 or attempt % 20 == 0:
                    log.warning("%s: %s; retrying (attempt %d)", self.path, exc, attempt)
                # full jitter: many writers retrying do not retry in step
                time.sleep(min(random.uniform(0.5, 1.0) * delay, max(deadline - now, 0.0)))
                delay = min(delay * 2, 2.0)

    def _read(self, fn: Any) -> Any:
        def attempt() -> Any:
            with self._rlock:
                return fn(self._rdb)
        return self._call_with_retry(attempt)

    def _use_synchronous(self, wanted: str) -> None:
        """The writing connection's synchronous mode for its next transaction (between
        transactions only; the caller holds ``_lock``)."""
        if wanted != self._synchronous:
            self._db.execute(f"PRAGMA synchronous={wanted}")
            self._synchronous = wanted

    def _write(self, fn: Any, *, durable: bool = False, retry_s: float | None = None) -> Any:
        """Run ``fn(db)`` in one IMMEDIATE transaction (``durable``: synchronous = alarm_sync),
        retried as a whole on transient errors. A failed COMMIT is rolled back, so the
        connection is never left inside a transaction."""

        def attempt() -> Any:
            with self._lock:
                self._use_synchronous(self.alarm_sync if durable else self.sync)
                self._db.execute("BEGIN IMMEDIATE")
                try:
                    result = fn(self._db)
                    self._db.execute("COMMIT")
                except BaseException:
                    if self._db.in_transaction:
                        try:
                            self._db.execute("ROLLBACK")
                        except sqlite3.Error:  # the rollback itself failed: SQLite rolled back already
                            pass
                    raise
                return result

        return self._call_with_retry(attempt, retry_s)

    # -- schema ---------------------------------------------------------------------------------

    @property
    def schema_version(self) -> int:
        """The schema's version, read on the reading connection: a status query never waits for
        the writers' lock (a fleet's status asks it once per structure)."""
        return int(self._read(lambda db: db.execute("PRAGMA user_version").fetchone()[0]))

    def migrate(self) -> None:
        """Bring the schema to ``SCHEMA_VERSION``; refuses a database of a newer version."""
        with self._lock:
            version = int(self._db.execute("PRAGMA user_version").fetchone()[0])
            if version > SCHEMA_VERSION:
                raise RuntimeError(f"{self.path}: schema version {version} is newer than this program's {SCHEMA_VERSION}")
            if version == SCHEMA_VERSION:
                return
            # A migration may rebuild a table others refer to: foreign keys are checked once at the end.
            self._db.execute("PRAGMA foreign_keys=OFF")
            try:
                for number in range(version + 1, SCHEMA_VERSION + 1):
                    script = _MIGRATIONS[number - 1]
                    self._db.execute("BEGIN IMMEDIATE")
                    try:
                        for statement in (s.strip() for s in script.split(";")):
                            if statement:
                                self._db.execute(statement)
                        problems = self._db.execute("PRAGMA foreign_key_check").fetchall()
                        if problems:
                            raise RuntimeError(f"{self.path}: migration {number} breaks foreign keys: {[tuple(p) for p in problems][:5]}")
                        self._db.execute(f"PRAGMA user_version = {number}")
                        self._db.execute("COMMIT")
                    except BaseException:
                        if self._db.in_transaction:
                            self._db.execute("ROLLBACK")
                        raise
            finally:
                self._db.execute("PRAGMA foreign_keys=ON")

    @contextmanager
    def transaction(self, *, durable: bool = False) -> Iterator[sqlite3.Connection]:
        """One write transaction (not retried: for callers that do their own)."""
        with self._lock:
            self._use_synchronous(self.alarm_sync if durable else self.sync)
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
                self._db.execute("COMMIT")
            except BaseException:
                if self._db.in_transaction:
                    self._db.execute("ROLLBACK")
                raise

    def close(self) -> None:
        with self._lock:
            self._db.close()
        if self._rdb is not self._db:
            with self._rlock:
                self._rdb.close()

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check``: "ok" or the problems found."""
        return "; ".join(str(r[0]) for r in self._read(lambda db: db.execute("PRAGMA integrity_check").fetchall()))

    @property
    def instance(self) -> str:
        """A random id of this database (keys of notifications: unique across databases)."""
        return self._instance

    # -- sources and state ----------------------------------------------------------------------

    def touch_source(self, source: str, kind: str, detail: str, seen_at: float) -> None:
        """Record that ``source`` delivered data at ``seen_at`` (UNIX s, wall clock)."""
        self.touch_sources([(source, kind, detail)], seen_at)

    def touch_sources(self, sources: Sequence[tuple[str, str, str]], seen_at: float) -> None:
        """``touch_source`` of several (source, kind, detail) in one transaction (a fleet's
        housekeeping: one write for all its structures, not one each taking the database's lock)."""
        if not sources:
            return
        # One statement of many rows, outside a transaction: the write lock is taken and released
        # inside one call into SQLite (an executemany would wait for the GIL after every row
        # while holding it; see the module's docstring). Chunks keep within SQLite's variables.
        rows = [(source, kind, detail, seen_at, seen_at) for source, kind, detail in sources]
        for start in range(0, len(rows), 1000):
            chunk = rows[start:start + 1000]

            def attempt(chunk: list[tuple] = chunk) -> None:
                with self._lock:
                    self._db.execute(
                        "INSERT INTO sources (id, kind, detail, first_seen_s, last_seen_s) VALUES "
                        + ", ".join(["(?, ?, ?, ?, ?)"] * len(chunk))
                        + " ON CONFLICT(id) DO UPDATE SET kind=excluded.kind, detail=excluded.detail, "
                        "last_seen_s=excluded.last_seen_s",
                        [value for row in chunk for value in row],
                    )
            self._call_with_retry(attempt)

    def load_state(self, source: str) -> dict[str, Any] | None:
        row = self._read(lambda db: db.execute("SELECT * FROM monitor_state WHERE source = ?", (source,)).fetchone())
        if row is None:
            return None
        return {
            "last_window_start_s": row["last_window_start_s"],
            "data_time_s": row["data_time_s"],
            "monitor": None if row["monitor"] is None else json.loads(row["monitor"]),
            "calibration": None if row["calibration"] is None else json.loads(row["calibration"]),
        }

    def save_calibration(self, source: str, calibration: dict) -> None:
        def run(db: sqlite3.Connection) -> None:
            db.execute(
                "INSERT INTO monitor_state (source, calibration, updated_at) VALUES (?, ?, ?) "
                "ON CONFLICT(source) DO UPDATE SET calibration=excluded.calibration, updated_at=excluded.updated_at",
                (source, json.dumps(calibration), time.time()),
            )
        self._write(run)

    # -- baselines ------------------------------------------------------------------------------

    def request_baseline(self, source: str, *, retry_s: float | None = None) -> int:
        """Supersede the active baseline; a new one is learnt (state 'learning'). Returns its id."""
        def run(db: sqlite3.Connection) -> int:
            db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
            cur = db.execute(
                "INSERT INTO baselines (source, state, requested_at) VALUES (?, 'learning', ?)", (source, time.time())
            )
            # The monitor starts over: its stored state no longer applies.
            db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
            return int(cur.lastrowid)
        return self._write(run, retry_s=retry_s)

    def baselines(self, source: str | None = None) -> list[dict[str, Any]]:
        def run(db: sqlite3.Connection) -> list:
            if source is None:
                return db.execute("SELECT * FROM baselines ORDER BY id DESC").fetchall()
            return db.execute("SELECT * FROM baselines WHERE source=? ORDER BY id DESC", (source,)).fetchall()
        out = []
        for r in self._read(run):
            d = dict(r)
            d["data"] = None if d["data"] is None else json.loads(d["data"])
            out.append(d)
        return out

    def store_baseline(self, source: str, baseline: dict) -> int:
        """Store ``baseline`` (``analytics.Baseline.to_dict()``) as the active baseline of
        ``source`` (the previous one superseded); the stored monitor state of the source is
        dropped so that the service starts its monitor from this baseline. Returns its id."""
        now = time.time()

        def run(db: sqlite3.Connection) -> int:
            db.execute("UPDATE baselines SET state='superseded' WHERE source=? AND state IN ('active', 'learning')", (source,))
            cur = db.execute(
                "INSERT INTO baselines (source, state, requested_at, learnt_at, start_s, end_s, data) "
                "VALUES (?, 'active', ?, ?, ?, ?, ?)",
                (source, now, now, baseline.get("start_s"), baseline.get("end_s"), json.dumps(baseline)),
            )
            db.execute("UPDATE monitor_state SET monitor=NULL WHERE source=?", (source,))
            return int(cur.lastrowid)

        return self._write(run, durable=True)

    def active_baseline(self, source: str) -> dict | None:
        """The data of the active baseline of ``source``, or None."""
        def run(db: sqlite3.Connection):
            return db.execute(
                "SELECT data FROM baselines WHERE source=? AND state='active' AND data IS NOT NULL ORDER BY id DESC LIMIT 1",
                (source,)).fetchone()

        row = self._read(run)
        return None if row is None else json.loads(row["data"])

    # -- reprocessed recordings ---------------------------------------------------------------

    def reprocessed(self, keys: Sequence[str]) -> set[str]:
        """Which of ``keys`` are done (committed by ``commit_reprocessed``)."""
        def run(db: sqlite3.Connection) -> set[str]:
            return {r["key"] for r in db.execute(
                f"SELECT key FROM reprocessed WHERE key IN ({', '.join('?' * len(keys))})", tuple(keys)).fetchall()}

        return self._read(run)

    def commit_reprocessed(self, *, key: str, path: str, source: str, content_sha256: str, configuration: str,
                           windows: int, start_s: float | None, end_s: float | None, rows: list[TrendRow]) -> None:
        """A reprocessed recording's trend rows (replacing those of the same windows) and its
        ledger row, in one transaction: after a kill a file is either done or not started."""
        now = time.time()
        for r in rows:
            if r.source != source:
                raise ValueError(f"trend row of source {r.source!r} for source {source!r}")

        def run(db: sqlite3.Connection) -> None:
            TrendRepository(db).insert([tuple(getattr(r, c) for c in TREND_COLUMNS) for r in rows], now, replace=True)
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

        self._write(run)

    # -- windows --------------------------------------------------------------------------------

    def commit_window(self, commit: WindowCommit, *, retry_s: float | None = None) -> list[int]:
        """Write a window's rows, state, alarm changes and their outbox rows in one transaction
        (durable when it changes an alarm), retried on transient errors. Rows of a window already
        stored are ignored (replaying the same period). Returns the ids of the alarm events
        written. Raises ``StorageUnavailable`` when it could not be written within ``retry_s``:
        then nothing of it was."""
        for r in commit.rows:
            if r.source != commit.source:
                raise ValueError(f"trend row of source {r.source!r} in a commit of source {commit.source!r}")

        # What needs no database is made before the transaction: the write lock, which the other
        # processes of a fleet wait for, is held for the statements only.
        rows = [tuple(getattr(r, c) for c in TREND_COLUMNS) for r in commit.rows]
        monitor = None if commit.monitor_state is None else json.dumps(commit.monitor_state)
        calibration = None if commit.calibration is None else json.dumps(commit.calibration)
        state = (commit.source, commit.window_start_s, commit.data_time_s, monitor, calibration)  # _STATE_COLUMNS

        def run(db: sqlite3.Connection) -> list[int]:
            now = time.time()
            events: list[int] = []
            TrendRepository(db).insert(rows, now)
            db.execute(f"INSERT INTO monitor_state ({', '.join(_STATE_COLUMNS)}, updated_at) "
                       f"VALUES ({', '.join('?' * (len(_STATE_COLUMNS) + 1))}) {_STATE_UPSERT}", (*state, now))
            alarms = AlarmRepository(db, self.policy)
            alarms.clear_stale([commit.source])  # the source is judged again: its alarms are no longer stale
            if commit.baseline is not None:
                self._store_baseline(db, commit.source, commit.baseline, now)
            for change in commit.alarm_changes:
                event = alarms.apply(commit.source, change, now)
                if event is not None:
                    events.append(event)
            return events

        plain = None
        if not commit.alarm_changes and commit.baseline is None:
            plain = (rows, state)
        return self._group_commit(_Ticket(run, bool(commit.alarm_changes), self.retry_s if retry_s is None else float(retry_s),
                                          plain))

    #: the most windows written in one group transaction (a bound on how long the lock is held)
    MAX_GROUP = 64

    def _group_commit(self, ticket: _Ticket) -> list[int]:
        """Write ``ticket`` with the others waiting: the first thread to find no group under way
        writes everything queued meanwhile (and what queues while it writes, until its own window
        is written); the others wait for it."""
        with self._group:
            self._queued.append(ticket)
            while not ticket.done and self._leading:
                self._group.wait()
            leader = not ticket.done
            if leader:
                self._leading = True
        if leader:
            try:
                while not ticket.done:
                    with self._group:
                        batch, self._queued = self._queued[:self.MAX_GROUP], self._queued[self.MAX_GROUP:]
                    if not batch:
                        raise RuntimeError("group commit: a window is neither queued nor written")
                    self._write_group(batch)
                    with self._group:
                        self._group.notify_all()
            finally:
                with self._group:
                    self._leading = False  # a waiting thread writes the next group
                    self._group.notify_all()
        if ticket.error is not None:
            raise ticket.error
        assert ticket.result is not None
        return ticket.result

    def _write_group(self, batch: list[_Ticket]) -> None:
        """The plain windows of ``batch`` in one statement (``_write_plain``), the others in one
        transaction of savepoints (``_write_savepoints``)."""
        try:
            plain = [t for t in batch if t.plain is not None]
            if plain and self._write_plain(plain):
                self._write_savepoints([t for t in batch if t.plain is None])
            else:  # none plain, or a bad window among them: each in its savepoint, to find it
                self._write_savepoints(batch)
        except BaseException as exc:  # never leave a window of the group waiting for nobody
            for t in batch:
                if not t.done:
                    t.result, t.error, t.done = None, exc, True
            raise

    def _write_plain(self, batch: list[_Ticket]) -> bool:
        """Stage the windows (no lock taken) and move them with one statement; a passing fault
        is retried, for the longest retry time of the group. False when the move failed for good
        (nothing of it kept, the windows untouched): the caller writes them one by one."""
        trends = [row for t in batch for row in t.plain[0]]
        states = [t.plain[1] for t in batch]
        columns = len(TREND_COLUMNS)

        def attempt() -> None:
            with self._lock:
                db = self._db
                self._use_synchronous(self.sync)
                db.execute("DELETE FROM stage_trends")  # what a failed attempt staged
                db.execute("DELETE FROM stage_state")
                db.executemany(f"INSERT INTO stage_trends VALUES ({', '.join('?' * columns)})", trends)
                db.executemany(f"INSERT INTO stage_state VALUES ({', '.join('?' * len(_STATE_COLUMNS))})", states)
                db.execute("INSERT INTO stage_flush (at) VALUES (?)", (time.time(),))

        try:
            self._call_with_retry(attempt, max(t.retry_s for t in batch))
        except StorageUnavailable as exc:
            for t in batch:
                t.result, t.error, t.done = None, exc, True
            return True
        except sqlite3.Error:
            return False
        self.groups += 1
        self.grouped_windows += len(batch)
        for t in batch:
            t.result, t.error, t.done = [], None, True
        return True

    def _write_savepoints(self, batch: list[_Ticket]) -> None:
        """One transaction for the windows of ``batch``, each in a savepoint: a window whose
        statements fail for good (not a passing fault) is rolled back alone and gets the error;
        a passing fault retries the whole group; when it outlasts the retry time (the longest of
        the group's), every window of the group gets ``StorageUnavailable`` and none is kept."""

        def run(db: sqlite3.Connection) -> None:
            for t in batch:
                t.result, t.error = None, None
            for t in batch:
                db.execute("SAVEPOINT window")
                try:
                    t.result = t.run(db)
                except Exception as exc:
                    if is_transient(exc):
                        raise
                    db.execute("ROLLBACK TO window")
                    t.error = exc
                db.execute("RELEASE window")

        try:
            if batch:
                self._write(run, durable=any(t.durable for t in batch), retry_s=max(t.retry_s for t in batch))
                self.groups += 1
                self.grouped_windows += len(batch)
        except BaseException as exc:
            for t in batch:
                t.result, t.error = None, exc
            if not isinstance(exc, Exception):
                raise
        finally:
            for t in batch:
                t.done = True

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

    # -- re-notification and stale alarms --------------------------------------------------------

    def renotify_due(self, interval_s: float, now: float | None = None) -> list[int]:
        """A 'repeated' event (notified) for every active, non-stale alarm whose last notified
        event (raised, escalated, repeated) is ``interval_s`` old. Returns the new event ids."""
        if not (math.isfinite(interval_s) and interval_s > 0):
            raise ValueError(f"{interval_s=} must be a positive number of seconds")
        at = time.time() if now is None else now
        if not self._read(lambda db: AlarmRepository(db).due_for_repeat(at - interval_s)):
            return []

        def run(db: sqlite3.Connection) -> list[int]:
            alarms = AlarmRepository(db, self.policy)
            return [alarms.event(i, "repeated", level, at, at) for i, level in alarms.due_for_repeat(at - interval_s)]

        return self._write(run, durable=True)

    def mark_stale(self, silent_since: float, now: float | None = None) -> list[int]:
        """Mark stale the active alarms of every source not seen since ``silent_since`` (UNIX s,
        wall clock; ``sources.last_seen_s``), with a 'stale' event each. Returns the alarm ids."""
        at = time.time() if now is None else now
        if not self._read(lambda db: AlarmRepository(db).silent(silent_since)):
            return []

        def run(db: sqlite3.Connection) -> list[int]:
            alarms = AlarmRepository(db, self.policy)
            found = alarms.silent(silent_since)
            for alarm_id, level in found:
                alarms.mark_stale(alarm_id)
                alarms.event(alarm_id, "stale", level, at, at)
            return [alarm_id for alarm_id, _ in found]

        return self._write(run, durable=True)

    # -- queries --------------------------------------------------------------------------------

    def trends(self, *, from_s: float | None = None, to_s: float | None = None, mode: int | None = None,
               source: str | None = None, limit: int = 100_000) -> list[TrendRow]:
        query = TrendQuery(from_s, to_s, mode, source)
        return self._read(lambda db: TrendRepository(db).query(query, limit))

    def trends_page(self, *, from_s: float | None = None, to_s: float | None = None, mode: int | None = None,
                    source: str | None = None, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        """A page of trend rows after ``cursor`` (``_store_paging``: counted in one snapshot, streamed)."""
        after = decode_cursor(TrendRepository.name, cursor, TrendRepository.key_types)
        return self._page(TrendRepository, TrendQuery(from_s, to_s, mode, source), limit=limit, after=after)

    def alarms_page(self, *, state: str | None = None, source: str | None = None, limit: int = 1000,
                    cursor: str | None = None) -> Page[AlarmDocument]:
        """A page of alarms, newest first, after ``cursor``."""
        after = decode_cursor(AlarmRepository.name, cursor, AlarmRepository.key_types)
        return self._page(AlarmRepository, AlarmQuery(state, source), limit=limit, after=after)

    def _page(self, repository: Callable[[sqlite3.Connection], Any], query: Any, *, limit: int,
              after: tuple | None) -> Page[Any]:
        if self._rdb is self._db:  # in memory (tests): no second connection sees it; read at once
            def whole(db: sqlite3.Connection) -> Page[Any]:
                page = open_page(lambda: (db, lambda: None), repository(db), query, limit=limit, after=after)
                page.items = iter(list(page.items))
                return page

            return self._read(whole)

        def attempt() -> Page[Any]:
            # a reading connection of its own for the page (WAL: its read transaction is a
            # snapshot no writer waits for), closed when the page is read or closed
            db = sqlite3.connect(str(self.path), check_same_thread=False, isolation_level=None, timeout=self._busy_timeout_s)
            db.execute("PRAGMA query_only=ON")
            return open_page(lambda: (db, db.close), repository(db), query, limit=limit, after=after)

        return self._call_with_retry(attempt)

    def delete_trends_older_than(self, age_s: float) -> int:
        """Delete the trend rows whose window starts more than ``age_s`` before the newest window of
        their source (data time: a replay of old data keeps its rows). Returns how many went."""
        if not (math.isfinite(age_s) and age_s > 0):
            raise ValueError(f"{age_s=} must be a positive number of seconds")
        return self._write(lambda db: TrendRepository(db).delete_older_than(age_s))

    def count(self, table: str) -> int:
        if table not in ("trends", "alarms", "alarm_events", "outbox", "notification_log", "baselines"):
            raise ValueError(f"{table=} is not a table of the service's database")
        return int(self._read(lambda db: db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]))

    def alarms(self, *, state: str | None = None, limit: int = 1000, source: str | None = None) -> list[AlarmDocument]:
        """Alarms, newest first (only those in ``state``: "active" or "cleared"; only those of
        ``source`` when given)."""
        query = AlarmQuery(state, source)
        return self._read(lambda db: AlarmRepository(db).list(query, limit))

    def alarm(self, alarm_id: int) -> AlarmDocument | None:
        return self._read(lambda db: AlarmRepository(db).get(alarm_id))

    def acknowledge(self, alarm_id: int, by: str, *, retry_s: float | None = None) -> AlarmDocument | None:
        """Acknowledge an alarm (idempotent: a second acknowledgement keeps the first)."""
        if not self._write(lambda db: AlarmRepository(db, self.policy).acknowledge(alarm_id, by, time.time()), durable=True,
                           retry_s=retry_s):
            return None
        return self.alarm(alarm_id)

    def alarm_events(self) -> list[dict[str, Any]]:
        return self._read(lambda db: AlarmRepository(db).events())

    # -- outbox ---------------------------------------------------------------------------------

    def due_notifications(self, now: float, limit: int = 20, *, channel: str | None = None,
                          target: str | None = None) -> list[dict[str, Any]]:
        """Pending rows due at ``now``, oldest first; of one target when given. A row waits while
        an earlier row of the same alarm and target is still pending: each target gets an alarm's
        events in their order, whatever their retries."""
        where, args = _conditions([("o.next_attempt_at <= ?", now), ("o.channel = ?", channel), ("o.target = ?", target)])
        where.insert(0, "o.status='pending'")
        sql = (f"SELECT o.* FROM outbox AS o WHERE {' AND '.join(where)} AND NOT EXISTS (SELECT 1 FROM outbox AS p "
               "WHERE p.status='pending' AND p.channel=o.channel AND p.target=o.target AND p.alarm_id IS o.alarm_id "
               "AND p.id < o.id) ORDER BY o.id LIMIT ?")
        args.append(limit)
        return [dict(r) for r in self._read(lambda db: db.execute(sql, args).fetchall())]

    def next_due(self, *, channel: str, target: str) -> float | None:
        """When the earliest pending row of a target is due (UNIX s), None when there is none."""
        row = self._read(lambda db: db.execute(
            "SELECT MIN(next_attempt_at) FROM outbox WHERE status='pending' AND channel=? AND target=?",
            (channel, target)).fetchone())
        return None if row[0] is None else float(row[0])

    def pending_targets(self) -> list[tuple[str, str]]:
        """(channel, target) of every pending row."""
        rows = self._read(lambda db: db.execute(
            "SELECT DISTINCT channel, target FROM outbox WHERE status='pending' ORDER BY channel, target").fetchall())
        return [(r["channel"], r["target"]) for r in rows]

    def record_attempt(self, outbox_id: int, ok: bool, detail: str, *, next_attempt_at: float | None, give_up: bool,
                       permanent: bool = False) -> None:
        """Log one delivery attempt and, in the same transaction, mark the row sent, failed
        (``give_up``; ``permanent``: the target refused it for good) or due again."""

        def run(db: sqlite3.Connection) -> None:
            now = time.time()
            row = db.execute("SELECT attempts FROM outbox WHERE id=?", (outbox_id,)).fetchone()
            if row is None:
                raise KeyError(f"outbox row {outbox_id} does not exist")
            attempt = int(row["attempts"]) + 1
            db.execute("INSERT INTO notification_log (outbox_id, attempt, at, ok, detail) VALUES (?, ?, ?, ?, ?)",
                       (outbox_id, attempt, now, int(ok), detail[:500]))
            if ok:
                db.execute("UPDATE outbox SET status='sent', attempts=?, sent_at=?, last_error=NULL WHERE id=?",
                           (attempt, now, outbox_id))
            elif give_up:
                db.execute("UPDATE outbox SET status='failed', attempts=?, last_error=?, permanent=? WHERE id=?",
                           (attempt, detail[:500], int(permanent), outbox_id))
            else:
                db.execute("UPDATE outbox SET attempts=?, next_attempt_at=?, last_error=? WHERE id=?",
                           (attempt, next_attempt_at, detail[:500], outbox_id))

        self._write(run, durable=True)

    def fail_pending(self, channel: str, target: str, detail: str) -> int:
        """Mark failed (for good) every pending row of a target no longer configured."""
        def run(db: sqlite3.Connection) -> int:
            cur = db.execute("UPDATE outbox SET status='failed', last_error=?, permanent=1 WHERE status='pending' "
                             "AND channel=? AND target=?", (detail[:500], channel, target))
            return int(cur.rowcount)
        return self._write(run, durable=True)

    def outbox(self) -> list[dict[str, Any]]:
        return [dict(r) for r in self._read(lambda db: db.execute("SELECT * FROM outbox ORDER BY id").fetchall())]

    def notification_log(self) -> list[dict[str, Any]]:
        return [dict(r) for r in self._read(lambda db: db.execute("SELECT * FROM notification_log ORDER BY id").fetchall())]

    def outbox_counts(self) -> dict[str, int]:
        rows = self._read(lambda db: db.execute("SELECT status, COUNT(*) AS n FROM outbox GROUP BY status").fetchall())
        return {r["status"]: int(r["n"]) for r in rows}
