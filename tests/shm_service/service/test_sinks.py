"""Sinks never break the pipeline: the dashboard's live view (the structure's live ring the
dashboard reads through the port) raising on every batch and a webhook that always fails are
isolated, counted by kind in /api/status and /metrics and logged once per kind, and not one sample,
estimate or window is lost; /healthz follows the pipeline and recovers with it."""

from __future__ import annotations

import logging
import time

import httpx
import pytest
from svc_helpers import Receiver, fast_overrides, wait_for

from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

TOKEN = "sink-test-token"


def _replay(tmp_path, recording, *, dashboard: bool, webhook: str | None = None, break_dashboard: bool = False):
    extra = {"source.spec": f"replay:{recording}", "source.speed": "max", "dashboard.enabled": dashboard, "dashboard.port": 0,
             "archive.enabled": False, "db": str(tmp_path / f"shm-{dashboard}.sqlite")}
    if webhook is not None:
        extra.update({"notify.webhooks": [webhook], "notify.retry_initial_s": 0.05, "notify.retry_max_s": 0.1})
    service = MonitoringService(load_settings(None, fast_overrides(tmp_path, **extra)), environ={})
    if break_dashboard:
        assert service.dashboard is not None

        def broken(*args, **kwargs):
            raise RuntimeError("the dashboard's live view is broken")

        service.pipeline.live.add = broken  # what the pipeline hands the dashboard: every batch's estimates
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    service.start()
    try:
        assert service.wait(240)
        if webhook is not None:  # a few more delivery attempts after the last window
            time.sleep(0.5)
        with httpx.Client(base_url=api.url) as c:
            status, metrics, health = c.get("/api/status").json(), c.get("/metrics").text, c.get("/healthz").json()
    finally:
        api.stop()
        service.stop(drain_s=0)
    return status, metrics, health


def test_a_failing_dashboard_and_notifier_lose_nothing(tmp_path, short_recording, caplog):
    reference, _, _ = _replay(tmp_path / "ref", short_recording, dashboard=False)
    receiver = Receiver(fail_first=10**9)  # answers 500 to every notification
    try:
        with caplog.at_level(logging.WARNING):
            status, metrics, health = _replay(tmp_path, short_recording, dashboard=True, webhook=receiver.url,
                                              break_dashboard=True)
    finally:
        receiver.close()
    p, ref = status["pipeline"], reference["pipeline"]
    # nothing lost: the same samples, estimates and windows as without a dashboard
    for key in ("samples", "estimates", "windows", "windows_committed"):
        assert p[key] == ref[key] > 0, key
    assert status["storage"]["trend_rows"] == reference["storage"]["trend_rows"]
    assert status["service"]["pipeline_errors"] == 0 and health["status"] == "ok"
    # counted by kind
    dashboard = status["sinks"]["dashboard"]
    assert set(dashboard["errors_by_kind"]) == {"live"} and dashboard["errors_by_kind"]["live"] > 0
    assert dashboard["errors"] == sum(dashboard["errors_by_kind"].values())
    notifier = status["sinks"]["notifier"]
    assert notifier["errors_by_kind"]["webhook"] == status["notifications"]["failed_attempts_this_run"] >= 2
    assert f'shm_sink_errors_total{{sink="dashboard",kind="live"}} {dashboard["errors"]}' in metrics
    assert 'shm_sink_errors_total{sink="notifier",kind="webhook"}' in metrics
    # logged once per kind
    failures = [r.getMessage() for r in caplog.records if "failed (" in r.getMessage()]
    for sink, kind in (("dashboard", "live"), ("notifier", "webhook")):
        assert sum(m.startswith(f"{sink} {kind} failed") for m in failures) == 1, (sink, kind, failures)


@pytest.fixture()
def ingest_service(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    service.start()
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    yield service, api.url
    api.stop()
    service.stop(drain_s=0)


def _post(c: httpx.Client, start: int) -> None:
    """20 samples of IMU D at rest from ``start`` (ns), ingested with the token."""
    batch = {"messages": [{"topic": "/imu/D", "log_time_ns": start + i * 5_000_000,
                           "payload": {"accel": [-9.81, 0.0, 0.0], "gyro": [0.0, 0.0, 0.0]}} for i in range(20)]}
    assert c.post("/api/ingest", json=batch, headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200


def _status_when(c: httpx.Client, predicate) -> dict:
    """The first /api/status that satisfies ``predicate`` within 20 s."""
    return wait_for(lambda: (st if predicate(st := c.get("/api/status").json()) else None), 20, "the status")


def test_healthz_follows_the_pipeline_and_recovers(ingest_service):
    service, url = ingest_service
    original = service.pipeline.process
    failures = iter([RuntimeError("injected fault")])

    def flaky(batch):
        fault = next(failures, None)
        if fault is not None:
            raise fault
        original(batch)

    service.pipeline.process = flaky
    t0 = 1_767_225_600_000_000_000

    with httpx.Client(base_url=url) as c:
        assert c.get("/healthz").json()["status"] == "ok"
        _post(c, t0)
        st = _status_when(c, lambda st: st["service"]["pipeline_errors"] == 1)
        assert st["service"]["pipeline_error"] == "RuntimeError: injected fault"
        assert c.get("/healthz").json()["status"] == "degraded"
        _post(c, t0 + 10**9)
        # the pipeline counts its samples before the step that ran it clears the error: wait for both
        st = _status_when(c, lambda st: st["pipeline"]["samples"] == 20 and st["service"]["pipeline_error"] is None)
        assert c.get("/healthz").json()["status"] == "ok"
        assert st["service"]["pipeline_errors"] == 1
        assert st["service"]["last_pipeline_error"] == "RuntimeError: injected fault"
        assert "shm_pipeline_errors_total 1" in c.get("/metrics").text


def test_a_failed_joined_batch_counts_each_batch_it_skipped(ingest_service):
    # A structure behind its pace takes up to eight queued batches in one step (joined). When that
    # step fails, every batch in it is lost: the count says how many, not one.
    import threading

    service, url = ingest_service
    original = service.pipeline.process
    release = threading.Event()
    calls: list[int] = []

    def failing_twice(batch):
        calls.append(len(batch.blocks[0]))
        if len(calls) == 1:
            release.wait(20)  # the next posts queue up behind this step
            raise RuntimeError("injected fault")
        if len(calls) == 2:
            raise RuntimeError("injected fault")
        original(batch)

    service.pipeline.process = failing_twice
    t0 = 1_767_225_600_000_000_000

    with httpx.Client(base_url=url) as c:
        _post(c, t0)
        wait_for(lambda: calls, 20, "the first step")
        assert calls == [20]  # the first batch is in the (held) step
        _post(c, t0 + 10**9)
        _post(c, t0 + 2 * 10**9)
        release.set()
        st = _status_when(c, lambda st: st["service"]["pipeline_errors"] >= 3)
        assert calls == [20, 40]  # the two queued batches went as one step
        assert st["service"]["pipeline_errors"] == 3
        assert "shm_pipeline_errors_total 3" in c.get("/metrics").text
