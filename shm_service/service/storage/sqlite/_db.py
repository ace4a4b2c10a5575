"""The SQLite database under the repositories: its connections, its transactions and the retry
of passing faults.

Writes go through one connection under a lock, each in one IMMEDIATE transaction retried as a
whole on a transient error (the database locked by another process, disk full, an I/O error) with
jittered exponential back-off for up to ``retry_s``; then ``StorageUnavailable`` is raised and
nothing of the transaction is kept. Reads use a connection of their own (WAL: a reader sees the
last committed state and never waits for a writer), and a page of a list a connection of its own
for its snapshot (``snapshot``).
"""

from __future__ import annotations

import logging
import random
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from ._schema import SCHEMA_VERSION, migrate

__all__ = ["Database", "StorageUnavailable", "is_transient", "retry_transient"]

log = logging.getLogger("shm.serve.storage")

T = TypeVar("T")


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


def retry_transient(db: Any, fn: Callable[[], T], budget: float, errors: tuple[type[BaseException], ...],
                    transient: Callable[[BaseException], bool]) -> T:
    """``fn()``, again after each of ``errors`` that ``transient`` judges passing, with jittered
    exponential back-off from ``db.retry_initial_s`` (no lock held while waiting), for ``budget``
    s; then StorageUnavailable naming ``db.path``. Either engine's database: it counts in
    ``db.retries``, ``db.failures`` and keeps ``db.last_error``."""
    deadline = time.monotonic() + budget
    delay = db.retry_initial_s
    attempt = 0
    while True:
        try:
            return fn()
        except errors as exc:
            if not transient(exc):
                raise
            attempt += 1
            db.last_error = f"{type(exc).__name__}: {exc}"
            now = time.monotonic()
            if now >= deadline:
                db.failures += 1
                raise StorageUnavailable(f"{db.path}: {exc} (still after {attempt} attempts in {budget:g} s)") from exc
            db.retries += 1
            if attempt == 1 or attempt % 20 == 0:
                log.warning("%s: %s; retrying (attempt %d)", db.path, exc, attempt)
            # full jitter: many writers retrying do not retry in step
            time.sleep(min(random.uniform(0.5, 1.0) * delay, max(deadline - now, 0.0)))
            delay = min(delay * 2, 2.0)


class Database:
    """One SQLite file (or ``:memory:``), migrated on opening. Thread-safe.

    ``sync`` is the synchronous mode of ordinary transactions, ``alarm_sync`` that of the
    ``durable`` ones (alarms, their events, the outbox: they survive a power loss)."""

    dialect = "sqlite"
    schema_latest = SCHEMA_VERSION  # the version this program migrates a database to

    def __init__(self, path: str | Path, *, sync: str = "normal", alarm_sync: str = "full", retry_s: float = 10.0,
                 retry_initial_s: float = 0.05, busy_timeout_s: float = 0.5) -> None:
        for name, value in (("sync", sync), ("alarm_sync", alarm_sync)):
            if value not in ("normal", "full"):
                raise ValueError(f"{name}={value!r} must be 'normal' or 'full'")
        if not (retry_s >= 0 and retry_initial_s > 0 and busy_timeout_s >= 0):
            raise ValueError(f"{retry_s=}, {retry_initial_s=} and {busy_timeout_s=} must be >= 0 (retry_initial_s > 0)")
        self.path = Path(path)
        self.memory = str(path) == ":memory:"
        if not self.memory:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self.sync = sync.upper()
        self.alarm_sync = alarm_sync.upper()
        self.retry_s = float(retry_s)
        self.retry_initial_s = float(retry_initial_s)
        self.busy_timeout_s = float(busy_timeout_s)
        self.retries = 0  # transient errors retried since the start
        self.failures = 0  # transactions given up after retry_s
        self.last_error: str | None = None
        self.lock = threading.RLock()
        self.db = self._connect()
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute(f"PRAGMA synchronous={self.sync}")
        self.db.execute("PRAGMA foreign_keys=ON")
        self._synchronous = self.sync
        self.retry(lambda: self._locked(lambda: migrate(self.db, self.path)))
        if self.memory:
            self.rdb, self.rlock = self.db, self.lock
        else:
            self.rdb = self._connect()
            self.rdb.execute("PRAGMA query_only=ON")
            self.rlock = threading.RLock()

    def _connect(self) -> sqlite3.Connection:
        db = sqlite3.connect(str(self.path), check_same_thread=False, isolation_level=None, timeout=self.busy_timeout_s)
        db.row_factory = sqlite3.Row
        return db

    @staticmethod
    def is_transient(exc: BaseException) -> bool:
        return is_transient(exc)

    def migrate(self) -> None:
        """Bring the schema to ``SCHEMA_VERSION``; refuses a database of a newer version."""
        with self.lock:
            migrate(self.db, self.path)

    def _locked(self, fn: Callable[[], T]) -> T:
        with self.lock:
            return fn()

    def retry(self, fn: Callable[[], T], retry_s: float | None = None) -> T:
        """``fn()`` again after a transient error, with jittered exponential back-off (no lock is
        held while waiting), until ``retry_s`` has passed."""
        return retry_transient(self, fn, self.retry_s if retry_s is None else retry_s,
                               (sqlite3.OperationalError, sqlite3.DatabaseError), is_transient)

    def read(self, fn: Callable[[sqlite3.Connection], T]) -> T:
        """``fn(reading connection)``, retried on passing faults."""
        def attempt() -> T:
            with self.rlock:
                return fn(self.rdb)
        return self.retry(attempt)

    def use_synchronous(self, wanted: str) -> None:
        """The writing connection's synchronous mode for its next transaction (between
        transactions only; the caller holds ``lock``)."""
        if wanted != self._synchronous:
            self.db.execute(f"PRAGMA synchronous={wanted}")
            self._synchronous = wanted

    def write(self, fn: Callable[[sqlite3.Connection], T], *, durable: bool = False, retry_s: float | None = None) -> T:
        """Run ``fn(db)`` in one IMMEDIATE transaction (``durable``: synchronous = alarm_sync),
        retried as a whole on transient errors. A failed COMMIT is rolled back, so the
        connection is never left inside a transaction."""
        def attempt() -> T:
            with self.transaction(durable=durable) as db:
                return fn(db)
        return self.retry(attempt, retry_s)

    @contextmanager
    def transaction(self, *, durable: bool = False) -> Iterator[sqlite3.Connection]:
        """One write transaction (not retried: for callers that do their own)."""
        with self.lock:
            self.use_synchronous(self.alarm_sync if durable else self.sync)
            self.db.execute("BEGIN IMMEDIATE")
            try:
                yield self.db
                self.db.execute("COMMIT")
            except BaseException:
                if self.db.in_transaction:
                    try:
                        self.db.execute("ROLLBACK")
                    except sqlite3.Error:  # the rollback itself failed: SQLite rolled back already
                        pass
                raise

    def snapshot(self) -> tuple[sqlite3.Connection, Callable[[], None]]:
        """A reading connection of its own (for one page of a list: its read transaction is a
        snapshot no writer waits for) and how to close it."""
        db = sqlite3.connect(str(self.path), check_same_thread=False, isolation_level=None, timeout=self.busy_timeout_s)
        db.execute("PRAGMA query_only=ON")
        return db, db.close

    def close(self) -> None:
        with self.lock:
            self.db.close()
        if self.rdb is not self.db:
            with self.rlock:
                self.rdb.close()

    def integrity_check(self) -> str:
        """``PRAGMA integrity_check``: "ok" or the problems found."""
        return "; ".join(str(r[0]) for r in self.read(lambda db: db.execute("PRAGMA integrity_check").fetchall()))

    @property
    def schema_version(self) -> int:
        return int(self.read(lambda db: db.execute("PRAGMA user_version").fetchone()[0]))
