"""The HTTP API on a real server (free loopback port), ingest source, real SQLite file:
authentication, validation, size limits, exports, metrics, and a property-based check of the
OpenAPI document (schemathesis)."""

from __future__ import annotations

import time

import httpx
import pytest
from svc_helpers import fast_overrides

from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

TOKEN = "test-token-123"


@pytest.fixture()
def running(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    service.start()
    api = ApiServer(create_app(service, max_body_bytes=2048, max_ingest_bytes=200_000), "127.0.0.1", 0).start()
    yield service, api.url
    api.stop()
    service.stop(drain_s=0)


def _imu_batch(t0: int, n: int, topic: str = "/imu/D"):
    return {"messages": [{"topic": topic, "log_time_ns": t0 + i * 5_000_000,
                          "payload": {"accel": [-9.81, 0.0, 0.0], "gyro": [0.0, 0.0, 1e-4]}} for i in range(n)]}


def test_read_endpoints_and_validation(running):
    service, url = running
    with httpx.Client(base_url=url) as c:
        assert c.get("/healthz").json()["status"] == "ok"
        st = c.get("/api/status").json()
        assert st["sources"][0]["kind"] == "ingest" and "degraded_sensors" in st
        assert c.get("/api/trends").json() == {"rows": [], "count": 0, "total": 0, "truncated": False, "next_cursor": None}
        csv = c.get("/api/trends", params={"format": "csv"})
        assert csv.headers["content-type"].startswith("text/csv") and csv.text.startswith("source,window_start_s")
        assert c.get("/api/trends", params={"from": "2026-01-01T00:00:00Z", "to": "1767312000"}).status_code == 200
        for bad in ({"from": "yesterday"}, {"mode": 0}, {"format": "xml"}, {"from": "10", "to": "5"},
                    {"from": "2026-01-01T00:00:00"}, {"limit": -1}, {"limit": 1_000_001}, {"cursor": "not-ours"},
                    {"cursor": "WyJhbGFybXMiLDVd"}):  # an alarms cursor is not a trends one
            r = c.get("/api/trends", params=bad)
            assert r.status_code == 422 and r.json()["detail"], bad
        assert c.get("/api/alarms").json()["count"] == 0
        assert c.get("/api/alarms", params={"state": "bogus"}).status_code == 422
        assert c.get("/api/spectra/latest").status_code == 404
        metrics = c.get("/metrics")
        assert metrics.headers["content-type"].startswith("text/plain")
        assert "# TYPE shm_source_messages_total counter" in metrics.text


def test_tokens_and_size_limits(running):
    service, url = running
    auth = {"Authorization": f"Bearer {TOKEN}"}
    with httpx.Client(base_url=url) as c:
        assert c.post("/api/baseline").status_code == 401
        assert c.post("/api/baseline", headers={"Authorization": "Bearer wrong-token"}).status_code == 401
        assert c.post("/api/alarms/1/ack", headers={"X-SHM-Token": "nope"}).status_code == 401
        assert c.post("/api/alarms/1/ack", headers=auth).status_code == 404
        assert c.post("/api/alarms/0/ack", headers=auth).status_code == 422
        assert c.post("/api/ingest", json=_imu_batch(10**18, 2)).status_code == 401
        r = c.post("/api/baseline", headers=auth)
        assert r.status_code == 202 and r.json()["state"] == "learning"
        big = c.post("/api/ingest", headers={**auth, "Content-Type": "application/json"}, content=b"x" * 300_000)
        assert big.status_code == 413 and "limit" in big.json()["detail"]
        assert c.post("/api/baseline", headers=auth, content=b"y" * 5000).status_code == 413
    service.token = None  # no token configured: protected actions are disabled
    with httpx.Client(base_url=url) as c:
        r = c.post("/api/baseline", headers=auth)
        assert r.status_code == 403 and "no API token" in r.json()["detail"]


def test_ingest_accepts_valid_and_counts_bad(running):
    service, url = running
    auth = {"Authorization": f"Bearer {TOKEN}"}
    t0 = 1_767_225_600_000_000_000
    with httpx.Client(base_url=url, headers=auth) as c:
        r = c.post("/api/ingest", json=_imu_batch(t0, 50))
        assert r.status_code == 200 and r.json()["accepted"] == 50
        r = c.post("/api/ingest", json=_imu_batch(t0, 3))  # a re-sent batch: duplicate, not backwards
        assert r.json()["accepted"] == 0 and r.json()["rejected_by_reason"] == {"duplicate": 3}
        r = c.post("/api/ingest", json=_imu_batch(t0 - 3 * 5_000_000 + 1, 3))  # stamps never accepted, before the last
        assert r.json()["accepted"] == 0 and r.json()["rejected_by_reason"] == {"backwards": 3}
        assert c.post("/api/ingest", content=b'{"messages": [', headers={"Content-Type": "application/json"}).status_code == 400
        assert c.post("/api/ingest", json={"msgs": []}).status_code == 400
        nan = b'{"messages": [{"topic": "/tof/s1", "log_time_ns": 1767225600000000000, "payload": {"distance": NaN}}]}'
        r = c.post("/api/ingest", content=nan, headers={"Content-Type": "application/json"})
        assert r.status_code == 200 and r.json()["rejected_by_reason"] == {"nonfinite": 1}
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            st = c.get("/api/status").json()
            if st["pipeline"]["samples"] >= 50:
                break
            time.sleep(0.05)
        src = st["sources"][0]
        assert src["messages"] == 50 and src["rejected"] == 7  # 3 duplicate, 3 backwards, 1 NaN
        assert "/imu/s1" in st["degraded_sensors"]  # never sent: reported, not fatal
        assert c.get("/healthz").json()["status"] == "ok"


def test_non_loopback_requires_the_token_everywhere(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest", "server.host": "0.0.0.0"}))
    with pytest.raises(Exception, match="token is required"):
        MonitoringService(settings, environ={})
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    app = create_app(service, loopback=False)
    api = ApiServer(app, "127.0.0.1", 0).start()
    try:
        with httpx.Client(base_url=api.url) as c:
            assert c.get("/api/status").status_code == 401
            assert c.get("/healthz").status_code == 401
            assert c.get("/api/status", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200
    finally:
        api.stop()
        service.stop(drain_s=0)


@pytest.fixture()
def replayed(tmp_path, short_recording):
    """A service that replayed a recording and keeps serving it: trends, alarms, spectra and a
    baseline to describe (the ingest service above has none of them)."""
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": f"replay:{short_recording}", "source.speed": "max",
                                                                "source.keep_running": True, "archive.enabled": False}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    service.start()
    assert service.wait(240)
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    yield service, api.url
    api.stop()
    service.stop(drain_s=0)


def test_openapi_describes_every_success_response(running):
    service, url = running
    with httpx.Client(base_url=url) as c:
        doc = c.get("/openapi.json").json()
    described = 0
    for path, operations in doc["paths"].items():
        for method, operation in operations.items():
            ok = {code: r for code, r in operation["responses"].items() if code.startswith("2")}
            assert ok, f"{method.upper()} {path} documents no success response"
            for code, response in ok.items():
                content = response.get("content")
                assert content, f"{method.upper()} {path} {code}: no content described"
                for media, body in content.items():
                    assert body.get("schema"), f"{method.upper()} {path} {code} {media}: no schema"
                    described += 1
    assert described >= 10
    schemas = doc["components"]["schemas"]
    # The documents of the contract, by name: what a client generates its types from.
    for name in ("StatusDocument", "TrendsDocument", "AlarmsDocument", "AlarmDocument", "SpectrumDocument", "HealthDocument",
                 "BaselineRequestDocument", "IngestResultDocument"):
        assert name in schemas, name
    pipeline = schemas["PipelineStatusDocument"]["properties"]
    assert {"samples", "estimates", "queue_depth", "estimator"} <= set(pipeline)


@pytest.mark.parametrize("which", ["running", "replayed"])
def test_openapi_property_based(which, request):
    """Every operation of the OpenAPI document, with generated parameters and bodies, answers
    without a server error, with a documented status code and content type, and a body that
    conforms to the documented schema; against an empty ingest service and against one with
    trends, alarms, spectra and a baseline."""
    import schemathesis
    from hypothesis import HealthCheck, given, settings

    service, url = request.getfixturevalue(which)
    schema = schemathesis.openapi.from_url(f"{url}/openapi.json")
    checks = [schemathesis.checks.not_a_server_error, schemathesis.checks.status_code_conformance,
              schemathesis.checks.content_type_conformance, schemathesis.checks.response_schema_conformance]
    failures = []
    statuses = set()

    def make(operation):
        @given(case=operation.as_strategy())
        @settings(max_examples=15, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
        def check(case):
            case.headers = {**(case.headers or {}), "Authorization": f"Bearer {TOKEN}"}
            response = case.call()
            statuses.add((operation.label, response.status_code))
            if response.status_code >= 500:
                failures.append((operation.label, response.status_code, response.text[:200]))
            case.validate_response(response, checks=checks)

        return check

    operations = [op.ok() for op in schema.get_all_operations()]
    assert len(operations) >= 9
    for operation in operations:
        make(operation)()
    assert not failures
    if which == "replayed":  # the documents were checked with data in them, not only empty
        for label in ("GET /api/trends", "GET /api/alarms", "GET /api/spectra/latest", "GET /api/status"):
            assert (label, 200) in statuses, label


def test_a_future_stamped_sample_is_rejected_and_later_data_are_processed(running):
    """One sample at +10 years used to stop the pipeline for good."""
    service, url = running
    auth = {"Authorization": f"Bearer {TOKEN}"}
    t0 = time.time_ns() - 60 * 1_000_000_000
    with httpx.Client(base_url=url, headers=auth) as c:
        assert c.post("/api/ingest", json=_imu_batch(t0, 200)).json()["accepted"] == 200
        future = _imu_batch(t0 + 10 * 365 * 86400 * 1_000_000_000, 1)
        r = c.post("/api/ingest", json=future)
        assert r.status_code == 200 and r.json()["rejected_by_reason"] == {"implausible_time": 1}
        health = c.get("/healthz").json()
        assert health["status"] == "degraded" and any("clock jump" in reason for reason in health["reasons"])
        for k in range(1, 6):  # the next 5 s of data
            assert c.post("/api/ingest", json=_imu_batch(t0 + k * 1_000_000_000, 200)).json()["accepted"] == 200
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            st = c.get("/api/status").json()
            if st["pipeline"]["samples"] >= 1200:
                break
            time.sleep(0.05)
        assert st["pipeline"]["samples"] == 1200 and st["pipeline"]["late_samples"] == 0
        assert st["sources"][0]["rejected_by_reason"] == {"implausible_time": 1}
        # NaN and an integer beyond 64 bits in one body: per-message rejections, never a 500,
        # and the valid message's retry is not answered 'duplicate' for a sample never taken
        t = t0 + 6 * 1_000_000_000
        body = ('{"messages": [{"topic": "/tof/s1", "log_time_ns": %d, "payload": {"distance": NaN}}, '
                '{"topic": "/tof/s1", "log_time_ns": %d, "payload": {"distance": 100000000000000000000000000000}}, '
                '{"topic": "/tof/s1", "log_time_ns": %d, "payload": {"distance": 0.5}}]}' % (t, t + 30_000_000, t + 60_000_000))
        r = c.post("/api/ingest", content=body.encode(), headers={"Content-Type": "application/json"})
        assert r.status_code == 200, r.text
        assert r.json()["accepted"] == 1 and r.json()["rejected_by_reason"] == {"nonfinite": 1, "implausible_value": 1}
