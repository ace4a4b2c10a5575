"""/api/trends says what it holds (issue 26): a cut answer is flagged in JSON and in the CSV's
headers. Real server, real SQLite file, real requests."""

from __future__ import annotations

import httpx
import pytest

from shm_service.service._api import create_app
from shm_service.service._config import load_settings
from shm_service.service._server import ApiServer
from shm_service.service._service import MonitoringService

from svc_helpers import fast_overrides


@pytest.fixture()
def running(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": "t0ken-for-tests"})
    service.start()
    with service.storage.transaction() as db:  # five windows of one mode
        db.executemany("INSERT INTO trends (source, window_start_s, window_end_s, mode, unit, kind, frequency_hz, created_at) "
                       "VALUES ('ingest', ?, ?, 1, 1, 'ambient', 1.5, 0.0)", [(60.0 * k, 60.0 * k + 60.0) for k in range(5)])
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    yield api.url
    api.stop()
    service.stop(drain_s=0)


def test_a_limit_below_the_history_says_there_is_more(running):
    with httpx.Client(base_url=running) as c:
        doc = c.get("/api/trends", params={"limit": 3}).json()
        assert doc["count"] == 3 and doc["truncated"] is True
        assert [r["window_start_s"] for r in doc["rows"]] == [0.0, 60.0, 120.0]
        doc = c.get("/api/trends", params={"limit": 5}).json()
        assert doc["count"] == 5 and doc["truncated"] is False
        rest = c.get("/api/trends", params={"limit": 3, "from": "180"}).json()
        assert [r["window_start_s"] for r in rest["rows"]] == [180.0, 240.0] and rest["truncated"] is False
        csv = c.get("/api/trends", params={"limit": 3, "format": "csv"})
        assert csv.headers["x-truncated"] == "true" and csv.headers["x-count"] == "3"
        assert len(csv.text.strip().splitlines()) == 4
        csv = c.get("/api/trends", params={"format": "csv"})
        assert csv.headers["x-truncated"] == "false" and csv.headers["x-count"] == "5"
