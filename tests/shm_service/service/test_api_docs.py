"""/docs and /redoc work offline: every asset the pages load is served by the API itself from the
installed packages (no CDN), on a real server."""

from __future__ import annotations

import re
from urllib.parse import urljoin, urlparse

import httpx
import pytest
from svc_helpers import fast_overrides

from shm_service.service import ApiServer, MonitoringService, create_app, load_settings
from shm_service.service.http._docs import ASSETS, CONTENT_SECURITY_POLICY, STATIC_URL


@pytest.fixture()
def api_url(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={})
    service.start()
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    yield api.url
    api.stop()
    service.stop(drain_s=0)


def _asset_urls(html: str) -> list[str]:
    return re.findall(r"""(?:src|href)\s*=\s*["']([^"']+)["']""", html) + re.findall(r"""url:\s*['"]([^'"]+)['"]""", html)


@pytest.mark.parametrize("page, expected", [
    ("/docs", {"swagger-ui-bundle.js", "swagger-ui.css", "favicon.png"}),
    ("/redoc", {"redoc.standalone.js", "favicon.png"}),
])
def test_docs_pages_load_only_local_assets(api_url, page, expected):
    with httpx.Client(base_url=api_url) as client:
        response = client.get(page)
        assert response.status_code == 200 and response.headers["content-type"].startswith("text/html")
        html = response.text
        assert not re.search(r"cdn|jsdelivr|unpkg|googleapis|https?://(?!127\.0\.0\.1)", html), html
        urls = _asset_urls(html)
        assert urls, html
        loaded = set()
        for url in urls:
            absolute = urljoin(f"{api_url}{page}", url)
            assert urlparse(absolute).netloc == urlparse(api_url).netloc, url  # served by the API itself
            r = client.get(absolute)
            assert r.status_code == 200 and r.content, url
            loaded.add(url.rsplit("/", 1)[-1])
        assert expected <= loaded, loaded
        assert client.get("/openapi.json").json()["info"]["title"] == "shm serve"
        # the browser may fetch nothing from elsewhere (ReDoc's bundle links a logo on a CDN)
        assert response.headers["content-security-policy"] == CONTENT_SECURITY_POLICY
        assert "https:" not in CONTENT_SECURITY_POLICY and "*" not in CONTENT_SECURITY_POLICY


def test_assets_are_the_packaged_files_with_their_types(api_url):
    types = {".js": "javascript", ".css": "text/css", ".png": "image/png"}
    with httpx.Client(base_url=api_url) as client:
        for name in ASSETS:
            r = client.get(f"{STATIC_URL}/{name}")
            assert r.status_code == 200 and types[name[name.rindex("."):]] in r.headers["content-type"], name
            assert len(r.content) > 1000, name
        assert client.get(f"{STATIC_URL}/nothing.js").status_code == 404
        assert client.get("/docs/oauth2-redirect").status_code == 200
        # the pages are not API operations
        paths = client.get("/openapi.json").json()["paths"]
        assert not any(p.startswith(("/docs", "/redoc", STATIC_URL)) for p in paths)


def test_docs_need_the_token_on_a_non_loopback_api_like_every_route(tmp_path):
    """Off loopback, /docs, /redoc, /openapi.json and their assets answered
    without the token. A browser opens them with the token as the HTTP Basic password."""
    import base64

    token = "test-token-123"
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": token})
    api = ApiServer(create_app(service, loopback=False), "127.0.0.1", 0).start()
    pages = ("/docs", "/redoc", "/openapi.json", "/docs/oauth2-redirect", f"{STATIC_URL}/swagger-ui.css")
    basic = "Basic " + base64.b64encode(f"operator:{token}".encode()).decode()
    try:
        with httpx.Client(base_url=api.url) as client:
            assert client.get("/api/status").status_code == 401
            for page in pages:
                r = client.get(page)
                assert r.status_code == 401, page
                assert any(v.startswith("Basic") for v in r.headers.get_list("www-authenticate")), page
                assert client.get(page, headers={"Authorization": f"Bearer {token}"}).status_code == 200, page
                assert client.get(page, headers={"Authorization": basic}).status_code == 200, page
    finally:
        api.stop()
        service.stop(drain_s=0)
