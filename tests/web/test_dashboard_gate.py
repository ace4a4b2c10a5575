"""The dashboard off loopback. viser has no authentication; the dashboard
refuses to listen off loopback without a token, and with one puts the token gate in front of
viser. Real servers: a ViserServer behind a TokenGate, real HTTP requests (httpx) and a real
websocket handshake (the websockets client, as the page's own script does)."""

from __future__ import annotations

import asyncio
import base64

import httpx
import pytest
import viser
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from browser_helpers import CHROMIUM_ARGS
from web._gate import COOKIE, TokenGate

TOKEN = "dashboard-token-1"


@pytest.fixture()
def gated():
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    server.scene.add_frame("/probe")
    gate = TokenGate(host="127.0.0.1", port=0, upstream_port=server.get_port(), token=TOKEN)
    yield gate, server
    gate.stop()
    server.stop()


def _ws(port: int, cookie: str | None) -> tuple[str | None, bytes | str]:
    async def go():
        headers = {"Cookie": f"{COOKIE}={cookie}"} if cookie else {}
        async with connect(f"ws://127.0.0.1:{port}/", subprotocols=[f"viser-v{viser.__version__}"],
                           additional_headers=headers, open_timeout=10) as ws:
            return ws.subprotocol, await asyncio.wait_for(ws.recv(), 10)

    return asyncio.run(go())


def test_the_page_and_the_websocket_need_the_token(gated):
    gate, server = gated
    url = f"http://127.0.0.1:{gate.port}"
    with httpx.Client(base_url=url) as c:
        r = c.get("/")
        assert r.status_code == 401 and r.headers["www-authenticate"].startswith("Basic")
        assert c.get("/", headers={"Authorization": "Basic " + base64.b64encode(b"op:wrong-token").decode()}).status_code == 401
        assert c.get("/", params={"token": "wrong-token"}).status_code == 401
        ok = c.get("/", headers={"Authorization": "Basic " + base64.b64encode(f"op:{TOKEN}".encode()).decode()})
        assert ok.status_code == 200 and "<html" in ok.text.lower()
        cookie = ok.cookies.get(COOKIE)
        assert cookie and TOKEN not in cookie and "HttpOnly" in ok.headers["set-cookie"]
    with httpx.Client(base_url=url) as c:  # a link with ?token= once: the cookie and a redirect
        r = c.get("/", params={"token": TOKEN})
        assert r.status_code == 303 and r.headers["location"] == "/" and c.cookies.get(COOKIE) == cookie
        assert c.get("/").status_code == 200  # the cookie alone
    with pytest.raises(InvalidStatus) as refused:
        _ws(gate.port, None)
    assert refused.value.response.status_code == 401
    with pytest.raises(InvalidStatus):
        _ws(gate.port, "0" * 64)
    protocol, first = _ws(gate.port, cookie)  # viser's own messages come through the gate
    assert protocol == f"viser-v{viser.__version__}" and len(first) > 0
    assert gate.refused >= 5


def test_the_dashboard_refuses_to_listen_off_loopback_without_a_token():
    from web import Dashboard

    with pytest.raises(ValueError, match="not loopback: a token is required"):
        Dashboard(host="0.0.0.0", port=0, service=None)
    with pytest.raises(ValueError, match="at least 8"):
        TokenGate(host="127.0.0.1", port=0, upstream_port=1, token="short")


def test_a_browser_opens_the_gated_dashboard_with_the_token(chromium, tmp_path):
    """Headless chromium: without the token the gate answers 401; with ``?token=`` once the
    page loads, its websocket passes the gate with the cookie and viser's GUI appears."""
    from playwright.sync_api import sync_playwright

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    server.gui.add_markdown("gate probe: live")
    gate = TokenGate(host="127.0.0.1", port=0, upstream_port=server.get_port(), token=TOKEN)
    try:
        with sync_playwright() as p:
            context = p.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=chromium,
                                                           headless=True, args=CHROMIUM_ARGS)
            try:
                page = context.pages[0] if context.pages else context.new_page()
                from playwright.sync_api import Error as PlaywrightError

                try:  # headless chromium cannot ask for the password: it gives up on the challenge
                    assert page.goto(f"http://127.0.0.1:{gate.port}/").status == 401
                except PlaywrightError as exc:
                    assert "ERR_INVALID_AUTH_CREDENTIALS" in str(exc)
                page.close()  # the refused navigation left an error page behind
                page = context.new_page()
                page.goto(f"http://127.0.0.1:{gate.port}/?token={TOKEN}")
                page.wait_for_selector("canvas", timeout=30_000)
                page.get_by_text("gate probe: live").first.wait_for(timeout=30_000)
                assert "token" not in page.url
                assert len(server.get_clients()) == 1
            finally:
                context.close()
    finally:
        gate.stop()
        server.stop()
