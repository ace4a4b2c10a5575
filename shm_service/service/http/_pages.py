"""The paging convention of every list route (an export says what it holds).

Query: ``limit`` (default 1000, at most ``contract.MAX_PAGE``) and ``cursor`` (the
``next_cursor`` of the previous page, opaque). JSON: the list under its key, ``count`` (in this
page), ``total`` (matching the query), ``truncated`` (more follow) and ``next_cursor`` (null on
the last page). CSV: the same in the headers ``X-Count``, ``X-Total-Count``, ``X-Truncated`` and
``X-Next-Cursor``. Both carry ``Link: <url of the next page>; rel="next"`` while more follow.

Both are streamed: the rows are read from the database in chunks while they are sent, so a page
of a million rows costs the server about one chunk of memory, not the whole answer.
"""

from __future__ import annotations

import csv
import functools
import io
import itertools
import json
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from fastapi import HTTPException, Query, Request
from fastapi.responses import StreamingResponse
from pydantic import BaseModel, TypeAdapter

from contract import MAX_PAGE, Page

__all__ = ["PageParams", "page_headers", "page_response"]

log = logging.getLogger("shm.serve.api")

#: documents serialised and sent at a time
_BATCH = 2000


@dataclass(frozen=True)
class PageParams:
    """``limit`` and ``cursor`` of a list route (a dependency: ``Depends(PageParams)``)."""

    limit: int = Query(1000, ge=1, le=MAX_PAGE, description=f"most items in this page (1..{MAX_PAGE})")
    cursor: str | None = Query(None, min_length=1, max_length=512,
                               description="next_cursor of the previous page (omit for the first page)")


def open_or_422(fn: Any, *args: Any, **kwargs: Any) -> Page[Any]:
    """``fn(...)`` that opens a page: a cursor it refuses (``ValueError``) is a 422 naming it."""
    try:
        return fn(*args, **kwargs)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None


def page_headers(request: Request, page: Page[Any]) -> dict[str, str]:
    headers = {"X-Count": str(page.count), "X-Total-Count": str(page.total),
               "X-Truncated": "true" if page.truncated else "false"}
    if page.next_cursor is not None:
        headers["X-Next-Cursor"] = page.next_cursor
        headers["Link"] = f'<{request.url.include_query_params(cursor=page.next_cursor)}>; rel="next"'
    return headers


def page_response(request: Request, page: Page[Any], *, key: str, format: Literal["json", "csv"] = "json",
                  fields: Sequence[str] = (), filename: str = "export.csv") -> StreamingResponse:
    """The page as a streamed JSON document (``{key: [...], count, total, truncated,
    next_cursor}``) or CSV (columns ``fields``, the counts in the headers)."""
    headers = page_headers(request, page)
    if format == "csv":
        headers["Content-Disposition"] = f'attachment; filename="{filename}"'
        return StreamingResponse(_csv(page, fields), media_type="text/csv; charset=utf-8", headers=headers)
    if format == "json":
        return StreamingResponse(_json(page, key), media_type="application/json", headers=headers)
    raise ValueError(f"format={format!r} must be 'json' or 'csv'")


def _batches(page: Page[Any]) -> Iterator[list[Any]]:
    """The page's items in batches; the page is closed however the sending ends (a client that
    went away closes this generator)."""
    try:
        items = iter(page.items)
        while batch := list(itertools.islice(items, _BATCH)):
            yield batch
    except Exception:
        log.exception("a streamed page failed while it was sent (the client gets a cut answer)")
        raise
    finally:
        page.close()


def _json(page: Page[Any], key: str) -> Iterator[bytes]:
    yield b'{"' + key.encode() + b'":['
    first = True
    for batch in _batches(page):
        body = _dump(batch)[1:-1]  # the items of a JSON array
        yield body if first else b"," + body
        first = False
    tail = {"count": page.count, "total": page.total, "truncated": page.truncated, "next_cursor": page.next_cursor}
    yield b"]," + json.dumps(tail, separators=(",", ":")).encode()[1:]


@functools.lru_cache(maxsize=16)
def _adapter(kind: type) -> TypeAdapter[Any]:
    return TypeAdapter(list[kind])  # type: ignore[valid-type]


def _dump(batch: list[Any]) -> bytes:
    """A batch of documents as a JSON array, serialised in one call."""
    if isinstance(batch[0], BaseModel):
        return _adapter(type(batch[0])).dump_json(batch)
    return json.dumps(batch, allow_nan=False, separators=(",", ":")).encode()


def _csv(page: Page[Any], fields: Sequence[str]) -> Iterator[bytes]:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(fields)
    for batch in _batches(page):
        for item in batch:
            writer.writerow([getattr(item, f) for f in fields] if isinstance(item, BaseModel) else
                            [item[f] for f in fields])  # None is written as an empty cell
        yield buf.getvalue().encode()
        buf.seek(0)
        buf.truncate()
    if buf.tell():
        yield buf.getvalue().encode()
