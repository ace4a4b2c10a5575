"""The structures of a service and what each holds live: ``/api/structures`` and, per
structure, its status, spectra, rig, live estimates and a new baseline; the single-structure
forms ``/api/spectra/latest`` and ``/api/baseline`` (a service of one structure)."""

from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException, Query

from contract import (
    BaselineRequestDocument,
    LiveEstimatesDocument,
    RigDescription,
    ServicePort,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
)

from ._deps import require_token, service_port
from ._http_common import AUTH_RESPONSES, INVALID, STRUCTURE_ID, UNKNOWN, error, of_structure

__all__ = ["router"]

router = APIRouter(tags=["structures"])


@router.get("/api/structures", summary="every structure: state, lag, committed windows, active alarms",
            response_model=StructuresDocument, responses=AUTH_RESPONSES)
def structures(port: ServicePort = Depends(service_port)) -> StructuresDocument:
    return port.structures_document()


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


@router.get("/api/structures/{structure_id}/spectra/latest",
            summary="amplitude spectra of b of the structure's latest window",
            response_model=SpectrumDocument, responses={**AUTH_RESPONSES, **UNKNOWN})
def structure_spectra(structure_id: str = STRUCTURE_ID, port: ServicePort = Depends(service_port)) -> SpectrumDocument:
    spec = of_structure(port.spectra, structure_id)
    if spec is None:
        raise HTTPException(404, f"structure {structure_id!r} has no analysis window yet")
    return spec


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
