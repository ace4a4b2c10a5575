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

import csv
import io
import ipaddress
import math
import re
import threading
import time
from collections.abc import Callable, Iterable
from datetime import datetime
from typing import Any, Literal

from fastapi import Depends, FastAPI, HTTPException, Path, Query, Request
from fastapi.responses import JSONResponse, PlainTextResponse, Response

from contract import (
    AlarmDocument,
    AlarmsDocument,
    BaselineRequestDocument,
    ErrorDocument,
    HealthDocument,
    IngestResultDocument,
    LiveEstimatesDocument,
    RigDescription,
    ServicePort,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
    TrendRow,
    TrendsDocument,
    WindowDocument,
)

from ._docs import serve_docs_offline
from ._metrics import _metrics, metrics_text  # noqa: F401  (_metrics: one structure's exposition, for the tests)
from ._ingest import IngestError, parse_body
from ._starting import ServiceStarting
from ._storage import StorageUnavailable

__all__ = ["ApiService", "AuthLimiter", "HostCheck", "create_app"]


#: what the API needs from the service: the runtime's port (``MonitoringService`` and the
#: ``WorkerFleet`` implement it)
ApiService = ServicePort


_TREND_FIELDS = tuple(TrendRow.model_fields)


class AuthLimiter:
    """Failed token attempts per client address: after ``max_failures`` wrong tokens within
    ``window_s`` the address is refused (429, ``Retry-After``) until the oldest failure leaves
    the window, whatever it sends meanwhile (a right guess would not be told apart). A missing
    token is not a guess and is not counted. At most ``max_clients`` addresses are remembered
    (the oldest entries go first), so a flood of addresses cannot grow the table without bound."""

    def __init__(self, max_failures: int = 10, window_s: float = 60.0, *, max_clients: int = 10_000) -> None:
        if max_failures < 1 or not window_s > 0:
            raise ValueError(f"{max_failures=} must be >= 1 and {window_s=} > 0")
        self.max_failures = int(max_failures)
        self.window_s = float(window_s)
        self.max_clients = int(max_clients)
        self._failures: dict[str, list[float]] = {}
        self._lock = threading.Lock()
        self.refused = 0  # requests answered 429

    def _recent(self, client: str, now: float) -> list[float]:
        times = self._failures.get(client)
        if not times:
            return []
        times[:] = [t for t in times if now - t < self.window_s]
        if not times:
            del self._failures[client]
        return times

    def retry_after(self, client: str, now: float | None = None) -> int | None:
        """Seconds until ``client`` may try again, or None when it may now."""
        now = time.monotonic() if now is None else now
        with self._lock:
            times = self._recent(client, now)
            if len(times) < self.max_failures:
                return None
            self.refused += 1
            return max(1, math.ceil(times[-self.max_failures] + self.window_s - now))

    def failed(self, client: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        with self._lock:
            self._recent(client, now)
            self._failures.setdefault(client, []).append(now)
            while len(self._failures) > self.max_clients:
                del self._failures[next(iter(self._failures))]


_LOOPBACK_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost", "ip6-loopback"})


class HostCheck:
    """Which ``Host`` headers the server answers (against DNS rebinding: a page of another site
    whose name was re-pointed at this machine sends its own name as ``Host``). Accepted: the
    loopback names and addresses, the bound address, the names and addresses of ``allowed``
    (``*.example.org`` matches the subdomains; ``*`` alone switches the check off) and, when
    bound to every interface (0.0.0.0, ::), any IP literal (a rebinding attack needs a name)."""

    def __init__(self, bound: str, allowed: Iterable[str] = ()) -> None:
        self.bound = ipaddress.ip_address(bound)
        self.wildcard = self.bound.is_unspecified
        self.allowed = frozenset(a.lower().rstrip(".") for a in allowed)
        self.everything = "*" in self.allowed
        self.suffixes = tuple(a[1:] for a in self.allowed if a.startswith("*."))
        self.refused = 0

    @staticmethod
    def name_of(header: str) -> str | None:
        """The host of a ``Host`` header (port and IPv6 brackets removed), None if malformed."""
        value = header.strip().lower()
        if not value or any(c in value for c in " /\\@?#"):
            return None
        if value.startswith("["):
            inside, bracket, rest = value[1:].partition("]")
            if not bracket or (rest and not (rest.startswith(":") and rest[1:].isdigit())):
                return None
            return inside
        name, colon, port = value.rpartition(":") if ":" in value else (value, "", "")
        if colon and not port.isdigit():
            return None
        return name.rstrip(".") or None

    def accepts(self, name: str) -> bool:
        if self.everything or name in _LOOPBACK_NAMES or name in self.allowed:
            return True
        try:
            address = ipaddress.ip_address(name)
        except ValueError:
            return any(name.endswith(s) for s in self.suffixes)
        return address.is_loopback or address == self.bound or self.wildcard


class _Gate:
    """ASGI middleware in front of every route (API, documents, their assets):

    1. the ``Host`` header is checked (400 missing or malformed, 421 not one of this server's);
    2. off loopback, the token is required (401; ``Basic`` with the token as password is
       accepted too, so a browser can open ``/docs``); wrong guesses are rate-limited (429);
    3. the body is read here, whole, before the route runs, and refused over the limit (413),
       by ``Content-Length`` and while it streams (chunked): a route that never reads its body
       would otherwise answer before the limit was ever checked.
    """

    def __init__(self, app: Any, *, default: int, ingest: int, hosts: HostCheck | None,
                 check_token: Any | None, limiter: AuthLimiter) -> None:
        self.app = app
        self.default = default
        self.ingest = ingest
        self.hosts = hosts
        self.check_token = check_token  # None: loopback, the routes decide
        self.limiter = limiter

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers: dict[bytes, bytes] = {}
        for name, value in scope.get("headers", []):
            if name in headers and name in (b"host", b"content-length"):
                await _reject(send, 400, f"more than one {name.decode()} header")
                return
            headers[name] = value
        if self.hosts is not None:
            raw = headers.get(b"host")
            if raw is None:
                await _reject(send, 400, "the request has no Host header")
                return
            host = HostCheck.name_of(raw.decode("latin-1"))
            if host is None:
                await _reject(send, 400, "the Host header is malformed")
                return
            if not self.hosts.accepts(host):
                self.hosts.refused += 1
                await _reject(send, 421, f"this server does not answer for host {host[:100]!r} (server.allowed_hosts "
                                         "lists the names it answers to besides loopback and its own address)")
                return
        if self.check_token is not None:
            client = _client_of(scope)
            wait = self.limiter.retry_after(client)
            if wait is not None:
                await _reject(send, 429, f"too many wrong tokens from {client}; retry in {wait} s",
                              [(b"retry-after", str(wait).encode())])
                return
            token = _token_from(headers.get(b"authorization", b"").decode("latin-1"),
                                headers.get(b"x-shm-token", b"").decode("latin-1"))
            try:
                self.check_token(token)
            except PermissionError as exc:
                if token:
                    self.limiter.failed(client)
                await _reject(send, 401, str(exc), [(b"www-authenticate", b'Bearer realm="shm serve"'),
                                                    (b"www-authenticate", b'Basic realm="shm serve", charset="UTF-8"')])
                return
        path = scope.get("path") or ""
        limit = self.ingest if path == "/api/ingest" or _STRUCTURE_INGEST.fullmatch(path) else self.default
        length_header = headers.get(b"content-length")
        if length_header is not None:
            try:
                length = int(length_header)
                if length < 0:
                    raise ValueError
            except ValueError:
                await _reject(send, 400, "Content-Length is not a number")
                return
            if length > limit:
                await _reject(send, 413, f"request body of {length} bytes exceeds the limit of {limit} bytes",
                              close=True)
                return
        elif b"transfer-encoding" not in headers:
            await self.app(scope, receive, send)  # no body
            return
        chunks: list[bytes] = []
        seen = 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            body = message.get("body", b"")
            seen += len(body)
            if seen > limit:
                await _reject(send, 413, f"request body exceeds the limit of {limit} bytes", close=True)
                return
            chunks.append(body)
            if not message.get("more_body", False):
                break
        whole = b"".join(chunks)
        delivered = False

        async def replay() -> dict:
            nonlocal delivered
            if not delivered:
                delivered = True
                return {"type": "http.request", "body": whole, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


def _client_of(scope: dict) -> str:
    client = scope.get("client")
    return str(client[0]) if client else "unknown"


async def _reject(send: Any, status: int, detail: str, headers: list[tuple[bytes, bytes]] | None = None, *,
                  close: bool = False) -> None:
    import json

    body = json.dumps({"detail": detail}).encode()
    extra = list(headers or []) + ([(b"connection", b"close")] if close else [])
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()), *extra]})
    await send({"type": "http.response.body", "body": body})


def _token_from(authorization: str, x_token: str) -> str | None:
    """The token of ``Authorization: Bearer T``, ``Authorization: Basic`` (any user, password T:
    what a browser asks for) or ``X-SHM-Token: T``."""
    if authorization:
        scheme, _, value = authorization.strip().partition(" ")
        value = value.strip()
        if scheme.lower() == "bearer" and value:
            return value
        if scheme.lower() == "basic" and value:
            import base64
            import binascii

            try:
                decoded = base64.b64decode(value, validate=True).decode("utf-8")
            except (binascii.Error, UnicodeDecodeError):
                return None
            return decoded.partition(":")[2] or None
    return x_token.strip() or None


def _token_of(request: Request) -> str | None:
    return _token_from(request.headers.get("authorization", ""), request.headers.get("x-shm-token", ""))


def _parse_time(name: str, value: str | None) -> float | None:
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


def _error(description: str) -> dict[str, Any]:
    return {"model": ErrorDocument, "description": description}


_AUTH_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: _error("no or a malformed Host header"),
    401: _error("missing or wrong token"),
    403: _error("no token is configured: the action is disabled"),
    413: _error("request body over the limit"),
    421: _error("the Host header names a host this server does not answer for (server.allowed_hosts)"),
    429: _error("too many wrong tokens from this address: retry after Retry-After seconds"),
    503: _error("the database is unavailable for now (locked by another process, disk full): retry later"),
}
#: Our own 422s say in a sentence what is wrong with a parameter; FastAPI's list what does not parse.
_INVALID = {422: _error("a parameter is invalid")}


def _ingest_message(topic: dict[str, Any], title: str) -> dict[str, Any]:
    """One ingest message of the sensor topics ``topic`` matches, its payload typed by the
    recording contract's JSON schema ``title`` (the schema a recording's channel carries)."""
    from contract import SCHEMAS

    payload = {k: v for k, v in SCHEMAS[title].items() if k != "$schema"}
    return {"type": "object", "title": f"{title} message", "required": ["topic", "log_time_ns", "payload"],
            "properties": {"topic": {"type": "string", **topic},
                           "log_time_ns": {"type": "integer", "minimum": 0},
                           "publish_time_ns": {"type": "integer", "minimum": 0},
                           "payload": payload}}


#: The documented body of both ingest routes (validated by hand: see ``_ingest``): each message's
#: payload typed by its topic, as the recording contract defines it.
_INGEST_BODY: dict[str, Any] = {"requestBody": {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "required": ["messages"], "additionalProperties": False,
    "properties": {"messages": {"type": "array", "items": {"oneOf": [
        _ingest_message({"pattern": "^/imu/[^/]+$", "examples": ["/imu/D"]}, "shm.Imu"),
        _ingest_message({"pattern": "^(/tof/[^/]+|/bearing/displacement)$", "examples": ["/tof/s1"]}, "shm.Distance"),
        _ingest_message({"pattern": "^/strain/[^/]+$", "examples": ["/strain/g1"]}, "shm.Strain"),
        _ingest_message({"enum": ["/env/temperature"]}, "shm.Temperature"),
    ]}}}}}}}}


def _cut_headers(rows: list, truncated: bool) -> dict[str, str]:
    """``X-Count`` and ``X-Truncated`` of a CSV export (a CSV has no place for them)."""
    return {"X-Count": str(len(rows)), "X-Truncated": "true" if truncated else "false"}


def create_app(service: ApiService, *, loopback: bool = True, max_body_bytes: int = 64 * 1024,
               max_ingest_bytes: int = 8 * 1024 * 1024, host: str = "127.0.0.1", allowed_hosts: Iterable[str] = (),
               check_host: bool = True, auth_failures_per_minute: int = 10) -> FastAPI:
    """The API of ``service``, bound at ``host``. ``loopback=False`` requires the token for every
    request, the API documents included. ``Host`` headers other than loopback, ``host`` and
    ``allowed_hosts`` are refused (421); more than ``auth_failures_per_minute`` wrong tokens from
    one address are answered 429 for the rest of the minute."""
    limiter = AuthLimiter(auth_failures_per_minute, 60.0)

    def authorize(request: Request) -> None:
        client = request.client.host if request.client else "unknown"
        wait = limiter.retry_after(client)
        if wait is not None:
            raise HTTPException(429, f"too many wrong tokens from {client}; retry in {wait} s",
                                headers={"Retry-After": str(wait)})
        token = _token_of(request)
        try:
            service.check_token(token)
        except PermissionError as exc:
            if service.token is None:
                raise HTTPException(403, str(exc)) from None
            if token:
                limiter.failed(client)
            raise HTTPException(401, str(exc), headers={"WWW-Authenticate": "Bearer"}) from None

    def everyone(request: Request) -> None:
        if not loopback:
            authorize(request)

    app = FastAPI(
        title="shm serve",
        version="0.1.0",
        description="Structural health monitoring service: status, modal trends, alarms, spectra, ingest.",
        dependencies=[Depends(everyone)],
    )
    serve_docs_offline(app)  # /docs and /redoc from the installed packages, not a CDN

    @app.exception_handler(ServiceStarting)
    async def service_starting(request: Request, exc: ServiceStarting) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=503, headers={"Retry-After": "5"})

    @app.exception_handler(StorageUnavailable)
    async def storage_unavailable(request: Request, exc: StorageUnavailable) -> JSONResponse:
        # The database stayed locked (another process) or failing for the storage's retry period.
        return JSONResponse({"detail": f"the database is unavailable for now ({exc}); retry later"}, status_code=503,
                            headers={"Retry-After": "5"})

    @app.get("/healthz", summary="liveness: 'degraded' while the pipeline's batches fail", response_model=HealthDocument,
             responses=_AUTH_RESPONSES)
    def healthz() -> HealthDocument:
        return service.health()

    @app.get("/api/status", summary="sources, rates, latency, dropped and rejected samples, degraded sensors",
             response_model=StatusDocument, responses=_AUTH_RESPONSES)
    def status() -> StatusDocument:
        return service.status()

    @app.get("/api/trends", summary="the modal trend export (one row per window and mode)", response_model=TrendsDocument,
             responses={**_AUTH_RESPONSES, **_INVALID, 200: {"content": {"text/csv": {"schema": {"type": "string"}}}}})
    def trends(
        from_: str | None = Query(None, alias="from", max_length=64, description="UNIX s or ISO 8601 (inclusive)"),
        to: str | None = Query(None, max_length=64, description="UNIX s or ISO 8601 (exclusive)"),
        mode: int | None = Query(None, ge=1, le=20, description="mode number (1-based)"),
        source: str | None = Query(None, min_length=1, max_length=200, description="source id"),
        format: Literal["json", "csv"] = Query("json", description="json or csv"),
        limit: int = Query(100_000, ge=1, le=1_000_000, description="most rows returned"),
    ) -> Any:
        lo, hi = _parse_time("from", from_), _parse_time("to", to)
        if lo is not None and hi is not None and lo > hi:
            raise HTTPException(422, f"'from' ({lo}) is after 'to' ({hi})")
        # one row more than asked: whether the answer is cut (issue 26: an export says what it holds)
        rows = service.trends(lo, hi, mode=mode, source=source, limit=limit + 1)
        rows, truncated = rows[:limit], len(rows) > limit
        if format == "csv":
            buf = io.StringIO()
            writer = csv.DictWriter(buf, fieldnames=_TREND_FIELDS, extrasaction="ignore", lineterminator="\n")
            writer.writeheader()
            writer.writerows(row.model_dump() for row in rows)
            return Response(buf.getvalue(), media_type="text/csv",
                            headers={"Content-Disposition": 'attachment; filename="trends.csv"', **_cut_headers(rows, truncated)})
        return TrendsDocument(rows=rows, count=len(rows), truncated=truncated)

    @app.get("/api/alarms", summary="alarms, newest first", response_model=AlarmsDocument, responses={**_AUTH_RESPONSES, **_INVALID})
    def alarms(state: Literal["active", "cleared"] | None = Query(None, description="only alarms in this state")) -> AlarmsDocument:
        items = service.alarms(state)
        return AlarmsDocument(alarms=items, count=len(items))

    @app.post("/api/alarms/{alarm_id}/ack", summary="acknowledge an alarm (token required)", response_model=AlarmDocument,
              responses={**_AUTH_RESPONSES, **_INVALID, 404: _error("no such alarm")})
    def acknowledge(request: Request, alarm_id: int = Path(..., ge=1, le=2**62)) -> AlarmDocument:
        authorize(request)
        try:
            return service.acknowledge(alarm_id, _token_of(request) or "", by="api")
        except KeyError:
            raise HTTPException(404, f"alarm {alarm_id} does not exist") from None
        except PermissionError as exc:
            raise HTTPException(401, str(exc)) from None

    @app.get("/api/spectra/latest", summary="amplitude spectra of b of the latest window", response_model=SpectrumDocument,
             responses={**_AUTH_RESPONSES, 404: _error("no window analysed yet")})
    def spectra() -> SpectrumDocument:
        spec = service.spectra()
        if spec is None:
            raise HTTPException(404, "no analysis window yet")
        return spec

    @app.post("/api/baseline", summary="start learning a new baseline (token required)", status_code=202,
              response_model=BaselineRequestDocument, responses=_AUTH_RESPONSES)
    def baseline(request: Request) -> BaselineRequestDocument:
        authorize(request)
        return service.request_baseline()

    @app.post(
        "/api/ingest", summary="ingest a batch of samples in the recording format (token required)",
        response_model=IngestResultDocument,
        responses={**_AUTH_RESPONSES, 400: _error("body is not a valid batch"), 409: _error("source is not ingest"),
                   413: _error("body too large"), 503: _error("pipeline full, retry later")},
        openapi_extra=_INGEST_BODY,
    )
    async def ingest(request: Request) -> IngestResultDocument | JSONResponse:
        authorize(request)
        body = await request.body()
        try:
            document = parse_body(body)
        except IngestError as exc:
            raise HTTPException(400, str(exc)) from None
        from starlette.concurrency import run_in_threadpool

        try:
            result = await run_in_threadpool(service.ingest, document)
        except IngestError as exc:
            raise HTTPException(400, str(exc)) from None
        except LookupError as exc:
            raise HTTPException(409, str(exc)) from None
        if result is None:
            return JSONResponse({"detail": "the pipeline is full; retry later (nothing of this request was taken)"},
                                status_code=503, headers={"Retry-After": "1"})
        return result

    _fleet_routes(app, service, authorize)

    @app.get("/metrics", summary="Prometheus metrics (text format); of a fleet, per structure (label structure)", response_class=PlainTextResponse,
             responses={**_AUTH_RESPONSES, 200: {"content": {"text/plain": {"schema": {"type": "string"}}}}})
    def metrics() -> PlainTextResponse:
        return PlainTextResponse(metrics_text(service), media_type="text/plain; version=0.0.4; charset=utf-8")

    app.add_middleware(_Gate, default=max_body_bytes, ingest=max_ingest_bytes,
                       hosts=HostCheck(host, allowed_hosts) if check_host else None,
                       check_token=None if loopback else (lambda token: service.check_token(token)), limiter=limiter)
    app.state.auth_limiter = limiter
    return app


# -- a fleet: /api/structures ---------------------------------------------------------------

_STRUCTURE_INGEST = re.compile(r"/api/structures/[^/]+/ingest")
_STRUCTURE_ID = Path(..., min_length=1, max_length=64, description="structure id ([a-z0-9-])")
_UNKNOWN = {404: _error("no such structure (the message names it)"),
            409: _error("the structure failed to start (the message says why)")}


def _fleet_routes(app: FastAPI, service: ServicePort, authorize: Callable[[Request], None]) -> None:
    """The routes of a fleet (``[[structures]]``): each single-structure route per structure.
    Also served for a single structure (its id is its source id)."""
    from ._service import NotSingleStructure, StructureUnavailable

    def call(fn: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except KeyError as exc:
            raise HTTPException(404, exc.args[0] if exc.args else str(exc)) from None
        except StructureUnavailable as exc:
            raise HTTPException(409, str(exc)) from None

    @app.exception_handler(NotSingleStructure)
    async def not_single(request: Request, exc: NotSingleStructure) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=409)

    @app.get("/api/structures", summary="every structure: state, lag, committed windows, active alarms",
             response_model=StructuresDocument, responses=_AUTH_RESPONSES)
    def structures() -> StructuresDocument:
        return service.structures_document()

    @app.get("/api/structures/{structure_id}/status", summary="one structure's status (as /api/status)",
             response_model=StatusDocument, responses={**_AUTH_RESPONSES, **_UNKNOWN})
    def structure_status(structure_id: str = _STRUCTURE_ID) -> StatusDocument:
        return call(service.status, structure_id)

    @app.get("/api/structures/{structure_id}/trends", summary="one structure's modal trends (as /api/trends)",
             response_model=TrendsDocument,
             responses={**_AUTH_RESPONSES, **_INVALID, **_UNKNOWN, 200: {"content": {"text/csv": {"schema": {"type": "string"}}}}})
    def structure_trends(
        structure_id: str = _STRUCTURE_ID,
        from_: str | None = Query(None, alias="from", max_length=64, description="UNIX s or ISO 8601 (inclusive)"),
        to: str | None = Query(None, max_length=64, description="UNIX s or ISO 8601 (exclusive)"),
        mode: int | None = Query(None, ge=1, le=20, description="mode number (1-based)"),
        format: Literal["json", "csv"] = Query("json", description="json or csv"),
        limit: int = Query(100_000, ge=1, le=1_000_000, description="most rows returned"),
    ) -> Any:
        lo, hi = _parse_time("from", from_), _parse_time("to", to)
        if lo is not None and hi is not None and lo > hi:
            raise HTTPException(422, f"'from' ({lo}) is after 'to' ({hi})")
        rows = call(service.structure_trends, structure_id, lo, hi, mode=mode, limit=limit + 1)
        rows, truncated = rows[:limit], len(rows) > limit
        if format == "csv":
            buf = io.StringIO()
            writer = csv.DictWriter(buf, fieldnames=_TREND_FIELDS, extrasaction="ignore", lineterminator="\n")
            writer.writeheader()
            writer.writerows(row.model_dump() for row in rows)
            return Response(buf.getvalue(), media_type="text/csv",
                            headers={"Content-Disposition": f'attachment; filename="trends-{structure_id}.csv"',
                                     **_cut_headers(rows, truncated)})
        return TrendsDocument(rows=rows, count=len(rows), truncated=truncated)

    @app.get("/api/structures/{structure_id}/alarms", summary="one structure's alarms, newest first",
             response_model=AlarmsDocument, responses={**_AUTH_RESPONSES, **_INVALID, **_UNKNOWN})
    def structure_alarms(structure_id: str = _STRUCTURE_ID,
                         state: Literal["active", "cleared"] | None = Query(None, description="only alarms in this state"),
                         ) -> AlarmsDocument:
        items = call(service.structure_alarms, structure_id, state)
        return AlarmsDocument(alarms=items, count=len(items))

    @app.get("/api/structures/{structure_id}/spectra/latest", summary="amplitude spectra of b of the structure's latest window",
             response_model=SpectrumDocument, responses={**_AUTH_RESPONSES, **_UNKNOWN})
    def structure_spectra(structure_id: str = _STRUCTURE_ID) -> SpectrumDocument:
        spec = call(service.spectra, structure_id)
        if spec is None:
            raise HTTPException(404, f"structure {structure_id!r} has no analysis window yet")
        return spec

    @app.get("/api/structures/{structure_id}/windows/latest", summary="the structure's latest committed analysis window",
             response_model=WindowDocument, responses={**_AUTH_RESPONSES, **_UNKNOWN})
    def structure_window(structure_id: str = _STRUCTURE_ID) -> WindowDocument:
        window = call(service.structure_window, structure_id)
        if window is None:
            raise HTTPException(404, f"structure {structure_id!r} has no analysis window yet")
        return window

    @app.get("/api/structures/{structure_id}/rig", summary="the rig the structure is monitored with (rig.json)",
             response_model=RigDescription, responses={**_AUTH_RESPONSES, **_UNKNOWN})
    def structure_rig(structure_id: str = _STRUCTURE_ID) -> RigDescription:
        return call(service.structure_rig, structure_id)

    @app.get("/api/structures/{structure_id}/live",
             summary="the structure's newest state estimates (about 10 per second of data) for a live view",
             description="A read makes the structure keep its newest estimates for `watch_s` more seconds (nothing is "
                         "kept for a structure nobody reads); poll with `after` = the last `seq` seen.",
             response_model=LiveEstimatesDocument, responses={**_AUTH_RESPONSES, **_INVALID, **_UNKNOWN})
    def structure_live(structure_id: str = _STRUCTURE_ID,
                       after: int = Query(0, ge=0, le=2**62, description="only estimates after this seq")) -> LiveEstimatesDocument:
        return call(service.live, structure_id, after)

    @app.post("/api/structures/{structure_id}/baseline", summary="start learning a new baseline of the structure (token required)",
              status_code=202, response_model=BaselineRequestDocument, responses={**_AUTH_RESPONSES, **_UNKNOWN})
    def structure_baseline(request: Request, structure_id: str = _STRUCTURE_ID) -> BaselineRequestDocument:
        authorize(request)
        return call(service.request_baseline, structure_id)

    @app.post(
        "/api/structures/{structure_id}/ingest", summary="ingest a batch of samples for the structure (token required)",
        response_model=IngestResultDocument,
        responses={**_AUTH_RESPONSES, **_UNKNOWN, 400: _error("body is not a valid batch"),
                   409: _error("the structure's source is not ingest, or it failed to start"),
                   413: _error("body too large"), 503: _error("pipeline full, retry later")},
        openapi_extra=_INGEST_BODY,
    )
    async def structure_ingest(request: Request, structure_id: str = _STRUCTURE_ID) -> IngestResultDocument | JSONResponse:
        authorize(request)
        call(service.structure, structure_id)  # 404/409 before the body is read
        body = await request.body()
        try:
            document = parse_body(body)
        except IngestError as exc:
            raise HTTPException(400, str(exc)) from None
        from starlette.concurrency import run_in_threadpool

        try:
            result = await run_in_threadpool(call, service.ingest, document, structure_id)
        except IngestError as exc:
            raise HTTPException(400, str(exc)) from None
        except LookupError as exc:
            raise HTTPException(409, str(exc)) from None
        if result is None:
            return JSONResponse({"detail": "the pipeline is full; retry later (nothing of this request was taken)"},
                                status_code=503, headers={"Retry-After": "1"})
        return result
