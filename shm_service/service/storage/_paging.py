"""Keyset paging of the stored lists (an export says what it holds and streams).

A page is read in ONE read transaction of a connection of its own (WAL: a snapshot; writers
never wait for it), so its ``total``, ``count``, the rows it streams and its ``next_cursor``
agree with each other whatever is committed meanwhile. The rows are fetched in chunks while they
are sent: the memory a page costs does not grow with its length.

A cursor is the key of the last row of the previous page (never an offset: rows committed or
deleted meanwhile do not shift the next page), tagged with its list so the cursor of one list is
refused by another, and opaque to clients (base64url of a small JSON array).
"""

from __future__ import annotations

import base64
import binascii
import json
import sqlite3
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol, TypeVar

from contract import MAX_PAGE, Page

__all__ = ["CHUNK_ROWS", "KeysetList", "decode_cursor", "encode_cursor", "open_page"]

T = TypeVar("T")
Q = TypeVar("Q", contravariant=True)

#: rows fetched from SQLite at a time while a page streams
CHUNK_ROWS = 2000


class KeysetList(Protocol[Q]):
    """A stored list in a fixed order, read through one connection (a repository implements it
    for each of its lists). ``after``: the key of the row a page starts after (None: the first)."""

    name: str

    def count(self, query: Q, after: tuple | None) -> int:
        """How many rows match ``query`` after ``after``."""
        ...

    def key_at(self, query: Q, after: tuple | None, offset: int) -> tuple | None:
        """The key of the row ``offset`` rows (0-based) after ``after``, None past the end."""
        ...

    def chunks(self, query: Q, after: tuple | None, limit: int) -> Iterator[list[Any]]:
        """At most ``limit`` rows after ``after``, in chunks of documents."""
        ...


def encode_cursor(name: str, key: Sequence[Any]) -> str:
    raw = json.dumps([name, *key], separators=(",", ":"), allow_nan=False).encode()
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def decode_cursor(name: str, cursor: str | None, types: Sequence[type]) -> tuple | None:
    """The key a cursor of the list ``name`` holds; ``ValueError`` naming it when it is not one
    this service issued for that list."""
    if cursor is None or cursor == "":
        return None
    wrong = ValueError(f"cursor {cursor[:80]!r} is not a cursor of this service's {name} (pass the next_cursor of "
                       f"the previous page unchanged)")
    try:
        value = json.loads(base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode())
    except (binascii.Error, UnicodeDecodeError, ValueError):
        raise wrong from None
    if not isinstance(value, list) or len(value) != len(types) + 1 or value[0] != name:
        raise wrong
    key = value[1:]
    for item, kind in zip(key, types):
        ok = isinstance(item, (int, float)) and not isinstance(item, bool) if kind is float else type(item) is kind
        if not ok:
            raise wrong
    return tuple(float(k) if kind is float else k for k, kind in zip(key, types))


def open_page(connect: Callable[[], tuple[sqlite3.Connection, Callable[[], None]]], stored: KeysetList[Any],
              query: Any, *, limit: int, after: tuple | None) -> Page[Any]:
    """A page of ``stored`` after the key ``after``: counted and bounded in one read transaction
    of the connection ``connect()`` returns (with how to release it), its rows streamed from it."""
    if not 1 <= limit <= MAX_PAGE:
        raise ValueError(f"limit={limit} must lie within 1..{MAX_PAGE}")
    db, release = connect()
    try:
        db.execute("BEGIN")  # one snapshot for the counts and the rows
        total = stored.count(query, None)
        remaining = total if after is None else stored.count(query, after)
        truncated = remaining > limit
        last = stored.key_at(query, after, limit - 1) if truncated else None
    except BaseException:
        _end(db, release)
        raise
    stream = _Stream(db, release, stored.chunks(query, after, limit))
    return Page(items=iter(stream), count=min(limit, remaining), total=total, truncated=truncated,
                next_cursor=None if last is None else encode_cursor(stored.name, last), close=stream.close)


def _end(db: sqlite3.Connection, release: Callable[[], None]) -> None:
    try:
        if db.in_transaction:
            db.execute("COMMIT")
    except sqlite3.Error:
        pass
    release()


class _Stream:
    """The rows of a page, one item at a time, and the end of its read transaction when they are
    all read or the page is closed (a client that went away), whichever comes first."""

    def __init__(self, db: sqlite3.Connection, release: Callable[[], None], chunks: Iterator[list[Any]]) -> None:
        self._db = db
        self._release = release
        self._chunks = chunks
        self._open = True

    def __iter__(self) -> Iterator[Any]:
        try:
            for chunk in self._chunks:
                yield from chunk
        finally:
            self.close()

    def close(self) -> None:
        if self._open:
            self._open = False
            _end(self._db, self._release)
