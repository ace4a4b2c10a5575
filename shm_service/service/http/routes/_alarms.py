"""``/api/alarms`` (paged, newest first), acknowledging one, and ``/api/structures/{id}/alarms``."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request
from fastapi.responses import StreamingResponse

from contract import AlarmDocument, AlarmsDocument, ServicePort

from .._deps import require_token, service_port, token_of
from .._common import AUTH_RESPONSES, INVALID, STRUCTURE_ID, UNKNOWN, error, of_structure
from .._pages import PageParams, open_or_422, page_response

__all__ = ["router"]

router = APIRouter(tags=["alarms"])

_STATE = Query(None, description="only alarms in this state")


@router.get("/api/alarms", summary="alarms, newest first, paged", response_model=AlarmsDocument,
            responses={**AUTH_RESPONSES, **INVALID})
def alarms(request: Request, state: Literal["active", "cleared"] | None = _STATE, paging: PageParams = Depends(),
           port: ServicePort = Depends(service_port)) -> StreamingResponse:
    page = open_or_422(port.alarms_page, state, limit=paging.limit, cursor=paging.cursor)
    return page_response(request, page, key="alarms")


@router.post("/api/alarms/{alarm_id}/ack", summary="acknowledge an alarm (token required)", response_model=AlarmDocument,
             responses={**AUTH_RESPONSES, **INVALID, 404: error("no such alarm")}, dependencies=[Depends(require_token)])
def acknowledge(request: Request, alarm_id: int = Path(..., ge=1, le=2**62),
                port: ServicePort = Depends(service_port)) -> AlarmDocument:
    try:
        return port.acknowledge(alarm_id, token_of(request) or "", by="api")
    except KeyError:
        raise HTTPException(404, f"alarm {alarm_id} does not exist") from None
    except PermissionError as exc:
        raise HTTPException(401, str(exc)) from None


@router.get("/api/structures/{structure_id}/alarms", summary="one structure's alarms, newest first, paged",
            response_model=AlarmsDocument, responses={**AUTH_RESPONSES, **INVALID, **UNKNOWN})
def structure_alarms(request: Request, structure_id: str = STRUCTURE_ID,
                     state: Literal["active", "cleared"] | None = _STATE, paging: PageParams = Depends(),
                     port: ServicePort = Depends(service_port)) -> StreamingResponse:
    page = open_or_422(of_structure, port.structure_alarms_page, structure_id, state, limit=paging.limit,
                       cursor=paging.cursor)
    return page_response(request, page, key="alarms")
