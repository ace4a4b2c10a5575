"""The commit of an analysis window: its trend rows, the monitor state after it, its alarm
changes, their events and the outbox rows of their notifications, in ONE transaction over the
repositories, so a crash at any instant leaves either all of it or none of it.

Group commit: the windows that threads of one process hand to ``WindowWriter.commit`` while a
write is under way are written together by one of those threads. A fleet's worker process thus
takes the database's write lock once for all its structures' windows of the moment, from one
thread, and not once per window from as many threads as it hosts structures.

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
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from contract import LoadsWindowDocument, TrendRow

from ._alarms import AlarmChange, AlarmRepository, NotifyPolicy
from .sqlite._db import Database, StorageUnavailable
from ._fatigue import FatigueRepository
from ._state import STATE_COLUMNS, STATE_UPSERT, StateRepository
from ._trends import TREND_COLUMNS, TrendRepository

__all__ = ["StaleLease", "WindowCommit", "WindowWriter"]


class StaleLease(RuntimeError):
    """A commit or a renewal with a fencing token that is no longer the structure's (another
    node took its lease, ``storage.postgres._leases``): nothing of it was written."""


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
    loads: LoadsWindowDocument | None = None  # the hot spots' loads of the window (its residue is in monitor_state)
    fencing_token: int | None = None  # the token of the node's lease of the source (PostgreSQL): checked in the transaction


@dataclass(eq=False)
class _Ticket:
    """A window handed to the group commit: its statements, and what became of them."""

    run: Callable[[sqlite3.Connection], list[int]]  # the window's statements
    durable: bool
    retry_s: float
    plain: tuple[list[tuple], tuple] | None = None  # (trend rows, monitor state row): no alarm, no baseline
    token: int | None = None  # the fencing token of the window's commit
    done: bool = False
    result: list[int] | None = None
    error: BaseException | None = None


class WindowWriter:
    """Writes windows to ``database`` (see the module's docstring); ``policy``: whom their alarm
    events notify. Thread-safe."""

    #: the most windows written in one group transaction (a bound on how long the lock is held)
    MAX_GROUP = 64

    def __init__(self, database: Database, policy: NotifyPolicy) -> None:
        self.database = database
        self.policy = policy
        self._group = threading.Condition(threading.Lock())
        self._queued: list[_Ticket] = []
        self._leading = False
        self.groups = 0  # group transactions written
        self.grouped_windows = 0  # windows written in them
        self.fenced = 0  # windows refused for a stale fencing token
        # The staging of plain windows answers SQLite's GIL-bound lock (see the module's text);
        # PostgreSQL's writers do not share a lock: every window there is a savepoint of the group.
        self.staged = getattr(database, "dialect", "sqlite") == "sqlite"
        if self.staged:
            self._stage()

    def _stage(self) -> None:
        """The writing connection's TEMP tables and trigger of the plain windows: staged rows are
        moved into the database's tables by one ``INSERT INTO stage_flush``."""
        cols = ", ".join(TREND_COLUMNS)
        state = ", ".join(STATE_COLUMNS)
        with self.database.lock:
            db = self.database.db
            db.execute("PRAGMA temp_store=MEMORY")
            db.execute(f"CREATE TEMP TABLE IF NOT EXISTS stage_trends ({cols})")
            db.execute(f"CREATE TEMP TABLE IF NOT EXISTS stage_state ({state})")
            db.execute("CREATE TEMP TABLE IF NOT EXISTS stage_flush (at REAL NOT NULL)")
            # Unqualified targets: a trigger may not name a schema; these tables exist in main only.
            db.execute(f"""
                CREATE TEMP TRIGGER IF NOT EXISTS stage_flush_windows AFTER INSERT ON stage_flush BEGIN
                    INSERT OR IGNORE INTO trends ({cols}, created_at) SELECT {cols}, NEW.at FROM stage_trends;
                    INSERT INTO monitor_state ({state}, updated_at) SELECT {state}, NEW.at FROM stage_state WHERE true
                        ORDER BY rowid {STATE_UPSERT};
                    UPDATE alarms SET stale=0 WHERE stale=1 AND source IN (SELECT source FROM stage_state);
                    DELETE FROM stage_trends;
                    DELETE FROM stage_state;
                    DELETE FROM stage_flush;
                END""")

    def commit(self, commit: WindowCommit, retry_s: float) -> list[int]:
        """Write a window (durable when it changes an alarm), retried on transient errors for up
        to ``retry_s``. Rows of a window already stored are ignored (replaying the same period).
        Returns the ids of the alarm events written. Raises ``StorageUnavailable`` when it could
        not be written in time: then nothing of it was."""
        for r in commit.rows:
            if r.source != commit.source:
                raise ValueError(f"trend row of source {r.source!r} in a commit of source {commit.source!r}")
        token = commit.fencing_token
        if token is not None and self.staged:
            raise ValueError(f"fencing_token={token}: leases need the PostgreSQL storage (a SQLite file has one service)")
        # What needs no database is made before the transaction: the write lock, which the other
        # processes of a fleet wait for, is held for the statements only.
        rows = [tuple(getattr(r, c) for c in TREND_COLUMNS) for r in commit.rows]
        monitor = None if commit.monitor_state is None else json.dumps(commit.monitor_state)
        calibration = None if commit.calibration is None else json.dumps(commit.calibration)
        state = (commit.source, commit.window_start_s, commit.data_time_s, monitor, calibration)  # STATE_COLUMNS

        def run(db: sqlite3.Connection) -> list[int]:
            if token is not None:  # first: a refused window writes nothing
                self.database.check_fence(db, commit.source, token)  # type: ignore[attr-defined]
            now = time.time()
            TrendRepository(db).insert(rows, now)
            stored = StateRepository(db)
            stored.save_state(state, now)
            alarms = AlarmRepository(db, self.policy)
            alarms.clear_stale([commit.source])  # the source is judged again: its alarms are no longer stale
            if commit.loads is not None:
                FatigueRepository.insert_window(db, commit.source, commit.loads, at=now)
            if commit.baseline is not None:
                stored.learnt_baseline(commit.source, commit.baseline, now)
            events = [alarms.apply(commit.source, change, now) for change in commit.alarm_changes]
            return [e for e in events if e is not None]

        simple = not commit.alarm_changes and commit.baseline is None and commit.loads is None
        plain = (rows, state) if simple else None
        return self._group_commit(_Ticket(run, bool(commit.alarm_changes), float(retry_s), plain, token))

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
        if not self.staged:
            return self._write_direct(batch)
        trends = [row for t in batch for row in t.plain[0]]  # type: ignore[index]
        states = [t.plain[1] for t in batch]  # type: ignore[index]
        columns = len(TREND_COLUMNS)
        database = self.database

        def attempt() -> None:
            with database.lock:
                db = database.db
                database.use_synchronous(database.sync)
                db.execute("DELETE FROM stage_trends")  # what a failed attempt staged
                db.execute("DELETE FROM stage_state")
                db.executemany(f"INSERT INTO stage_trends VALUES ({', '.join('?' * columns)})", trends)
                db.executemany(f"INSERT INTO stage_state VALUES ({', '.join('?' * len(STATE_COLUMNS))})", states)
                db.execute("INSERT INTO stage_flush (at) VALUES (?)", (time.time(),))

        try:
            database.retry(attempt, max(t.retry_s for t in batch))
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

    def _write_direct(self, batch: list[_Ticket]) -> bool:
        """PostgreSQL's plain windows: one transaction of a few statements for all of them (the
        fencing tokens checked at once, then the rows, states and stale flags of the windows whose
        token holds; a window with a stale token gets ``StaleLease``). As ``_write_plain``: a
        passing fault is retried; False when it failed for good and nothing of it was kept."""
        windows = [(t.plain[0], t.plain[1], t.token) for t in batch]  # type: ignore[index]
        refused: list[str | None] = []

        def run(db: sqlite3.Connection) -> None:
            refused[:] = self.database.write_plain(db, windows, time.time())  # type: ignore[attr-defined]

        try:
            self.database.write(run, retry_s=max(t.retry_s for t in batch))
        except StorageUnavailable as exc:
            for t in batch:
                t.result, t.error, t.done = None, exc, True
            return True
        except Exception as exc:
            if self.database.is_transient(exc):
                raise
            return False
        self.groups += 1
        self.grouped_windows += len(batch)
        for t, why in zip(batch, refused):
            t.result, t.error, t.done = (None, StaleLease(why), True) if why is not None else ([], None, True)
        self.fenced += sum(why is not None for why in refused)
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
                db.execute("SAVEPOINT window_commit")  # not "window": a reserved word of PostgreSQL
                try:
                    t.result = t.run(db)
                except Exception as exc:
                    if self.database.is_transient(exc):
                        raise
                    db.execute("ROLLBACK TO window_commit")
                    t.error = exc
                db.execute("RELEASE window_commit")

        try:
            if batch:
                self.database.write(run, durable=any(t.durable for t in batch), retry_s=max(t.retry_s for t in batch))
                self.groups += 1
                self.grouped_windows += len(batch)
                self.fenced += sum(isinstance(t.error, StaleLease) for t in batch)
        except BaseException as exc:
            for t in batch:
                t.result, t.error = None, exc
            if not isinstance(exc, Exception):
                raise
        finally:
            for t in batch:
                t.done = True

