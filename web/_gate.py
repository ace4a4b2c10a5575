"""The token in front of the dashboard when it listens off loopback.

viser has no authentication of its own (one port serves the page and the websocket, to anyone
who reaches it). Off loopback the dashboard therefore runs viser on a free loopback port and
puts this gate on the public address: every request (the page, its assets, the websocket) needs
the operator token, else 401 with a ``Basic`` challenge, so a browser asks for it (any user
name, the token as password). A valid token sets an ``HttpOnly``, ``SameSite=Strict`` cookie
(a keyed hash of the token, never the token itself) that the page's websocket sends along; a
link may carry ``?token=`` once (answered with the cookie and a redirect to the bare path).
The gate forwards the page over HTTP and pumps websocket messages both ways, unchanged.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import hashlib
import hmac
import logging
import threading
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit

import httpx
import websockets
from websockets.asyncio.client import connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

__all__ = ["COOKIE", "TokenGate"]

COOKIE = "shm_dashboard"


class _QuietHandshakes(logging.Filter):
    """A browser closing a spare connection before sending a request is no error worth a traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() not in ("opening handshake failed", "connection rejected (401 Unauthorized)")


_LOG = logging.getLogger("shm.dashboard.gate")
_LOG.addFilter(_QuietHandshakes())
_HOP = {"connection", "keep-alive", "transfer-encoding", "upgrade", "content-length", "content-encoding"}


class TokenGate:
    """Serves ``host:port`` (0: a free port), forwarding to viser at ``127.0.0.1:upstream_port``
    when the request carries ``token``. :attr:`port` is the bound port; ``stop()`` frees it."""

    def __init__(self, *, host: str, port: int, upstream_port: int, token: str) -> None:
        if not token or len(token) < 8:
            raise ValueError("the dashboard's token must have at least 8 characters")
        self.token = token
        self.cookie_value = hmac.new(token.encode(), b"shm dashboard session", hashlib.sha256).hexdigest()
        self.upstream = f"127.0.0.1:{int(upstream_port)}"
        self.refused = 0
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._stopped: asyncio.Future | None = None
        self._error: BaseException | None = None
        self.port = 0
        self._thread = threading.Thread(target=self._run, args=(host, int(port)), name="shm-dashboard-gate", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise OSError(f"dashboard gate on {host}:{port}: {self._error}") from self._error
        if not self.port:
            raise TimeoutError("the dashboard gate did not start")

    # -- authentication -------------------------------------------------------------------------

    def authorized(self, headers: Headers, query: str) -> tuple[bool, bool]:
        """(the request may pass, it showed the token itself: set the cookie)."""
        given = dict(parse_qsl(query)).get("token")
        if given is not None and hmac.compare_digest(given.encode(), self.token.encode()):
            return True, True
        auth = headers.get("Authorization", "")
        scheme, _, value = auth.partition(" ")
        if scheme.lower() == "basic" and value:
            try:
                password = base64.b64decode(value.strip(), validate=True).decode("utf-8").partition(":")[2]
            except (binascii.Error, UnicodeDecodeError):
                password = ""
            if password and hmac.compare_digest(password.encode(), self.token.encode()):
                return True, True
        if scheme.lower() == "bearer" and value and hmac.compare_digest(value.strip().encode(), self.token.encode()):
            return True, True
        cookies = SimpleCookie()
        try:
            cookies.load(headers.get("Cookie", ""))
        except Exception:  # noqa: BLE001 - a malformed cookie header is no cookie
            return False, False
        morsel = cookies.get(COOKIE)
        if morsel is not None and hmac.compare_digest(morsel.value.encode(), self.cookie_value.encode()):
            return True, False
        return False, False

    def _cookie(self) -> str:
        return f"{COOKIE}={self.cookie_value}; HttpOnly; SameSite=Strict; Path=/"

    # -- serving --------------------------------------------------------------------------------

    async def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        parts = urlsplit(request.path)
        ok, showed = self.authorized(request.headers, parts.query)
        if not ok:
            self.refused += 1
            return Response(401, "Unauthorized", Headers({
                "WWW-Authenticate": 'Basic realm="shm dashboard", charset="UTF-8"', "Content-Type": "text/plain",
                "Cache-Control": "no-store"}), b"the dashboard needs the operator token (any user name, the token as password)\n")
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return None  # the handshake goes on; the handler pumps the messages
        query = [(k, v) for k, v in parse_qsl(parts.query) if k != "token"]
        if showed and "token" in dict(parse_qsl(parts.query)):
            target = parts.path + (f"?{urlencode(query)}" if query else "")
            return Response(303, "See Other", Headers({"Location": target or "/", "Set-Cookie": self._cookie(),
                                                      "Cache-Control": "no-store"}), b"")
        url = f"http://{self.upstream}{parts.path or '/'}" + (f"?{urlencode(query)}" if query else "")
        try:
            async with httpx.AsyncClient(timeout=30.0) as client:
                upstream = await client.get(url, headers={"Accept-Encoding": "identity"})
        except httpx.HTTPError as exc:
            return Response(502, "Bad Gateway", Headers({"Content-Type": "text/plain"}), f"dashboard: {exc}\n".encode())
        headers = Headers({k: v for k, v in upstream.headers.items() if k.lower() not in _HOP})
        headers["Cache-Control"] = headers.get("Cache-Control", "no-cache")
        if showed:
            headers["Set-Cookie"] = self._cookie()
        return Response(upstream.status_code, upstream.reason_phrase or "OK", headers, upstream.content)

    async def _handler(self, connection: ServerConnection) -> None:
        protocol = connection.subprotocol
        try:
            async with connect(f"ws://{self.upstream}/", subprotocols=[protocol] if protocol else None,
                               max_size=50 * 1024 * 1024, compression=None, open_timeout=10) as upstream:

                async def pump(source: Any, sink: Any) -> None:
                    async for message in source:
                        await sink.send(message)

                tasks = [asyncio.create_task(pump(connection, upstream)), asyncio.create_task(pump(upstream, connection))]
                done, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
        except (OSError, websockets.exceptions.WebSocketException):
            pass

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)

        async def main() -> None:
            self._stopped = self._loop.create_future()
            try:
                server = await serve(
                    self._handler, host, port, process_request=self._process_request, max_size=50 * 1024 * 1024,
                    compression=None, logger=_LOG,
                    select_subprotocol=lambda _, offered: next((p for p in offered if p.startswith("viser-v")), None))
            except OSError as exc:
                self._error = exc
                self._ready.set()
                return
            self.port = int(next(iter(server.sockets)).getsockname()[1])
            self._ready.set()
            async with server:
                await self._stopped

        try:
            self._loop.run_until_complete(main())
        finally:
            self._loop.close()

    def stop(self) -> None:
        stopped = self._stopped
        if stopped is not None and not self._loop.is_closed():

            def release() -> None:
                if not stopped.done():
                    stopped.set_result(None)

            self._loop.call_soon_threadsafe(release)
        self._thread.join(5.0)
