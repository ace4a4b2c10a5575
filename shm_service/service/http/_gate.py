"""The door of the HTTP API: ``Host`` checks against DNS rebinding, the token off loopback
with a rate limit of wrong guesses, and request bodies bounded before any route runs (an ASGI
middleware, ``Gate``, in front of every route and document)."""

from __future__ import annotations

import ipaddress
import math
import re
import threading
import time
from collections.abc import Iterable
from typing import Any

__all__ = ["STRUCTURE_INGEST", "AuthLimiter", "Gate", "HostCheck", "client_of", "reject", "token_from"]

#: the ingest route of one structure: its body limit is the ingest one
STRUCTURE_INGEST = re.compile(r"/api/structures/[^/]+/ingest")


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


class Gate:
    """ASGI middleware in front of every route (API, documents, their assets):

    1. the ``Host`` header is checked (400 missing or malformed, 421 not one of this server's);
    2. off loopback, the token is required (401; ``Basic`` with the token as password is
       accepted too, so a browser can open ``/docs``); wrong guesses are rate-limited (429);
    3. the body is read here, whole, before the route runs, and refused over the limit (413),
       by ``Content-Length`` and while it streams (chunked): a route that never reads its body
       would otherwise answer before the limit was ever checked.

    Each step answers a refusal itself and returns False; the request goes on when all pass.
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
                await reject(send, 400, f"more than one {name.decode()} header")
                return
            headers[name] = value
        if not await self._host_passes(headers, send) or not await self._token_passes(scope, headers, send):
            return
        path = scope.get("path") or ""
        limit = self.ingest if path == "/api/ingest" or STRUCTURE_INGEST.fullmatch(path) else self.default
        length_header = headers.get(b"content-length")
        if length_header is None and b"transfer-encoding" not in headers:
            await self.app(scope, receive, send)  # no body
            return
        if length_header is not None and not await self._length_passes(length_header, limit, send):
            return
        await self._with_body(scope, receive, send, limit)

    async def _host_passes(self, headers: dict[bytes, bytes], send: Any) -> bool:
        if self.hosts is None:
            return True
        raw = headers.get(b"host")
        if raw is None:
            await reject(send, 400, "the request has no Host header")
            return False
        host = HostCheck.name_of(raw.decode("latin-1"))
        if host is None:
            await reject(send, 400, "the Host header is malformed")
            return False
        if not self.hosts.accepts(host):
            self.hosts.refused += 1
            await reject(send, 421, f"this server does not answer for host {host[:100]!r} (server.allowed_hosts "
                                    "lists the names it answers to besides loopback and its own address)")
            return False
        return True

    async def _token_passes(self, scope: dict, headers: dict[bytes, bytes], send: Any) -> bool:
        if self.check_token is None:
            return True
        client = client_of(scope)
        wait = self.limiter.retry_after(client)
        if wait is not None:
            await reject(send, 429, f"too many wrong tokens from {client}; retry in {wait} s",
                         [(b"retry-after", str(wait).encode())])
            return False
        token = token_from(headers.get(b"authorization", b"").decode("latin-1"),
                           headers.get(b"x-shm-token", b"").decode("latin-1"))
        try:
            self.check_token(token)
        except PermissionError as exc:
            if token:
                self.limiter.failed(client)
            await reject(send, 401, str(exc), [(b"www-authenticate", b'Bearer realm="shm serve"'),
                                               (b"www-authenticate", b'Basic realm="shm serve", charset="UTF-8"')])
            return False
        return True

    @staticmethod
    async def _length_passes(length_header: bytes, limit: int, send: Any) -> bool:
        try:
            length = int(length_header)
            if length < 0:
                raise ValueError
        except ValueError:
            await reject(send, 400, "Content-Length is not a number")
            return False
        if length > limit:
            await reject(send, 413, f"request body of {length} bytes exceeds the limit of {limit} bytes", close=True)
            return False
        return True

    async def _with_body(self, scope: dict, receive: Any, send: Any, limit: int) -> None:
        """Read the body whole (refused over ``limit`` while it streams), then hand it on."""
        chunks: list[bytes] = []
        seen = 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            body = message.get("body", b"")
            seen += len(body)
            if seen > limit:
                await reject(send, 413, f"request body exceeds the limit of {limit} bytes", close=True)
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


def client_of(scope: dict) -> str:
    client = scope.get("client")
    return str(client[0]) if client else "unknown"


async def reject(send: Any, status: int, detail: str, headers: list[tuple[bytes, bytes]] | None = None, *,
                  close: bool = False) -> None:
    import json

    body = json.dumps({"detail": detail}).encode()
    extra = list(headers or []) + ([(b"connection", b"close")] if close else [])
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()), *extra]})
    await send({"type": "http.response.body", "body": body})


def token_from(authorization: str, x_token: str) -> str | None:
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
