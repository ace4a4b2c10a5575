"""What the routers share: the documented error answers, time parameters, a structure's id and
how a structure's errors become HTTP answers."""

from __future__ import annotations

import math
from collections.abc import Callable
from datetime import datetime
from typing import Any, TypeVar

from fastapi import HTTPException, Path

from contract import ErrorDocument, StructureUnavailable

__all__ = ["AUTH_RESPONSES", "CSV_RESPONSE", "INVALID", "STRUCTURE_ID", "UNKNOWN", "error", "of_structure", "parse_time",
           "time_range"]

T = TypeVar("T")


def error(description: str) -> dict[str, Any]:
    return {"model": ErrorDocument, "description": description}


AUTH_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: error("no or a malformed Host header"),
    401: error("missing or wrong token"),
    403: error("no token is configured: the action is disabled"),
    413: error("request body over the limit"),
    421: error("the Host header names a host this server does not answer for (server.allowed_hosts)"),
    429: error("too many wrong tokens from this address: retry after Retry-After seconds"),
    503: error("the database is unavailable for now (locked by another process, disk full): retry later"),
}
#: Our own 422s say in a sentence what is wrong with a parameter; FastAPI's list what does not parse.
INVALID: dict[int | str, dict[str, Any]] = {422: error("a parameter is invalid")}
CSV_RESPONSE: dict[int | str, dict[str, Any]] = {200: {"content": {"text/csv": {"schema": {"type": "string"}}}}}
UNKNOWN: dict[int | str, dict[str, Any]] = {404: error("no such structure (the message names it)"),
                                            409: error("the structure failed to start (the message says why)")}
STRUCTURE_ID = Path(..., min_length=1, max_length=64, description="structure id ([a-z0-9-])")


def parse_time(name: str, value: str | None) -> float | None:
    """A time parameter: UNIX seconds or ISO 8601 with a zone; 422 naming it otherwise."""
    if value is None or value == "":
        return None
    try:
        x = float(value)
    except ValueError:
        try:
            dt = datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            raise HTTPException(422, f"'{name}' must be UNIX seconds or an ISO 8601 time, got {value[:40]!r}") from None
        if dt.tzinfo is None:
            raise HTTPException(422, f"'{name}' needs a time zone (e.g. 2026-01-01T00:00:00Z)") from None
        x = dt.timestamp()
    if not math.isfinite(x) or not -1e11 < x < 1e11:
        raise HTTPException(422, f"'{name}' = {value[:40]!r} is out of range")
    return x


def time_range(from_: str | None, to: str | None) -> tuple[float | None, float | None]:
    lo, hi = parse_time("from", from_), parse_time("to", to)
    if lo is not None and hi is not None and lo > hi:
        raise HTTPException(422, f"'from' ({lo}) is after 'to' ({hi})")
    return lo, hi


def of_structure(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(...)`` of one structure: an unknown id is 404, a structure that cannot answer 409."""
    try:
        return fn(*args, **kwargs)
    except KeyError as exc:
        raise HTTPException(404, exc.args[0] if exc.args else str(exc)) from None
    except StructureUnavailable as exc:
        raise HTTPException(409, str(exc)) from None
