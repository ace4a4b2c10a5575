"""The trend rows: one row per analysis window and mode (``contract.TrendRow``).

``TrendStore`` is what the service needs of them, whatever holds them; ``TrendRepository``
implements it over one SQLite connection. A repository neither opens transactions nor retries:
its caller (``Storage``) decides what one transaction holds (a window's rows with its state and
alarms) and retries it as a whole."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Protocol

from pydantic import TypeAdapter

from contract import TrendRow

__all__ = ["TREND_COLUMNS", "TrendQuery", "TrendRepository", "TrendStore"]

#: The trend table's columns are the trend row document's fields.
TREND_COLUMNS = tuple(TrendRow.model_fields)
#: A trend row's key and the order of every answer: window start, source, mode, bending plane
#: (a biaxial beam's ζ and ξ mode k of one window are two rows).
_KEY = ("window_start_s", "source", "mode", "plane")
#: validates a chunk of rows in one call (a tenth of the cost of one call per row)
_ROWS = TypeAdapter(list[TrendRow])


@dataclass(frozen=True)
class TrendQuery:
    """Which rows: ``from_s <= window_start_s < to_s`` (UNIX s; None: open), of one mode, of one
    source."""

    from_s: float | None = None
    to_s: float | None = None
    mode: int | None = None
    source: str | None = None


class TrendStore(Protocol):
    """The trend rows of every source, in the order of their key (window start, source, mode)."""

    name: str

    def insert(self, rows: Sequence[tuple], now: float, *, replace: bool = False) -> None:
        """Rows as tuples of ``TREND_COLUMNS``; a row whose key is stored is kept (``replace``:
        replaced, as a reprocessed recording does)."""
        ...

    def query(self, query: TrendQuery, limit: int) -> list[TrendRow]: ...

    def count(self, query: TrendQuery, after: tuple | None) -> int: ...

    def key_at(self, query: TrendQuery, after: tuple | None, offset: int) -> tuple | None: ...

    def chunks(self, query: TrendQuery, after: tuple | None, limit: int) -> Iterator[list[TrendRow]]: ...

    def delete_older_than(self, age_s: float) -> int: ...

    def total(self) -> int: ...


class TrendRepository:
    """``TrendStore`` over the SQLite connection ``db`` (table ``trends``, keyed and indexed by
    (source, window start, mode, plane) and window start: every query below is an index range)."""

    name = "trends"
    key_types: tuple[type, ...] = (float, str, int, str)

    def __init__(self, db: sqlite3.Connection, chunk_rows: int = 2000) -> None:
        self.db = db
        self.chunk_rows = int(chunk_rows)

    def insert(self, rows: Sequence[tuple], now: float, *, replace: bool = False) -> None:
        verb = "INSERT OR REPLACE" if replace else "INSERT OR IGNORE"
        self.db.executemany(
            f"{verb} INTO trends ({', '.join(TREND_COLUMNS)}, created_at) VALUES ({', '.join('?' * (len(TREND_COLUMNS) + 1))})",
            [(*row, now) for row in rows])

    @staticmethod
    def _where(query: TrendQuery, after: tuple | None) -> tuple[str, list]:
        pairs = [("window_start_s >= ?", query.from_s), ("window_start_s < ?", query.to_s), ("mode = ?", query.mode),
                 ("source = ?", query.source)]
        where = [sql for sql, value in pairs if value is not None]
        args = [value for _, value in pairs if value is not None]
        if after is not None:
            where.append(f"({', '.join(_KEY)}) > ({', '.join('?' * len(_KEY))})")
            args.extend(after)
        return (" WHERE " + " AND ".join(where)) if where else "", args

    def query(self, query: TrendQuery, limit: int) -> list[TrendRow]:
        where, args = self._where(query, None)
        rows = self.db.execute(f"SELECT {', '.join(TREND_COLUMNS)} FROM trends{where} ORDER BY {', '.join(_KEY)} LIMIT ?",
                               [*args, int(limit)]).fetchall()
        return _ROWS.validate_python([dict(zip(TREND_COLUMNS, r)) for r in rows])

    def count(self, query: TrendQuery, after: tuple | None) -> int:
        where, args = self._where(query, after)
        return int(self.db.execute(f"SELECT COUNT(*) FROM trends{where}", args).fetchone()[0])

    def key_at(self, query: TrendQuery, after: tuple | None, offset: int) -> tuple | None:
        where, args = self._where(query, after)
        row = self.db.execute(f"SELECT {', '.join(_KEY)} FROM trends{where} ORDER BY {', '.join(_KEY)} LIMIT 1 OFFSET ?",
                              [*args, int(offset)]).fetchone()
        return None if row is None else (float(row[0]), str(row[1]), int(row[2]), str(row[3]))

    def chunks(self, query: TrendQuery, after: tuple | None, limit: int) -> Iterator[list[TrendRow]]:
        where, args = self._where(query, after)
        cursor = self.db.execute(f"SELECT {', '.join(TREND_COLUMNS)} FROM trends{where} ORDER BY {', '.join(_KEY)} LIMIT ?",
                                 [*args, int(limit)])
        while True:
            rows = cursor.fetchmany(self.chunk_rows)
            if not rows:
                return
            yield _ROWS.validate_python([dict(zip(TREND_COLUMNS, r)) for r in rows])

    def delete_older_than(self, age_s: float) -> int:
        """Delete the rows whose window starts more than ``age_s`` before the newest window of
        their source (data time: a replay of old data keeps its rows). Returns how many went."""
        cur = self.db.execute(
            "DELETE FROM trends WHERE window_start_s < "
            "(SELECT MAX(t.window_start_s) FROM trends AS t WHERE t.source = trends.source) - ?", (float(age_s),))
        return int(cur.rowcount)

    def total(self) -> int:
        return int(self.db.execute("SELECT COUNT(*) FROM trends").fetchone()[0])
