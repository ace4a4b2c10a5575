"""``GET /api/fatigue`` and ``GET /api/structures/{id}/fatigue``: the hot spots' loads and life
 as a typed ``FatigueDocument`` (JSON) or one CSV row per window and hot spot."""

from __future__ import annotations

import csv
import io
from typing import Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response

from contract import FatigueDocument, ServicePort, StructureUnavailable

from .._common import AUTH_RESPONSES as _AUTH_RESPONSES, INVALID as _INVALID, error as _error, parse_time as _parse_time
from .._deps import service_port

__all__ = ["router", "fatigue_csv"]

router = APIRouter(tags=["fatigue"])

_CSV: dict[int | str, dict[str, Any]] = {200: {"content": {"text/csv": {"schema": {"type": "string"}}}}}
_UNKNOWN: dict[int | str, dict[str, Any]] = {404: _error("no such structure (the message names it)"),
            409: _error("the structure failed to start, or (/api/fatigue) the service monitors a fleet: ask per structure")}
_COLUMNS = ("structure_id", "window_start_s", "duration_s", "temperature_c", "hot_spot", "position_m", "curve", "n_eq",
            "max_range_pa", "damage_increment", "consumed", "rate_per_year", "remaining_years", "verdict", "design_life_years")


def fatigue_csv(doc: FatigueDocument) -> str:
    """One row per window and hot spot, oldest first; a ``del_m{m}_pa`` column per Wöhler exponent."""
    exponents = sorted({m for w in doc.windows for h in w.hot_spots for m in h.del_pa}, key=float)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*_COLUMNS[:8], *(f"del_m{m}_pa" for m in exponents), *_COLUMNS[8:]])
    for w in doc.windows:
        for h in w.hot_spots:
            writer.writerow([doc.structure_id, w.start_s, w.duration_s, w.temperature_c, h.name, h.position_m, h.curve, h.n_eq,
                             *(h.del_pa.get(m) for m in exponents), h.max_range_pa, h.damage_increment, h.consumed,
                             h.rate_per_year, h.remaining_years, h.verdict, h.design_life_years])
    return buf.getvalue()


def _answer(doc: FatigueDocument, format: str, name: str) -> Any:
    if format == "csv":
        return Response(fatigue_csv(doc), media_type="text/csv",
                        headers={"Content-Disposition": f'attachment; filename="{name}.csv"', "X-Count": str(len(doc.windows)),
                                 "X-Total-Count": str(doc.total), "X-Truncated": "true" if doc.truncated else "false"})
    if format == "json":
        return doc
    raise HTTPException(422, f"format={format!r} must be json or csv")


def _period(from_: str | None, to: str | None) -> tuple[float | None, float | None]:
    lo, hi = _parse_time("from", from_), _parse_time("to", to)
    if lo is not None and hi is not None and lo > hi:
        raise HTTPException(422, f"'from' ({lo}) is after 'to' ({hi})")
    return lo, hi


def _call(fn: Any, *args: Any) -> FatigueDocument:
    try:
        return fn(*args)
    except KeyError as exc:
        raise HTTPException(404, exc.args[0] if exc.args else str(exc)) from None
    except StructureUnavailable as exc:
        raise HTTPException(409, str(exc)) from None


_FROM = Query(None, alias="from", max_length=64, description="UNIX s or ISO 8601 (inclusive): windows starting then or later")
_TO = Query(None, max_length=64, description="UNIX s or ISO 8601 (exclusive)")
_FORMAT = Query("json", description="json (FatigueDocument) or csv (one row per window and hot spot)")
_LIMIT = Query(1000, ge=1, le=100_000, description="most windows returned (oldest first; truncated says when more match)")


@router.get("/api/fatigue", summary="the single structure's hot spots: consumed life, remaining life, DEL trend, strain envelope",
            response_model=FatigueDocument, responses={**_AUTH_RESPONSES, **_INVALID, **_UNKNOWN, **_CSV})
def fatigue(from_: str | None = _FROM, to: str | None = _TO, format: Literal["json", "csv"] = _FORMAT, limit: int = _LIMIT,
            port: ServicePort = Depends(service_port)) -> Any:
    lo, hi = _period(from_, to)
    doc = _call(port.fatigue, None, lo, hi, limit)
    return _answer(doc, format, "fatigue")


@router.get("/api/structures/{structure_id}/fatigue", summary="one structure's hot spots (as /api/fatigue)",
            response_model=FatigueDocument, responses={**_AUTH_RESPONSES, **_INVALID, **_UNKNOWN, **_CSV})
def structure_fatigue(structure_id: str = Path(..., min_length=1, max_length=64, description="structure id ([a-z0-9-])"),
                      from_: str | None = _FROM, to: str | None = _TO, format: Literal["json", "csv"] = _FORMAT,
                      limit: int = _LIMIT, port: ServicePort = Depends(service_port)) -> Any:
    lo, hi = _period(from_, to)
    doc = _call(port.structure_fatigue, structure_id, lo, hi, limit)
    return _answer(doc, format, f"fatigue-{structure_id}")
