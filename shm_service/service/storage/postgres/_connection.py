"""A PostgreSQL connection that the repositories use as they use a SQLite one.

The repositories (``storage._trends``, ``_alarms``, ``_outbox``, ``_state``, ``_fatigue``,
``_ledger``) are written once, in SQLite's SQL with ``?`` parameters. ``PgConnection`` runs that
text on PostgreSQL after a fixed set of rewrites, each of a form the repositories use and each
with the same meaning on both engines:

- ``?`` becomes ``%s`` (psycopg's placeholder; the repositories never write a literal ``%``);
- ``INSERT OR IGNORE INTO t`` becomes ``INSERT INTO t ... ON CONFLICT DO NOTHING``;
- ``INSERT OR REPLACE INTO t (cols)`` becomes an upsert on ``t``'s primary key that sets every
  other column given (``_PRIMARY_KEYS``: a table missing there is refused, not guessed);
- ``MIN(a, b)`` / ``MAX(a, b)`` of two arguments (SQLite's scalar forms) become ``LEAST`` /
  ``GREATEST``; ``x.c IS y.c`` becomes ``IS NOT DISTINCT FROM``;
- an ``INSERT`` into a table with an ``id`` column returns it (``lastrowid``, as SQLite gives);
- a bare ``BEGIN`` (a page's read snapshot, ``storage._paging``) opens a REPEATABLE READ
  read-only transaction: its counts and rows agree, as in SQLite's WAL snapshot; a page's
  connection (``streaming``) reads its rows through server-side cursors, chunk by chunk.

A NaN parameter is stored as NULL, as SQLite stores it. Rows answer by index and by column name
(``row[0]``, ``row["id"]``, ``dict(row)``), as ``sqlite3.Row`` does.
"""

from __future__ import annotations

import math
import re
import weakref
from collections.abc import Iterator, Sequence
from functools import lru_cache
from typing import Any

import psycopg
from psycopg.conninfo import conninfo_to_dict
from psycopg.pq import TransactionStatus

from .._paging import CHUNK_ROWS

__all__ = ["PgConnection", "PgRow", "translate"]

#: the primary key of each table an ``INSERT OR REPLACE`` writes
_PRIMARY_KEYS: dict[str, tuple[str, ...]] = {
    "trends": ("source", "window_start_s", "mode", "plane"),
    "fatigue_windows": ("source", "window_start_s"),
    "fatigue_hot_spots": ("source", "window_start_s", "hot_spot"),
    "reprocessed": ("key",),
    "meta": ("key",),
}
#: the tables whose rows have a generated ``id`` (an INSERT returns it)
_ID_TABLES = frozenset({"alarms", "alarm_events", "baselines", "outbox", "notification_log"})

_INSERT = re.compile(r"^\s*INSERT\s+(OR\s+(IGNORE|REPLACE)\s+)?INTO\s+(\w+)\s*\(([^)]*)\)", re.IGNORECASE)
_PAIR = re.compile(r"\b(MIN|MAX)\(([\w.]+),\s*([\w.]+)\)", re.IGNORECASE)
_IS = re.compile(r"\b(\w+\.\w+) IS (\w+\.\w+)\b")


@lru_cache(maxsize=512)
def translate(sql: str, many: bool = False) -> tuple[str, bool]:
    """The PostgreSQL text of the SQLite statement ``sql`` (see the module's docstring) and
    whether it returns the new row's id (never for ``many``)."""
    text = sql.replace("?", "%s")
    text = _PAIR.sub(lambda m: f"{'LEAST' if m[1].upper() == 'MIN' else 'GREATEST'}({m[2]}, {m[3]})", text)
    text = _IS.sub(r"\1 IS NOT DISTINCT FROM \2", text)
    returning = False
    insert = _INSERT.match(text)
    if insert is not None:
        verb, table = (insert[2] or "").upper(), insert[3]
        text = _INSERT.sub(f"INSERT INTO {table} ({insert[4]})", text, count=1)
        if verb == "IGNORE":
            text += " ON CONFLICT DO NOTHING"
        elif verb == "REPLACE":
            if table not in _PRIMARY_KEYS:
                raise ValueError(f"INSERT OR REPLACE into {table!r}: its primary key is not known to the PostgreSQL backend")
            key = _PRIMARY_KEYS[table]
            columns = [c.strip() for c in insert[4].split(",")]
            others = [c for c in columns if c not in key]
            text += f" ON CONFLICT ({', '.join(key)}) DO " + (
                "UPDATE SET " + ", ".join(f"{c} = EXCLUDED.{c}" for c in others) if others else "NOTHING")
        if table in _ID_TABLES and not many and "RETURNING" not in text.upper():
            text += " RETURNING id"
            returning = True
    elif text.strip().upper() == "BEGIN":
        text = "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY"
    return text, returning


def _param(value: Any) -> Any:
    return None if isinstance(value, float) and math.isnan(value) else value


def _params(args: Sequence[Any] | None) -> tuple[Any, ...] | None:
    return tuple(_param(v) for v in args) if args else None


class PgRow(tuple):
    """A row answering by index and by column name (``sqlite3.Row``'s interface)."""

    _names: tuple[str, ...] = ()

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, str):
            try:
                return tuple.__getitem__(self, self._names.index(key))
            except ValueError:
                raise IndexError(f"no column {key!r}") from None
        return tuple.__getitem__(self, key)

    def keys(self) -> list[str]:
        return list(self._names)


def _row_factory(cursor: Any) -> Any:
    names = tuple(c.name for c in cursor.description or ())
    kind = type("Row", (PgRow,), {"_names": names, "__slots__": ()})
    return lambda values: kind(values)


class _Cursor:
    """The answer of one statement: rows (fetched), ``rowcount``, ``lastrowid``, ``description``."""

    def __init__(self, cursor: psycopg.Cursor[Any] | psycopg.ServerCursor[Any], returning: bool) -> None:
        self._cursor = cursor
        self.lastrowid: int | None = None
        self.rowcount = cursor.rowcount
        self.description = cursor.description
        if returning:
            row = cursor.fetchone() if cursor.description else None
            self.lastrowid = None if row is None else int(row[0])

    def fetchone(self) -> Any:
        return self._cursor.fetchone()

    def fetchall(self) -> list[Any]:
        return self._cursor.fetchall()

    def fetchmany(self, size: int) -> list[Any]:
        return self._cursor.fetchmany(size)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._cursor)


#: libpq's options that make a connection to a server gone silent (a cut network, a host that
#: died) fail within seconds instead of hanging a write for the kernel's TCP timeout (minutes):
#: keep-alive probes on an idle connection, and a bound on unacknowledged data of a busy one.
#: A URL's own values of these keys win.
_LIVENESS = {"keepalives": 1, "keepalives_idle": 5, "keepalives_interval": 2, "keepalives_count": 3,
             "tcp_user_timeout": 10_000}


def _close(conn: psycopg.Connection[Any], servers: list[psycopg.ServerCursor[Any]]) -> None:
    for cursor in servers:
        cursor.close()
    conn.close()


class PgConnection:
    """A psycopg connection in autocommit mode (transactions are the caller's ``BEGIN`` and
    ``COMMIT``, as with the SQLite connections) running the repositories' SQLite text."""

    def __init__(self, url: str, *, connect_timeout_s: float = 5.0, application_name: str = "shm",
                 streaming: bool = False) -> None:
        self.url = url
        self.streaming = streaming
        given = conninfo_to_dict(url)
        defaults: dict[str, Any] = {"connect_timeout": max(1, int(math.ceil(connect_timeout_s))),
                                    "application_name": application_name, **_LIVENESS}
        options = {k: v for k, v in defaults.items() if k not in given}
        self.conn: psycopg.Connection[Any] = psycopg.connect(url, autocommit=True, row_factory=_row_factory, **options)
        self._servers: list[psycopg.ServerCursor[Any]] = []
        # closed when this object goes, as a sqlite3 connection is (a Storage not closed leaves no session behind)
        self._finalizer = weakref.finalize(self, _close, self.conn, self._servers)

    def execute(self, sql: str, args: Sequence[Any] | None = None) -> _Cursor:
        text, returning = translate(sql)
        if self.streaming and self.in_transaction and text.lstrip().upper().startswith("SELECT"):
            # a page's rows come from the server as they are read: its memory does not grow with its length
            server = self.conn.cursor(name=f"page_{len(self._servers)}")
            server.itersize = CHUNK_ROWS
            self._servers.append(server)
            server.execute(text, _params(args))
            return _Cursor(server, returning)
        cursor = self.conn.cursor()
        cursor.execute(text, _params(args))
        return _Cursor(cursor, returning)

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> None:
        rows = list(rows)
        if not rows:
            return
        text, _ = translate(sql, True)
        with self.conn.cursor() as cursor:
            cursor.executemany(text, [_params(r) or () for r in rows])

    @property
    def in_transaction(self) -> bool:
        return self.conn.info.transaction_status != TransactionStatus.IDLE

    @property
    def usable(self) -> bool:
        """False once the connection is closed or broken (a restart of the server, the network)."""
        return not (self.conn.closed or self.conn.broken)

    def close(self) -> None:
        self._finalizer()
