"""Open doors, with real requests against the real server (uvicorn on a free
loopback port): the Host check against DNS rebinding, body limits on chunked bodies, the rate
limit on wrong tokens, and the token on every route off loopback."""

from __future__ import annotations

import socket

import httpx
import pytest
from svc_helpers import fast_overrides

from shm_service.service import ApiServer, MonitoringService, SettingsError, load_settings
from shm_service.service.http._app import AuthLimiter, HostCheck, create_app

TOKEN = "test-token-123"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def _serve(tmp_path, **app_options):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    service.start()
    api = ApiServer(create_app(service, **app_options), "127.0.0.1", 0).start()
    return service, api


@pytest.fixture()
def served(tmp_path):
    service, api = _serve(tmp_path, allowed_hosts=("shm.example.org", "*.plant.local"), auth_failures_per_minute=5)
    yield service, api
    api.stop()
    service.stop(drain_s=0)


def _raw(port: int, request: bytes) -> bytes:
    """One request as bytes on a socket (for Host headers httpx would not send)."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(request)
        data = b""
        while chunk := s.recv(65536):
            data += chunk
            if b"\r\n\r\n" in data:
                head, _, body = data.partition(b"\r\n\r\n")
                length = [int(line.split(b":")[1]) for line in head.split(b"\r\n") if line.lower().startswith(b"content-length")]
                if length and len(body) >= length[0]:
                    break
        return data


def test_host_header_is_checked_against_dns_rebinding(served):
    service, api = served
    port = api.port
    with httpx.Client(base_url=api.url) as c:
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", "localhost", "[::1]:80", "shm.example.org",
                     "SHM.example.org.", "a.plant.local:8600"):
            assert c.get("/api/status", headers={"Host": host}).status_code == 200, host
        for host in ("evil.example", f"evil.example:{port}", "plant.local.evil.example", "10.1.2.3", "example.org"):
            r = c.get("/api/status", headers={"Host": host})
            assert r.status_code == 421 and "allowed_hosts" in r.json()["detail"], host
        # the documents and their assets are behind the same check
        assert c.get("/openapi.json", headers={"Host": "evil.example"}).status_code == 421
        assert c.get("/docs", headers={"Host": "evil.example"}).status_code == 421
    for bad in (b"bad host", b"[::1", b"a@b", b"host:port"):
        answer = _raw(port, b"GET /healthz HTTP/1.1\r\nHost: " + bad + b"\r\nConnection: close\r\n\r\n")
        assert answer.startswith(b"HTTP/1.1 400"), (bad, answer[:80])


def test_host_check_rules():
    wildcard = HostCheck("0.0.0.0", ())
    assert wildcard.accepts("192.168.7.5") and wildcard.accepts("::1") and not wildcard.accepts("evil.example")
    bound = HostCheck("10.0.0.5", ("*",))
    assert bound.accepts("anything.example")
    one = HostCheck("10.0.0.5", ())
    assert one.accepts("10.0.0.5") and one.accepts("127.0.0.2") and not one.accepts("10.0.0.6")
    assert HostCheck.name_of("[::1]:8600") == "::1" and HostCheck.name_of("Example.ORG:80") == "example.org"
    assert HostCheck.name_of("a b") is None and HostCheck.name_of("x:") is None and HostCheck.name_of("") is None
    with pytest.raises(SettingsError, match="allowed_hosts"):
        load_settings(None, {"server": {"allowed_hosts": ["http://shm.example.org/"]}})
    assert load_settings(None, {"server": {"allowed_hosts": ["SHM.example.org", "[fd00::1]", "*"]}}).server.allowed_hosts == (
        "shm.example.org", "fd00::1", "*")


def _chunks(total: int, size: int = 4096):
    sent = 0
    while sent < total:
        n = min(size, total - sent)
        yield b"x" * n
        sent += n


def test_chunked_bodies_over_the_limit_are_refused(served):
    """70 kB chunked to /api/baseline (limit 64 kB) was accepted (202): the route never reads its
    body, so the streaming check never ran."""
    service, api = served
    with httpx.Client(base_url=api.url, headers=AUTH) as c:
        r = c.post("/api/baseline", content=_chunks(70_000))
        assert r.status_code == 413 and "limit" in r.json()["detail"]
    with httpx.Client(base_url=api.url, headers=AUTH) as c:
        big = c.post("/api/ingest", content=_chunks(9 * 1024 * 1024, 1 << 16), headers={"Content-Type": "application/json"})
        assert big.status_code == 413
    with httpx.Client(base_url=api.url, headers=AUTH) as c:
        # a chunked body under the limit is read whole and reaches the route
        t0 = 1_767_225_600_000_000_000
        body = ('{"messages": [' + ",".join(
            '{"topic": "/imu/D", "log_time_ns": %d, "payload": {"accel": [-9.81, 0, 0], "gyro": [0, 0, 0.0001]}}'
            % (t0 + i * 5_000_000) for i in range(20)) + "]}").encode()
        r = c.post("/api/ingest", content=(body[i:i + 100] for i in range(0, len(body), 100)),
                   headers={"Content-Type": "application/json"})
        assert r.status_code == 200 and r.json()["accepted"] == 20
        assert c.post("/api/baseline", content=_chunks(1000)).status_code == 202
        # a lying Content-Length is refused before the body is read
        assert c.post("/api/baseline", headers={"Content-Length": "70000"}, content=b"x" * 70_000).status_code == 413


def test_wrong_tokens_are_rate_limited_per_client(served):
    service, api = served
    with httpx.Client(base_url=api.url) as c:
        for _ in range(10):  # a missing token is not a guess
            assert c.post("/api/baseline").status_code == 401
        for k in range(5):
            assert c.post("/api/baseline", headers={"Authorization": f"Bearer guess-{k:04d}"}).status_code == 401
        r = c.post("/api/baseline", headers={"X-SHM-Token": "guess-0005"})
        assert r.status_code == 429 and 1 <= int(r.headers["Retry-After"]) <= 60
        # meanwhile the right token is refused too: a right guess would not be told apart
        assert c.post("/api/baseline", headers=AUTH).status_code == 429
        assert c.get("/api/status").status_code == 200  # the read routes stay open on loopback


def test_limiter_window_and_bounded_memory():
    limiter = AuthLimiter(3, 60.0, max_clients=100)
    for t in (0.0, 1.0, 2.0):
        assert limiter.retry_after("a", now=t) is None
        limiter.failed("a", now=t)
    assert limiter.retry_after("a", now=10.0) == 50
    assert limiter.retry_after("b", now=10.0) is None
    assert limiter.retry_after("a", now=60.5) is None  # the first failure left the window
    for k in range(1000):
        limiter.failed(f"10.0.{k // 256}.{k % 256}", now=100.0)
    assert len(limiter._failures) <= 100
    with pytest.raises(ValueError, match="max_failures"):
        AuthLimiter(0)


def test_off_loopback_every_route_needs_the_token_and_guesses_are_limited(tmp_path):
    service, api = _serve(tmp_path, loopback=False, host="0.0.0.0", auth_failures_per_minute=3)
    try:
        with httpx.Client(base_url=api.url) as c:
            for path in ("/healthz", "/api/status", "/metrics", "/openapi.json", "/docs", "/redoc", "/api/trends",
                         "/nonexistent"):
                assert c.get(path).status_code == 401, path
                assert c.get(path, headers=AUTH).status_code in (200, 404), path
            # an IP literal is fine on a wildcard address; a name is not
            assert c.get("/healthz", headers={**AUTH, "Host": "192.168.7.5:8600"}).status_code == 200
            assert c.get("/healthz", headers={**AUTH, "Host": "rebound.example"}).status_code == 421
            for k in range(3):
                assert c.get("/healthz", headers={"Authorization": f"Bearer guess-{k:04d}"}).status_code == 401
            r = c.get("/healthz", headers=AUTH)
            assert r.status_code == 429 and int(r.headers["Retry-After"]) >= 1
    finally:
        api.stop()
        service.stop(drain_s=0)


def test_serve_refuses_a_dashboard_off_loopback_without_a_token(tmp_path):
    from shm_service.service import ServiceError

    o = fast_overrides(tmp_path, **{"source.spec": "ingest"})
    o["dashboard"] = {"enabled": True, "host": "0.0.0.0", "port": 0}
    with pytest.raises(ServiceError, match="dashboard.host 0.0.0.0 is not loopback: a token is required"):
        MonitoringService(load_settings(None, o), environ={})


def test_generated_and_mutated_requests_get_no_server_error(tmp_path):
    """A short seeded part of benchmarks/http_campaign (10 000 requests there): NaN, huge
    integers, deep nesting, chunked bodies, odd Host and Authorization headers, with and
    without the token, on a loopback API and on one that needs the token everywhere."""
    from benchmarks.http_campaign import campaign

    result = campaign(150, seed=5, workdir=tmp_path)
    assert result["server_errors"] == 0 and result["dropped"] == 0, result["examples"]
    statuses = result["statuses"]
    assert sum(statuses.values()) + result["not_sent"] == 150
    assert {200, 400, 401, 413, 421} <= set(statuses) and result["integrity"] == "ok"
