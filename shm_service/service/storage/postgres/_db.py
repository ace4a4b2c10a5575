"""The PostgreSQL database under the repositories: its connections, transactions and the retry
of passing faults, with the interface of ``storage.sqlite._db.Database`` (``Storage`` and the
window writer use either).

Writes go through one connection under a lock, each in one transaction retried as a whole on a
transient error (the server restarting or unreachable, a serialization failure, a deadlock, the
disk full) with jittered exponential back-off for up to ``retry_s``; then ``StorageUnavailable``
is raised and nothing of the transaction is kept. A connection found broken is opened anew at
the next attempt. Reads use a connection of their own (READ COMMITTED: the last committed state,
never waiting for a writer), a page of a list one of its own (a REPEATABLE READ snapshot).

Every commit is durable (``synchronous_commit`` on, the server's default): ``sync`` and
``alarm_sync`` are SQLite's and accepted for the same settings, but a window a node counts as
committed is one another node resumes after, so none is committed less durably.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import psycopg

from .._commit import StaleLease
from .._state import STATE_COLUMNS, STATE_UPSERT
from .._trends import TrendRepository
from .._url import check_postgres_url, redact
from ..sqlite._db import StorageUnavailable, retry_transient
from ._connection import PgConnection
from ._schema import SCHEMA_VERSION, migrate, schema_version

__all__ = ["PgDatabase", "check_fence", "is_transient", "write_plain"]

log = logging.getLogger("shm.serve.storage")

T = TypeVar("T")


def is_transient(exc: BaseException) -> bool:
    """Whether an error of PostgreSQL may pass when the transaction is tried again: the server
    unreachable or restarting, a serialization failure or deadlock, resources exhausted; a
    connection closed under the client; a unique key taken by another node's concurrent commit.
    Not an error of the statement (its SQL, another constraint)."""
    if isinstance(exc, StorageUnavailable):
        return True
    # An alarm's events are numbered MAX(seq) + 1 in the writing transaction; two nodes writing
    # events of one alarm at once (an acknowledgement on one, the holder's window on the other)
    # collide on (alarm_id, seq): tried again, the number is taken after the other's commit.
    return isinstance(exc, (psycopg.OperationalError, psycopg.InterfaceError, psycopg.errors.UniqueViolation))


def check_fence(db: Any, structure_id: str, token: int) -> None:
    """Refuse the transaction of ``db`` (a ``PgConnection`` inside a transaction) unless
    ``token`` is the current fencing token of ``structure_id``'s lease. The lease's row stays
    locked (FOR SHARE) until the transaction ends, so no takeover happens in between.

    Raises
    ------
    StaleLease
        When the lease's token differs (or the structure has no lease).
    """
    row = db.execute("SELECT token FROM leases WHERE structure_id = ? FOR SHARE", (structure_id,)).fetchone()
    current = None if row is None else int(row[0])
    if current != int(token):
        raise StaleLease(_refusal(structure_id, token, current))


def _refusal(structure_id: str, token: int, current: int | None) -> str:
    if current is None:
        return f"structure {structure_id!r} has no lease: a commit with fencing token {token} is refused"
    return f"structure {structure_id!r}: fencing token {token} is stale (the lease's is {current}): the commit is refused"


def write_plain(db: PgConnection, windows: list[tuple[list[tuple], tuple, int | None]], now: float) -> list[str | None]:
    """Write plain windows (trend rows as tuples of ``TREND_COLUMNS``, a monitor state row of
    ``STATE_COLUMNS``, a fencing token or None) inside the caller's transaction: the tokens
    checked in one statement (their lease rows locked FOR SHARE, in key order), then every row of
    the windows whose token holds in three. Per window, why it was refused (None: written)."""
    fences = sorted({(state[0], token) for _, state, token in windows if token is not None})
    current: dict[str, int] = {}
    if fences:
        rows = db.execute("SELECT structure_id, token FROM leases WHERE structure_id = ANY(?) ORDER BY structure_id FOR SHARE",
                          ([source for source, _ in fences],)).fetchall()
        current = {str(r[0]): int(r[1]) for r in rows}
    refused = [None if token is None or current.get(state[0]) == token else _refusal(state[0], token, current.get(state[0]))
               for _, state, token in windows]
    kept = [w for w, no in zip(windows, refused) if no is None]
    if kept:
        TrendRepository(db).insert([row for rows, _, _ in kept for row in rows], now)  # type: ignore[arg-type]
        db.executemany(f"INSERT INTO monitor_state ({', '.join(STATE_COLUMNS)}, updated_at) "
                       f"VALUES ({', '.join('?' * (len(STATE_COLUMNS) + 1))}) {STATE_UPSERT}", [(*state, now) for _, state, _ in kept])
        db.execute("UPDATE alarms SET stale=0 WHERE stale=1 AND source = ANY(?)", (sorted({state[0] for _, state, _ in kept}),))
    return refused


class PgDatabase:
    """One PostgreSQL database (``url``: ``postgresql://USER@HOST:PORT/DB``), migrated on opening
    (``storage.postgres._schema``: under an advisory lock, so nodes starting together migrate
    once). Thread-safe."""

    dialect = "postgresql"
    memory = False
    schema_latest = SCHEMA_VERSION  # the version this program migrates a database to

    def __init__(self, url: str, *, sync: str = "normal", alarm_sync: str = "full", retry_s: float = 10.0,
                 retry_initial_s: float = 0.05, busy_timeout_s: float = 0.5, connect_timeout_s: float = 5.0) -> None:
        for name, value in (("sync", sync), ("alarm_sync", alarm_sync)):
            if value not in ("normal", "full"):
                raise ValueError(f"{name}={value!r} must be 'normal' or 'full'")
        if not (retry_s >= 0 and retry_initial_s > 0 and busy_timeout_s >= 0):
            raise ValueError(f"{retry_s=}, {retry_initial_s=} and {busy_timeout_s=} must be >= 0 (retry_initial_s > 0)")
        check_postgres_url(url, "storage url")
        self.url = url
        self.path = redact(url)
        self.sync, self.alarm_sync = sync.upper(), alarm_sync.upper()
        self.retry_s = float(retry_s)
        self.retry_initial_s = float(retry_initial_s)
        self.connect_timeout_s = float(connect_timeout_s)
        self.retries = 0
        self.failures = 0
        self.last_error: str | None = None
        self.lock = threading.RLock()
        self.rlock = threading.RLock()
        self._db: PgConnection | None = None
        self._rdb: PgConnection | None = None
        self.retry(lambda: self._locked(lambda: migrate(self.db, self.path)))

    def _connect(self, role: str) -> PgConnection:
        return PgConnection(self.url, connect_timeout_s=self.connect_timeout_s, application_name=f"shm-{role}",
                            streaming=role == "page")

    @property
    def db(self) -> PgConnection:
        """The writing connection (opened anew when found broken; the caller holds ``lock``)."""
        if self._db is None or not self._db.usable:
            self._db = self._connect("writer")
        return self._db

    @property
    def rdb(self) -> PgConnection:
        if self._rdb is None or not self._rdb.usable:
            self._rdb = self._connect("reader")
        return self._rdb

    def _locked(self, fn: Callable[[], T]) -> T:
        with self.lock:
            return fn()

    @staticmethod
    def is_transient(exc: BaseException) -> bool:
        return is_transient(exc)

    def retry(self, fn: Callable[[], T], retry_s: float | None = None) -> T:
        """``fn()`` again after a transient error, with jittered exponential back-off (no lock is
        held while waiting), until ``retry_s`` has passed."""
        return retry_transient(self, fn, self.retry_s if retry_s is None else retry_s, (psycopg.Error,), is_transient)

    def read(self, fn: Callable[[PgConnection], T]) -> T:
        """``fn(reading connection)``, retried on passing faults."""
        def attempt() -> T:
            with self.rlock:
                return fn(self.rdb)
        return self.retry(attempt)

    @staticmethod
    def check_fence(db: PgConnection, structure_id: str, token: int) -> None:
        """``check_fence`` (the window writer's check of a commit's fencing token)."""
        check_fence(db, structure_id, token)

    @staticmethod
    def write_plain(db: PgConnection, windows: list[tuple[list[tuple], tuple, int | None]], now: float) -> list[str | None]:
        """``write_plain`` (the window writer's plain windows)."""
        return write_plain(db, windows, now)

    def use_synchronous(self, wanted: str) -> None:
        """Nothing to change: every commit is durable (see the module's docstring)."""

    def write(self, fn: Callable[[PgConnection], T], *, durable: bool = False, retry_s: float | None = None) -> T:
        """Run ``fn(db)`` in one transaction, retried as a whole on transient errors."""
        def attempt() -> T:
            with self.transaction(durable=durable) as db:
                return fn(db)
        return self.retry(attempt, retry_s)

    @contextmanager
    def transaction(self, *, durable: bool = False) -> Iterator[PgConnection]:
        """One write transaction (not retried: for callers that do their own). A failed
        transaction is rolled back, so the connection is never left inside one."""
        with self.lock:
            db = self.db
            db.conn.execute("BEGIN")
            try:
                yield db
                db.conn.execute("COMMIT")
            except BaseException:
                if db.usable and db.in_transaction:
                    try:
                        db.conn.execute("ROLLBACK")
                    except psycopg.Error:  # the connection broke meanwhile: the server rolled back
                        pass
                raise

    def snapshot(self) -> tuple[PgConnection, Callable[[], None]]:
        """A reading connection of its own (for one page of a list) and how to close it."""
        db = self._connect("page")
        return db, db.close

    def migrate(self) -> None:
        with self.lock:
            migrate(self.db, self.path)

    def close(self) -> None:
        with self.lock:
            if self._db is not None:
                self._db.close()
        with self.rlock:
            if self._rdb is not None:
                self._rdb.close()

    def integrity_check(self) -> str:
        """PostgreSQL keeps its own consistency (WAL, checksums when enabled): "ok" when the
        schema is this program's."""
        version = self.schema_version
        return "ok" if version == SCHEMA_VERSION else f"schema version {version}, this program's is {SCHEMA_VERSION}"

    @property
    def schema_version(self) -> int:
        return self.read(schema_version)
