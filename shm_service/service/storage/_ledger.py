"""The ledger of recordings reprocessed into the trends (``shm reprocess``): a file is done once
its row is committed with its trend rows, in one transaction; its key is its content hash and
the configuration (the source included)."""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from typing import Protocol

__all__ = ["ReprocessLedger", "ReprocessStore"]


class ReprocessStore(Protocol):
    def done(self, keys: Sequence[str]) -> set[str]: ...

    def record(self, *, key: str, path: str, source: str, content_sha256: str, configuration: str, windows: int,
               start_s: float | None, end_s: float | None, now: float) -> None: ...


class ReprocessLedger:
    """``ReprocessStore`` over the SQLite connection ``db`` (tables reprocessed, sources)."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db

    def done(self, keys: Sequence[str]) -> set[str]:
        """Which of ``keys`` are done."""
        rows = self.db.execute(f"SELECT key FROM reprocessed WHERE key IN ({', '.join('?' * len(keys))})", tuple(keys))
        return {r[0] for r in rows.fetchall()}

    def record(self, *, key: str, path: str, source: str, content_sha256: str, configuration: str, windows: int,
               start_s: float | None, end_s: float | None, now: float) -> None:
        """The file's ledger row, and its source's span of data."""
        self.db.execute(
            "INSERT INTO sources (id, kind, detail, first_seen_s, last_seen_s) VALUES (?, 'reprocess', ?, ?, ?) "
            "ON CONFLICT(id) DO UPDATE SET first_seen_s=MIN(sources.first_seen_s, excluded.first_seen_s), "
            "last_seen_s=MAX(sources.last_seen_s, excluded.last_seen_s)",
            (source, path, start_s if start_s is not None else now, end_s if end_s is not None else now))
        self.db.execute(
            "INSERT OR REPLACE INTO reprocessed (key, path, source, content_sha256, configuration, windows, start_s, end_s, "
            "done_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (key, path, source, content_sha256, configuration, windows, start_s, end_s, now))
