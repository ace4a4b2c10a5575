"""While ``shm serve`` waits for a ``follow:`` file, every route of the real app answers 503 with
``Retry-After`` (``/healthz`` answers "degraded" with the reason; the API documents are served),
never 500: the stand-in service implements the whole port."""

from __future__ import annotations

import re

import httpx
import pytest
from fastapi.routing import APIRoute

from contract import ServicePort, ServiceStarting
from shm_service.service._config import load_settings
from shm_service.service.http._app import create_app
from shm_service.service.http._server import ApiServer
from shm_service.service.runtime._service import MonitoringService, RigPending
from shm_service.service.runtime._starting import ServiceSlot, StartingService, port_methods

from svc_helpers import fast_overrides

TOKEN = "starting-token"
#: a value for each path parameter of the routes
PATH_VALUES = {"structure_id": "live", "alarm_id": "1"}
#: the routes that answer while the service starts, and how
WORKING = {"/healthz": 200, "/openapi.json": 200, "/docs": 200, "/redoc": 200}


@pytest.fixture
def starting_app(tmp_path):
    """The app as ``shm serve`` builds it while its ``follow:`` file does not exist yet."""
    path = tmp_path / "live.mcap"
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": f"follow:{path}"}))
    environ = {"SHM_TOKEN": TOKEN}
    with pytest.raises(RigPending) as pending:
        MonitoringService(settings, environ=environ)
    slot = ServiceSlot(StartingService(settings, str(pending.value), environ=environ))
    app = create_app(slot)
    api = ApiServer(app, "127.0.0.1", 0).start()
    yield app, api.url, path
    api.stop()


def _api_routes(routes) -> list[APIRoute]:
    """The app's API routes, through the routers it includes (held as included routers by newer
    FastAPI versions, which ``create_app`` includes without a prefix)."""
    out: list[APIRoute] = []
    for route in routes:
        if isinstance(route, APIRoute):
            out.append(route)
        elif hasattr(route, "original_router"):
            out.extend(_api_routes(route.original_router.routes))
    return out


def _filled(path: str) -> str:
    def value(match: re.Match[str]) -> str:
        name = match.group(1).partition(":")[0]
        if name not in PATH_VALUES:
            raise AssertionError(f"no value for the path parameter {name!r} of {path}: add one to PATH_VALUES")
        return PATH_VALUES[name]

    return re.sub(r"\{([^}]+)\}", value, path)


def test_every_route_answers_503_while_the_service_starts(starting_app):
    app, url, path = starting_app
    routes = [(route.path, method) for route in _api_routes(app.routes) for method in sorted(route.methods)]
    assert len(routes) > 15  # the API's routers are all there
    answers: dict[tuple[str, str], int] = {}
    with httpx.Client(base_url=url, timeout=10) as client:
        for route_path, method in routes:
            r = client.request(method, _filled(route_path), headers={"Authorization": f"Bearer {TOKEN}"},
                               json={} if method in ("POST", "PUT", "PATCH") else None)
            answers[(route_path, method)] = r.status_code
            expected = WORKING.get(route_path, 503)
            assert r.status_code == expected, (route_path, method, r.status_code, r.text[:300])
            if expected == 503:
                assert r.headers["Retry-After"] and str(path) in r.json()["detail"]
        health = client.get("/healthz").json()
    assert health["status"] == "degraded" and any(str(path) in reason for reason in health["reasons"])
    assert 500 not in answers.values()


def test_the_stand_in_implements_every_method_of_the_port(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": f"follow:{tmp_path / 'x.mcap'}"}))
    starting = StartingService(settings, "the file", environ={})
    assert isinstance(starting, ServicePort)
    answered = {"check_token", "health"}
    raising = [name for name in port_methods() if name not in answered]
    assert {"structures_document", "live", "fatigue", "structure_status"} <= set(raising)
    for name in raising:
        with pytest.raises(ServiceStarting, match="the file"):
            getattr(starting, name)("live")
