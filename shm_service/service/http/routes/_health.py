"""The service itself: liveness (``/healthz``), its status (``/api/status``) and the Prometheus
exposition (``/metrics``)."""

from __future__ import annotations

from fastapi import APIRouter, Depends
from fastapi.responses import PlainTextResponse

from contract import HealthDocument, ServicePort, StatusDocument

from .._deps import service_port
from .._common import AUTH_RESPONSES
from .._metrics import metrics_text

__all__ = ["router"]

router = APIRouter(tags=["service"])


@router.get("/healthz", summary="liveness: 'degraded' while the pipeline's batches fail", response_model=HealthDocument,
            responses=AUTH_RESPONSES)
def healthz(port: ServicePort = Depends(service_port)) -> HealthDocument:
    return port.health()


@router.get("/api/status", summary="sources, rates, latency, dropped and rejected samples, degraded sensors",
            response_model=StatusDocument, responses=AUTH_RESPONSES)
def status(port: ServicePort = Depends(service_port)) -> StatusDocument:
    return port.status()


@router.get("/metrics", summary="Prometheus metrics (text format); of a fleet, per structure (label structure)",
            response_class=PlainTextResponse,
            responses={**AUTH_RESPONSES, 200: {"content": {"text/plain": {"schema": {"type": "string"}}}}})
def metrics(port: ServicePort = Depends(service_port)) -> PlainTextResponse:
    return PlainTextResponse(metrics_text(port), media_type="text/plain; version=0.0.4; charset=utf-8")
