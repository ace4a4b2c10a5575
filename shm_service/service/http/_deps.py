"""The dependencies of the HTTP routers: the runtime's port the app was built on, and the token
the acting routes require. Routers reach the service only through these (``Depends``)."""

from __future__ import annotations

from fastapi import HTTPException, Request

from contract import ServicePort

from ._gate import AuthLimiter, token_from

__all__ = ["everyone", "require_token", "service_port", "token_of"]


def service_port(request: Request) -> ServicePort:
    return request.app.state.port


def token_of(request: Request) -> str | None:
    """The token of the request (``Authorization: Bearer``/``Basic`` or ``X-SHM-Token``)."""
    return token_from(request.headers.get("authorization", ""), request.headers.get("x-shm-token", ""))


def require_token(request: Request) -> None:
    """The service's token is required: 403 when none is configured (the action is disabled),
    401 when missing or wrong; wrong guesses of an address are rate-limited (429)."""
    port: ServicePort = request.app.state.port
    limiter: AuthLimiter = request.app.state.auth_limiter
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait is not None:
        raise HTTPException(429, f"too many wrong tokens from {client}; retry in {wait} s", headers={"Retry-After": str(wait)})
    token = token_of(request)
    try:
        port.check_token(token)
    except PermissionError as exc:
        if port.token is None:
            raise HTTPException(403, str(exc)) from None
        if token:
            limiter.failed(client)
        raise HTTPException(401, str(exc), headers={"WWW-Authenticate": "Bearer"}) from None


def everyone(request: Request) -> None:
    """Of every route: off loopback (``app.state.loopback`` False) the token is required."""
    if not request.app.state.loopback:
        require_token(request)
