"""The API documents (``/docs``: Swagger UI, ``/redoc``: ReDoc) served from the installed packages.

FastAPI's own pages load Swagger UI and ReDoc from a CDN, so on a rig's offline network ``/docs``
stays blank. ``fastapi-offline`` ships the same JavaScript and CSS in its wheel; these pages point
at those files, served by the API itself under ``STATIC_URL``. On loopback the pages, the
assets and the OpenAPI document need no token; off loopback every path needs it (the API's
middleware checks it before any route), a browser sending it as the HTTP Basic password.

ReDoc's sidebar always shows a Redocly logo fetched from the vendor's CDN; the pages' Content
Security Policy allows images, scripts, styles and connections only from the API itself (plus
inline code and ``data:``/``blob:`` that both bundles use), so the browser does not even try.
"""

from __future__ import annotations

from importlib.resources import files
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.staticfiles import StaticFiles
from starlette.requests import Request
from starlette.responses import HTMLResponse

__all__ = ["ASSETS", "CONTENT_SECURITY_POLICY", "STATIC_URL", "serve_docs_offline"]

STATIC_URL = "/docs-static"
#: The files the pages load, all from ``fastapi_offline/static`` of the installed package.
ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; font-src 'self' data:; worker-src 'self' blob:; connect-src 'self'"
)


def _local_only(page: HTMLResponse) -> HTMLResponse:
    page.headers["Content-Security-Policy"] = CONTENT_SECURITY_POLICY
    return page


def _asset_directory() -> str:
    directory = files("fastapi_offline") / "static"
    missing = [name for name in ASSETS if not (directory / name).is_file()]
    if missing:
        raise RuntimeError(f"fastapi-offline is installed without {missing} in {directory}")
    return str(directory)


def serve_docs_offline(app: FastAPI) -> FastAPI:
    """Replace ``app``'s CDN-loaded ``/docs`` and ``/redoc`` by pages whose assets are served by
    ``app`` itself from the installed ``fastapi-offline`` package. Returns ``app``."""
    docs_url, redoc_url, openapi_url = app.docs_url, app.redoc_url, app.openapi_url
    oauth2_url = app.swagger_ui_oauth2_redirect_url
    if openapi_url is None:
        raise ValueError("the app has no OpenAPI document (openapi_url=None): there is nothing to document")
    replaced = {docs_url, redoc_url, oauth2_url if docs_url else None} - {None}
    app.router.routes[:] = [r for r in app.router.routes if getattr(r, "path", None) not in replaced]
    app.mount(STATIC_URL, StaticFiles(directory=_asset_directory()), name="docs-static")
    # Swagger UI would fetch a validity badge from validator.swagger.io for a public spec URL.
    swagger_parameters: dict[str, Any] = {**(app.swagger_ui_parameters or {}), "validatorUrl": None}

    def root(request: Request) -> str:
        return str(request.scope.get("root_path", "")).rstrip("/")

    async def swagger_ui(request: Request) -> HTMLResponse:
        base = root(request)
        return _local_only(get_swagger_ui_html(
            openapi_url=f"{base}{openapi_url}", title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=f"{base}{oauth2_url}" if oauth2_url else None,
            swagger_js_url=f"{base}{STATIC_URL}/swagger-ui-bundle.js", swagger_css_url=f"{base}{STATIC_URL}/swagger-ui.css",
            swagger_favicon_url=f"{base}{STATIC_URL}/favicon.png", swagger_ui_parameters=swagger_parameters,
        ))

    async def oauth2_redirect(request: Request) -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    async def redoc(request: Request) -> HTMLResponse:
        base = root(request)
        return _local_only(get_redoc_html(
            openapi_url=f"{base}{openapi_url}", title=f"{app.title} - ReDoc",
            redoc_js_url=f"{base}{STATIC_URL}/redoc.standalone.js", redoc_favicon_url=f"{base}{STATIC_URL}/favicon.png",
            with_google_fonts=False,
        ))

    # add_route, as FastAPI adds its own pages: outside the OpenAPI document and the API's dependencies.
    if docs_url:
        app.add_route(docs_url, swagger_ui, include_in_schema=False)
        if oauth2_url:
            app.add_route(oauth2_url, oauth2_redirect, include_in_schema=False)
    if redoc_url:
        app.add_route(redoc_url, redoc, include_in_schema=False)
    return app
