"""The HTTP API (FastAPI), built by ``create_app(service)``. Handlers are thin: they validate
parameters and call the service (storage, analytics). Errors are HTTPExceptions with a detail.

Authentication: ``Authorization: Bearer <token>`` (or ``X-SHM-Token``). Ingest, acknowledge
and baseline changes always need the token (403 when none is configured, 401 when missing or
wrong); on a non-loopback address every request needs it, the API documents (``/docs``, ``/redoc``,
``/openapi.json``) included; a browser may send it as the password of HTTP Basic. Wrong tokens
are rate-limited per client address (429). The ``Host`` header is checked against loopback,
the bound address and ``server.allowed_hosts`` (421), against DNS rebinding. Request bodies are
size-limited (413), chunked ones too.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterable
from contextlib import asynccontextmanager
from typing import Any

from fastapi import Depends, FastAPI, Request
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from contract import NotSingleStructure, ServicePort, ServiceStarting

from .routes import ROUTERS
from ._deps import everyone
from ._docs import serve_docs_offline
from ._gate import AuthLimiter, Gate, HostCheck
from ._metrics import _metrics  # noqa: F401  (one structure's exposition, for the tests)
from ..storage._storage import StorageUnavailable

__all__ = ["ApiService", "AuthLimiter", "HostCheck", "ROUTERS", "create_app"]


#: what the API needs from the service: the runtime's port (``MonitoringService`` and the
#: ``WorkerFleet`` implement it)
ApiService = ServicePort

#: the resources of the API, one router each, in the order of the documents


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """The app's life: with ``start_port``, it starts its port before it serves and stops it after
    (an app embedded in any ASGI server owns its service); ``shm serve`` starts its service itself
    (the API answers "starting" meanwhile) and builds the app without."""
    if app.state.start_port:
        await run_in_threadpool(app.state.port.start)
    try:
        yield
    finally:
        if app.state.start_port:
            await run_in_threadpool(app.state.port.stop)


def create_app(service: ApiService, *, loopback: bool = True, max_body_bytes: int = 64 * 1024,
               max_ingest_bytes: int = 8 * 1024 * 1024, host: str = "127.0.0.1", allowed_hosts: Iterable[str] = (),
               check_host: bool = True, auth_failures_per_minute: int = 10, start_port: bool = False) -> FastAPI:
    """The API of ``service``, bound at ``host``. ``loopback=False`` requires the token for every
    request, the API documents included. ``Host`` headers other than loopback, ``host`` and
    ``allowed_hosts`` are refused (421); more than ``auth_failures_per_minute`` wrong tokens from
    one address are answered 429 for the rest of the minute. ``start_port``: the app's lifespan
    starts and stops ``service``."""
    app = FastAPI(title="shm serve", version="0.1.0", lifespan=lifespan, dependencies=[Depends(everyone)],
                  description="Structural health monitoring service: status, modal trends, alarms, spectra, ingest.")
    app.state.port, app.state.loopback, app.state.start_port = service, loopback, start_port
    app.state.auth_limiter = limiter = AuthLimiter(auth_failures_per_minute, 60.0)
    serve_docs_offline(app)  # /docs and /redoc from the installed packages, not a CDN
    for router in ROUTERS:
        app.include_router(router)
    app.add_exception_handler(ServiceStarting, _answer(503, "{}", retry_after="5"))
    # the database stayed locked (another process) or failing for the storage's retry period
    app.add_exception_handler(StorageUnavailable, _answer(503, "the database is unavailable for now ({}); retry later",
                                                          retry_after="5"))
    app.add_exception_handler(NotSingleStructure, _answer(409, "{}"))
    app.add_middleware(Gate, default=max_body_bytes, ingest=max_ingest_bytes,
                       hosts=HostCheck(host, allowed_hosts) if check_host else None,
                       check_token=None if loopback else (lambda token: service.check_token(token)), limiter=limiter)
    return app


def _answer(status: int, detail: str, *, retry_after: str | None = None) -> Any:
    """An exception handler answering ``status`` with ``detail`` (``{}``: the exception's text)."""
    headers = {"Retry-After": retry_after} if retry_after is not None else None

    async def handler(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": detail.format(exc)}, status_code=status, headers=headers)

    return handler
