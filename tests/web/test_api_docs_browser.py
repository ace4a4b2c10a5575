"""Swagger UI and ReDoc render in headless Chromium with the network cut off: every request the
pages make goes to the API itself (a request anywhere else is recorded and refused)."""

from __future__ import annotations

from urllib.parse import urlparse

import pytest
from browser_helpers import CHROMIUM_ARGS, VIEWPORT


@pytest.fixture()
def api_url(tmp_path):
    from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

    settings = load_settings(None, {"source": {"spec": "ingest"}, "dashboard": {"enabled": False},
                                    "db": str(tmp_path / "shm.sqlite"), "archive": {"enabled": False}})
    service = MonitoringService(settings, environ={})
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    yield api.url
    api.stop()
    service.stop(drain_s=0)


@pytest.mark.timeout(180)
def test_swagger_ui_and_redoc_render_offline(chromium, api_url, tmp_path):
    from playwright.sync_api import sync_playwright

    local = urlparse(api_url).netloc
    outside: list[str] = []

    def route(r):
        if urlparse(r.request.url).netloc == local:
            r.continue_()
        else:
            outside.append(r.request.url)
            r.abort()

    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"), executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
        )
        try:
            context.route("**/*", route)
            page = context.pages[0] if context.pages else context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(f"{api_url}/docs")
            page.wait_for_selector(".swagger-ui .info .title", timeout=30_000)
            assert "shm serve" in page.inner_text(".swagger-ui .info .title")
            # the operations of the API are listed
            page.locator(".opblock-summary-path", has_text="/api/status").first.wait_for(timeout=15_000)
            assert page.locator(".opblock").count() >= 8
            page.goto(f"{api_url}/redoc")
            page.wait_for_selector("h1", timeout=30_000)
            # an operation's heading in the middle panel (the side menu's entry of it is folded under its tag)
            page.locator("h2", has_text="sources, rates, latency").first.wait_for(timeout=15_000)
            assert "shm serve" in page.inner_text("h1")
            assert errors == []
        finally:
            context.close()
    assert outside == [], outside
