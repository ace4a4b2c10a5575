"""Storage of the service: trends, baselines, monitor state, alarms, the notification outbox
and its attempt log, and the ledger of reprocessed recordings, in a SQLite file (WAL; the
default) or a PostgreSQL database (``path`` a ``postgresql://`` URL: ``storage.postgres``, the
same repositories and transactions; a fleet's nodes share it).

``Storage`` is a thin facade: each method is one transaction (or one read) over the repositories,
each a class over a connection behind a Protocol that a second backend could implement:

- ``storage._trends.TrendRepository`` (``TrendStore``): the trend rows;
- ``storage._alarms.AlarmRepository`` (``AlarmStore``): alarms, their events and the outbox rows
  they fill; ``storage._outbox.OutboxRepository`` (``OutboxStore``): the outbox's delivery side;
- ``storage._state.StateRepository`` (``StateStore``): sources, monitor state, baselines;
- ``storage._ledger.ReprocessLedger`` (``ReprocessStore``): the reprocessed recordings.

The database itself (connections, transactions, the retry of passing faults) is
``storage.sqlite._db.Database``; its schema and migrations ``storage.sqlite._schema``; the commit of a window (one
transaction over trends, state and alarms; group commit) ``storage._commit.WindowWriter``; the
paging of lists (one snapshot, a keyset cursor, streamed rows) ``storage._paging``.

Durability: a transaction that writes alarms or the outbox is committed with
``synchronous = FULL`` (it survives a power loss, not only a crash of the process); trend rows
alone may use NORMAL (``sync``). Every alarm event has a UUID, so a notification's id
(``shm-{instance}-{uuid}``) never repeats for a different event, even after a power loss rolled
back the last AUTOINCREMENT ids.
"""

from __future__ import annotations

import math
import sqlite3
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from contract import AlarmDocument, LoadsWindowDocument, Page, TrendRow

from ._alarms import AlarmChange, AlarmQuery, AlarmRepository, NotifyPolicy
from ._commit import WindowCommit, WindowWriter
from .sqlite._db import Database, StorageUnavailable, is_transient
from ._fatigue import FatigueRepository
from ._ledger import ReprocessLedger
from ._outbox import OutboxRepository
from ._paging import decode_cursor, open_page
from .sqlite._schema import SCHEMA_VERSION
from ._state import StateRepository
from ._trends import TREND_COLUMNS, TrendQuery, TrendRepository
from ._url import is_postgres_url, redact

__all__ = ["AlarmChange", "SCHEMA_VERSION", "Storage", "StorageUnavailable", "WindowCommit", "is_transient"]

T = TypeVar("T")


def _open_database(target: str | Path, **kwargs: Any) -> Any:
    """The engine ``target`` names: a ``postgresql://`` URL (``storage.postgres``, whose client is
    imported only then: it is an optional dependency), else a SQLite file (or ``:memory:``)."""
    if is_postgres_url(target):
        try:
            from .postgres._db import PgDatabase
        except ImportError as exc:
            raise RuntimeError(f"storage url {redact(str(target))!r} needs PostgreSQL's client psycopg 3, which is not "
                               f"installed ({exc}): pip install 'psycopg[binary]' (the package's 'cluster' extra)") from None
        return PgDatabase(str(target), **kwargs)
    return Database(target, **kwargs)


class Storage:
    """The service's database (see the module's docstring). Thread-safe. Writes go through one
    connection under a lock, in short transactions retried on transient errors (``retry_s``,
    jittered exponential back-off from ``retry_initial_s``); reads through a second connection
    (WAL: a reader sees the last committed state and never waits for a writer).

    ``sync`` is the synchronous mode of transactions that only write trend rows and state;
    ``alarm_sync`` that of transactions writing alarms, alarm events or the outbox."""

    def __init__(self, path: str | Path, *, notify_targets: Sequence[tuple[str, str]] = (),
                 notify_levels: Sequence[str] = ("warning", "alarm"), notify_cleared: bool = True, notify_stale: bool = True,
                 sync: str = "normal", alarm_sync: str = "full", retry_s: float = 10.0, retry_initial_s: float = 0.05,
                 busy_timeout_s: float = 0.5) -> None:
        self.database = _open_database(path, sync=sync, alarm_sync=alarm_sync, retry_s=retry_s,
                                       retry_initial_s=retry_initial_s, busy_timeout_s=busy_timeout_s)
        self.path = self.database.path
        self._instance = self._read(lambda db: str(db.execute("SELECT value FROM meta WHERE key='instance'").fetchone()[0]))
        self.policy = NotifyPolicy(self._instance, tuple(notify_targets), tuple(notify_levels), bool(notify_cleared),
                                   bool(notify_stale))
        self.windows = WindowWriter(self.database, self.policy)

    # -- the database ---------------------------------------------------------------------------

    def _read(self, fn: Callable[[sqlite3.Connection], T]) -> T:
        return self.database.read(fn)

    def _write(self, fn: Callable[[sqlite3.Connection], T], *, durable: bool = False, retry_s: float | None = None) -> T:
        return self.database.write(fn, durable=durable, retry_s=retry_s)

    @property
    def _db(self) -> sqlite3.Connection:  # the writing connection (tests of faults reach it between transactions)
        return self.database.db

    @property
    def _lock(self) -> Any:
        return self.database.lock

    retry_s = property(lambda self: self.database.retry_s)
    retries = property(lambda self: self.database.retries, doc="transient errors retried since the start")
    failures = property(lambda self: self.database.failures, doc="transactions given up after retry_s")
    last_error = property(lambda self: self.database.last_error)
    fenced = property(lambda self: self.windows.fenced, doc="windows refused for a stale fencing token (StaleLease)")
    groups = property(lambda self: self.windows.groups, doc="group transactions of windows written")
    grouped_windows = property(lambda self: self.windows.grouped_windows, doc="windows written in them")
    schema_version = property(lambda self: self.database.schema_version,
                              doc="read on the reading connection: a status query never waits for the writers' lock")

    def migrate(self) -> None:
        """Bring the schema to ``SCHEMA_VERSION``; refuses a database of a newer version."""
        self.database.migrate()

    @contextmanager
    def transaction(self, *, durable: bool = False) -> Iterator[sqlite3.Connection]:
        """One write transaction (not retried: for callers that do their own)."""
        with self.database.transaction(durable=durable) as db:
            yield db

    def close(self) -> None:
        self.database.close()

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check``: "ok" or the problems found."""
        return self.database.integrity_check()

    @property
    def instance(self) -> str:
        """A random id of this database (keys of notifications: unique across databases)."""
        return self._instance

    # -- sources, state, baselines ----------------------------------------------------------------

    def touch_source(self, source: str, kind: str, detail: str, seen_at: float) -> None:
        """Record that ``source`` delivered data at ``seen_at`` (UNIX s, wall clock)."""
        self.touch_sources([(source, kind, detail)], seen_at)

    def touch_sources(self, sources: Sequence[tuple[str, str, str]], seen_at: float) -> None:
        """``touch_source`` of several (source, kind, detail): one statement per 1000, outside a
        transaction (a fleet's housekeeping: one write for all its structures, the write lock
        taken and released inside one call into SQLite)."""
        for start in range(0, len(sources), 1000):
            chunk = list(sources[start:start + 1000])

            def attempt(chunk: list[tuple[str, str, str]] = chunk) -> None:
                with self.database.lock:
                    StateRepository(self.database.db).touch_sources(chunk, seen_at)

            self.database.retry(attempt)

    def load_state(self, source: str) -> dict[str, Any] | None:
        return self._read(lambda db: StateRepository(db).load_state(source))

    def save_calibration(self, source: str, calibration: dict) -> None:
        self._write(lambda db: StateRepository(db).save_calibration(source, calibration, time.time()))

    def request_baseline(self, source: str, *, retry_s: float | None = None) -> int:
        """Supersede the active baseline; a new one is learnt (state 'learning'). Returns its id."""
        return self._write(lambda db: StateRepository(db).request_baseline(source, time.time()), retry_s=retry_s)

    def baselines(self, source: str | None = None) -> list[dict[str, Any]]:
        return self._read(lambda db: StateRepository(db).baselines(source))

    def store_baseline(self, source: str, baseline: dict) -> int:
        """Store ``baseline`` (``analytics.Baseline.to_dict()``) as the active baseline of
        ``source`` (the previous one superseded); the stored monitor state of the source is
        dropped so that the service starts its monitor from this baseline. Returns its id."""
        now = time.time()
        return self._write(lambda db: StateRepository(db).store_baseline(source, baseline, now), durable=True)

    def active_baseline(self, source: str) -> dict | None:
        """The data of the active baseline of ``source``, or None."""
        return self._read(lambda db: StateRepository(db).active_baseline(source))

    # -- windows and reprocessed recordings ---------------------------------------------------------

    @property
    def MAX_GROUP(self) -> int:  # noqa: N802  (the writer's bound, read as before)
        return self.windows.MAX_GROUP

    def commit_window(self, commit: WindowCommit, *, retry_s: float | None = None) -> list[int]:
        """Write a window's rows, state, alarm changes and their outbox rows in one transaction
        (``storage._commit``); the ids of the alarm events written. ``StorageUnavailable`` when it
        could not be written within ``retry_s``: then nothing of it was."""
        return self.windows.commit(commit, self.retry_s if retry_s is None else float(retry_s))

    def reprocessed(self, keys: Sequence[str]) -> set[str]:
        """Which of ``keys`` are done (committed by ``commit_reprocessed``)."""
        return self._read(lambda db: ReprocessLedger(db).done(keys))

    def commit_reprocessed(self, *, key: str, path: str, source: str, content_sha256: str, configuration: str,
                           windows: int, start_s: float | None, end_s: float | None, rows: list[TrendRow],
                           loads: Sequence[LoadsWindowDocument] = ()) -> None:
        """A reprocessed recording's trend rows and loads windows (replacing those of the same windows)
        and its ledger row, in one transaction: after a kill a file is either done or not started."""
        for r in rows:
            if r.source != source:
                raise ValueError(f"trend row of source {r.source!r} for source {source!r}")
        values = [tuple(getattr(r, c) for c in TREND_COLUMNS) for r in rows]

        def run(db: sqlite3.Connection) -> None:
            now = time.time()
            TrendRepository(db).insert(values, now, replace=True)
            for doc in loads:
                FatigueRepository.insert_window(db, source, doc, at=now, replace=True)
            ReprocessLedger(db).record(key=key, path=path, source=source, content_sha256=content_sha256,
                                       configuration=configuration, windows=windows, start_s=start_s, end_s=end_s, now=now)

        self._write(run)

    # -- alarms -------------------------------------------------------------------------------------

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

    def alarms(self, *, state: str | None = None, limit: int = 1000, source: str | None = None) -> list[AlarmDocument]:
        """Alarms, newest first (only those in ``state``: "active" or "cleared"; of ``source``)."""
        query = AlarmQuery(state, source)
        return self._read(lambda db: AlarmRepository(db).newest(query, limit))

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

    # -- trends and pages -----------------------------------------------------------------------------

    def trends(self, *, from_s: float | None = None, to_s: float | None = None, mode: int | None = None,
               source: str | None = None, limit: int = 100_000) -> list[TrendRow]:
        query = TrendQuery(from_s, to_s, mode, source)
        return self._read(lambda db: TrendRepository(db).query(query, limit))

    def fatigue_windows(self, source: str, *, from_s: float | None = None, to_s: float | None = None,
                        limit: int = 100_000) -> tuple[list[LoadsWindowDocument], int, LoadsWindowDocument | None]:
        """(the stored loads windows of ``source`` with ``from_s <= start < to_s``, oldest first, at most
        ``limit``; how many the period holds; the newest window of the period) in one read."""

        def run(db: sqlite3.Connection) -> tuple[list[LoadsWindowDocument], int, LoadsWindowDocument | None]:
            latest = FatigueRepository.latest(db, source, to_s)
            if latest is not None and from_s is not None and latest.start_s < from_s:
                latest = None
            return FatigueRepository.windows(db, source, from_s, to_s, limit), FatigueRepository.count(db, source, from_s, to_s), latest

        return self._read(run)

    def delete_trends_older_than(self, age_s: float) -> int:
        """Delete the trend rows whose window starts more than ``age_s`` before the newest window of
        their source (data time: a replay of old data keeps its rows). Returns how many went."""
        if not (math.isfinite(age_s) and age_s > 0):
            raise ValueError(f"{age_s=} must be a positive number of seconds")
        return self._write(lambda db: TrendRepository(db).delete_older_than(age_s))

    def trends_page(self, *, from_s: float | None = None, to_s: float | None = None, mode: int | None = None,
                    source: str | None = None, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        """A page of trend rows after ``cursor`` (``storage._paging``: counted in one snapshot, streamed)."""
        after = decode_cursor(TrendRepository.name, cursor, TrendRepository.key_types)
        return self._page(TrendRepository, TrendQuery(from_s, to_s, mode, source), limit=limit, after=after)

    def alarms_page(self, *, state: str | None = None, source: str | None = None, limit: int = 1000,
                    cursor: str | None = None) -> Page[AlarmDocument]:
        """A page of alarms, newest first, after ``cursor``."""
        after = decode_cursor(AlarmRepository.name, cursor, AlarmRepository.key_types)
        return self._page(AlarmRepository, AlarmQuery(state, source), limit=limit, after=after)

    def _page(self, repository: Callable[[sqlite3.Connection], Any], query: Any, *, limit: int,
              after: tuple | None) -> Page[Any]:
        if self.database.memory:  # no second connection sees an in-memory database: read at once
            def whole(db: sqlite3.Connection) -> Page[Any]:
                page = open_page(lambda: (db, lambda: None), repository(db), query, limit=limit, after=after)
                page.items = iter(list(page.items))
                return page

            return self._read(whole)

        def attempt() -> Page[Any]:
            db, release = self.database.snapshot()  # closed when the page is read or closed
            return open_page(lambda: (db, release), repository(db), query, limit=limit, after=after)

        return self.database.retry(attempt)

    def count(self, table: str) -> int:
        if table not in ("trends", "alarms", "alarm_events", "outbox", "notification_log", "baselines"):
            raise ValueError(f"{table=} is not a table of the service's database")
        return int(self._read(lambda db: db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]))

    # -- outbox ---------------------------------------------------------------------------------------

    def due_notifications(self, now: float, limit: int = 20, *, channel: str | None = None,
                          target: str | None = None) -> list[dict[str, Any]]:
        """Pending rows due at ``now``, oldest first, in each alarm's order per target."""
        return self._read(lambda db: OutboxRepository(db).due(now, limit, channel, target))

    def next_due(self, *, channel: str, target: str) -> float | None:
        """When the earliest pending row of a target is due (UNIX s), None when there is none."""
        return self._read(lambda db: OutboxRepository(db).next_due(channel, target))

    def pending_targets(self) -> list[tuple[str, str]]:
        return self._read(lambda db: OutboxRepository(db).pending_targets())

    def claim_notification(self, outbox_id: int, hold_s: float) -> bool:
        """Take a due row for one attempt (no other notifier's for ``hold_s``); False: taken (nodes share PostgreSQL's outbox)."""
        if not (math.isfinite(hold_s) and hold_s > 0):
            raise ValueError(f"{hold_s=} must be a positive number of seconds")
        return self.database.dialect == "sqlite" or self._write(
            lambda db: OutboxRepository(db).claim(outbox_id, time.time(), hold_s), durable=True)

    def record_attempt(self, outbox_id: int, ok: bool, detail: str, *, next_attempt_at: float | None, give_up: bool,
                       permanent: bool = False) -> None:
        """Log one delivery attempt and, in the same transaction, mark the row sent, failed or due again."""
        self._write(lambda db: OutboxRepository(db).record_attempt(outbox_id, ok, detail, time.time(), give_up=give_up,
                                                                   next_attempt_at=next_attempt_at, permanent=permanent),
                    durable=True)

    def fail_pending(self, channel: str, target: str, detail: str) -> int:
        """Mark failed (for good) every pending row of a target no longer configured."""
        return self._write(lambda db: OutboxRepository(db).fail_pending(channel, target, detail), durable=True)

    def outbox(self) -> list[dict[str, Any]]:
        return self._read(lambda db: OutboxRepository(db).rows("outbox"))

    def notification_log(self) -> list[dict[str, Any]]:
        return self._read(lambda db: OutboxRepository(db).rows("notification_log"))

    def outbox_counts(self) -> dict[str, int]:
        return self._read(lambda db: OutboxRepository(db).counts())
