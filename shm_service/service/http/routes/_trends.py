"""``/api/trends`` and ``/api/structures/{id}/trends``: the modal trend export, one row per
window and mode, paged with a cursor and streamed (``http._pages``)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import StreamingResponse

from contract import ServicePort, TrendRow, TrendsDocument

from .._deps import service_port
from .._common import AUTH_RESPONSES, CSV_RESPONSE, INVALID, STRUCTURE_ID, UNKNOWN, of_structure, time_range
from .._pages import PageParams, open_or_422, page_response

__all__ = ["router"]

router = APIRouter(tags=["trends"])

_FIELDS = tuple(TrendRow.model_fields)
_FROM = Query(None, alias="from", max_length=64, description="UNIX s or ISO 8601 (inclusive)")
_TO = Query(None, max_length=64, description="UNIX s or ISO 8601 (exclusive)")
_MODE = Query(None, ge=1, le=20, description="mode number (1-based)")
_FORMAT = Query("json", description="json or csv (the counts then in the X-Count, X-Total-Count, X-Truncated and "
                                    "X-Next-Cursor headers)")


@router.get("/api/trends", summary="the modal trend export (one row per window and mode), paged",
            response_model=TrendsDocument, responses={**AUTH_RESPONSES, **INVALID, **CSV_RESPONSE})
def trends(request: Request, from_: str | None = _FROM, to: str | None = _TO, mode: int | None = _MODE,
           source: str | None = Query(None, min_length=1, max_length=200, description="source id"),
           format: Literal["json", "csv"] = _FORMAT, paging: PageParams = Depends(),
           port: ServicePort = Depends(service_port)) -> Any:
    lo, hi = time_range(from_, to)
    page = open_or_422(port.trends_page, lo, hi, mode=mode, source=source, limit=paging.limit, cursor=paging.cursor)
    return page_response(request, page, key="rows", format=format, fields=_FIELDS, filename="trends.csv")


@router.get("/api/structures/{structure_id}/trends", summary="one structure's modal trends (as /api/trends)",
            response_model=TrendsDocument, responses={**AUTH_RESPONSES, **INVALID, **UNKNOWN, **CSV_RESPONSE})
def structure_trends(request: Request, structure_id: str = STRUCTURE_ID, from_: str | None = _FROM, to: str | None = _TO,
                     mode: int | None = _MODE, format: Literal["json", "csv"] = _FORMAT, paging: PageParams = Depends(),
                     port: ServicePort = Depends(service_port)) -> StreamingResponse:
    lo, hi = time_range(from_, to)
    page = open_or_422(of_structure, port.structure_trends_page, structure_id, lo, hi, mode=mode, limit=paging.limit,
                       cursor=paging.cursor)
    return page_response(request, page, key="rows", format=format, fields=_FIELDS, filename=f"trends-{structure_id}.csv")
