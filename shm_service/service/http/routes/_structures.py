"""The structures of a service and what each holds live: ``/api/structures`` and, per
structure, its status, spectra, rig, live estimates and a new baseline; the single-structure
forms ``/api/spectra/latest`` and ``/api/baseline`` (a service of one structure)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from fastapi import APIRouter, Depends, HTTPException, Query, Response

from contract import (
    BaselineRequestDocument,
    LiveEstimatesDocument,
    RigDescription,
    ServicePort,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
    WindowDocument,
)

from .._deps import require_token, service_port
from .._common import AUTH_RESPONSES, INVALID, STRUCTURE_ID, UNKNOWN, error, of_structure
from .._pages import PageParams
from ...storage._paging import decode_cursor, encode_cursor

__all__ = ["router"]

T = TypeVar("T")

router = APIRouter(tags=["structures"])


@router.get("/api/structures", summary="every structure: state, lag, committed windows, active alarms; paged",
            response_model=StructuresDocument, responses={**AUTH_RESPONSES, **INVALID})
def structures(response: Response, paging: PageParams = Depends(),
               port: ServicePort = Depends(service_port)) -> StructuresDocument:
    listed = port.structures_document().structures
    start = 0
    if paging.cursor is not None:
        try:
            (after,) = decode_cursor("structures", paging.cursor, (str,)) or ("",)
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None
        ids = [s.id for s in listed]
        if after not in ids:
            raise HTTPException(422, f"cursor names structure {after!r}, which this service no longer lists")
        start = ids.index(after) + 1
    page = listed[start:start + paging.limit]
    truncated = start + len(page) < len(listed)
    next_cursor = encode_cursor("structures", [page[-1].id]) if truncated and page else None
    response.headers.update({"X-Count": str(len(page)), "X-Total-Count": str(len(listed)),
                             "X-Truncated": "true" if truncated else "false"})
    if next_cursor is not None:
        response.headers["X-Next-Cursor"] = next_cursor
    return StructuresDocument(structures=page, count=len(page), total=len(listed), truncated=truncated,
                              next_cursor=next_cursor)


@router.get("/api/structures/{structure_id}/status", summary="one structure's status (as /api/status)",
            response_model=StatusDocument, responses={**AUTH_RESPONSES, **UNKNOWN})
def structure_status(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> StatusDocument:
    return of_structure(port.status, structure_id)


@router.get("/api/spectra/latest", summary="amplitude spectra of b of the latest window", response_model=SpectrumDocument,
            responses={**AUTH_RESPONSES, 404: error("no window analysed yet")})
def spectra(port: ServicePort = Depends(service_port)) -> SpectrumDocument:
    spec = port.spectra()
    if spec is None:
        raise HTTPException(404, "no analysis window yet")
    return spec


def _latest_or_404(read: Callable[[str], T | None], structure_id: str) -> T:
    """What ``read`` holds of the structure's latest window; 404 (unknown structure, or no window yet)."""
    latest = of_structure(read, structure_id)
    if latest is None:
        raise HTTPException(404, f"structure {structure_id!r} has no analysis window yet")
    return latest


@router.get("/api/structures/{structure_id}/spectra/latest",
            summary="amplitude spectra of b of the structure's latest window",
            response_model=SpectrumDocument, responses={**AUTH_RESPONSES, **UNKNOWN})
def structure_spectra(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> SpectrumDocument:
    return _latest_or_404(port.spectra, structure_id)


@router.get("/api/structures/{structure_id}/windows/latest", summary="the structure's latest committed analysis window",
            response_model=WindowDocument, responses={**AUTH_RESPONSES, **UNKNOWN})
def structure_window(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> WindowDocument:
    return _latest_or_404(port.structure_window, structure_id)


@router.get("/api/structures/{structure_id}/rig", summary="the rig the structure is monitored with (rig.json)",
            response_model=RigDescription, responses={**AUTH_RESPONSES, **UNKNOWN})
def structure_rig(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> RigDescription:
    return of_structure(port.structure_rig, structure_id)


@router.get("/api/structures/{structure_id}/live",
            summary="the structure's newest state estimates (about 10 per second of data) for a live view",
            description="A read makes the structure keep its newest estimates for `watch_s` more seconds (nothing is "
                        "kept for a structure nobody reads); poll with `after` = the last `seq` seen.",
            response_model=LiveEstimatesDocument, responses={**AUTH_RESPONSES, **INVALID, **UNKNOWN})
def structure_live(structure_id: str = STRUCTURE_ID,
                   after: int = Query(0, ge=0, le=2**62, description="only estimates after this seq"),
                   port: ServicePort = Depends(service_port)) -> LiveEstimatesDocument:
    return of_structure(port.live, structure_id, after)


@router.post("/api/baseline", summary="start learning a new baseline (token required)", status_code=202,
             response_model=BaselineRequestDocument, responses=AUTH_RESPONSES, dependencies=[Depends(require_token)])
def baseline(port: ServicePort = Depends(service_port)) -> BaselineRequestDocument:
    return port.request_baseline()


@router.post("/api/structures/{structure_id}/baseline",
             summary="start learning a new baseline of the structure (token required)", status_code=202,
             response_model=BaselineRequestDocument, responses={**AUTH_RESPONSES, **UNKNOWN},
             dependencies=[Depends(require_token)])
def structure_baseline(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> BaselineRequestDocument:
    return of_structure(port.request_baseline, structure_id)
