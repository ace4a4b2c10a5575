"""Ingest: ``POST /api/ingest`` and ``POST /api/structures/{id}/ingest`` take a batch of samples
in the recording format (token required). The body is validated by hand (``sources._ingest.parse_body``:
every message, with counted rejections); its documented schema types each payload by its topic."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from contract import IngestResultDocument, ServicePort

from .._deps import require_token, service_port
from .._common import AUTH_RESPONSES, STRUCTURE_ID, UNKNOWN, error, of_structure
from ...sources._ingest import IngestError, parse_body

__all__ = ["INGEST_BODY", "router"]

router = APIRouter(tags=["ingest"], dependencies=[Depends(require_token)])


def ingest_message(topic: dict[str, Any], title: str) -> dict[str, Any]:
    """One ingest message of the sensor topics ``topic`` matches, its payload typed by the
    recording contract's JSON schema ``title`` (the schema a recording's channel carries)."""
    from contract import SCHEMAS

    payload = {k: v for k, v in SCHEMAS[title].items() if k != "$schema"}
    return {"type": "object", "title": f"{title} message", "required": ["topic", "log_time_ns", "payload"],
            "properties": {"topic": {"type": "string", **topic},
                           "log_time_ns": {"type": "integer", "minimum": 0},
                           "publish_time_ns": {"type": "integer", "minimum": 0},
                           "payload": payload}}


#: The documented body of both ingest routes (validated by hand: see ``sources._ingest``): each message's
#: payload typed by its topic, as the recording contract defines it.
INGEST_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "required": ["messages"], "additionalProperties": False,
    "properties": {"messages": {"type": "array", "items": {"oneOf": [
        ingest_message({"pattern": "^/imu/[^/]+$", "examples": ["/imu/D"]}, "shm.Imu"),
        ingest_message({"pattern": "^(/tof/[^/]+|/bearing/displacement)$", "examples": ["/tof/s1"]}, "shm.Distance"),
        ingest_message({"pattern": "^/strain/[^/]+$", "examples": ["/strain/g1"]}, "shm.Strain"),
        ingest_message({"enum": ["/env/temperature"]}, "shm.Temperature"),
    ]}}}}}}}}


_FULL = {"detail": "the pipeline is full; retry later (nothing of this request was taken)"}


async def _take(request: Request, port: ServicePort, structure_id: str | None) -> IngestResultDocument | JSONResponse:
    body = await request.body()
    try:
        document = parse_body(body)
    except IngestError as exc:
        raise HTTPException(400, str(exc)) from None
    try:
        if structure_id is None:
            result = await run_in_threadpool(port.ingest, document)
        else:
            result = await run_in_threadpool(of_structure, port.ingest, document, structure_id)
    except IngestError as exc:
        raise HTTPException(400, str(exc)) from None
    except LookupError as exc:
        raise HTTPException(409, str(exc)) from None
    if result is None:
        return JSONResponse(_FULL, status_code=503, headers={"Retry-After": "1"})
    return result


@router.post("/api/ingest", summary="ingest a batch of samples in the recording format (token required)",
             response_model=IngestResultDocument,
             responses={**AUTH_RESPONSES, 400: error("body is not a valid batch"), 409: error("source is not ingest"),
                        413: error("body too large"), 503: error("pipeline full, retry later")},
             openapi_extra=INGEST_BODY)
async def ingest(request: Request, port: ServicePort = Depends(service_port)) -> IngestResultDocument | JSONResponse:
    return await _take(request, port, None)


@router.post("/api/structures/{structure_id}/ingest", summary="ingest a batch of samples for the structure (token required)",
             response_model=IngestResultDocument,
             responses={**AUTH_RESPONSES, **UNKNOWN, 400: error("body is not a valid batch"),
                        409: error("the structure's source is not ingest, or it failed to start"),
                        413: error("body too large"), 503: error("pipeline full, retry later")},
             openapi_extra=INGEST_BODY)
async def structure_ingest(request: Request, structure_id: str = STRUCTURE_ID,
                           port: ServicePort = Depends(service_port)) -> IngestResultDocument | JSONResponse:
    # 404/409 before the body is read: its rig is the port's cheapest read that finds it by id
    await run_in_threadpool(of_structure, port.structure_rig, structure_id)
    return await _take(request, port, structure_id)
