"""The list routes say what they hold and page with a cursor: a cut answer is flagged,
counted and continued, in JSON and in the CSV's headers. Real server, real SQLite file, real
requests."""

from __future__ import annotations

import httpx
import pytest
from svc_helpers import fast_overrides

from shm_service.service import ApiServer, MonitoringService, create_app, load_settings


@pytest.fixture()
def served_db(storage_target, tmp_path) -> str:
    """The running service's database: the SQLite file of its data directory, or a PostgreSQL database."""
    return str(tmp_path / "shm.sqlite") if storage_target.endswith(".sqlite") else storage_target


@pytest.fixture()
def running(tmp_path, served_db):
    overrides = fast_overrides(tmp_path, **{"source.spec": "ingest"})
    if not served_db.endswith(".sqlite"):
        overrides["storage"] = {"url": served_db}
        del overrides["db"]
    settings = load_settings(None, overrides)
    assert settings.db == served_db
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


def test_pages_by_cursor_hold_every_row_once(running):
    with httpx.Client(base_url=running) as c:
        first = c.get("/api/trends", params={"limit": 2})
        doc = first.json()
        assert (doc["count"], doc["total"], doc["truncated"]) == (2, 5, True) and doc["next_cursor"]
        assert first.headers["x-total-count"] == "5" and first.headers["x-next-cursor"] == doc["next_cursor"]
        starts = [r["window_start_s"] for r in doc["rows"]]
        pages, page = 1, first
        while doc["truncated"]:
            link = page.headers["link"]
            assert link.endswith('>; rel="next"') and "cursor=" in link
            page = c.get(link[1:link.index(">")])  # the Link header's URL is the next page
            doc = page.json()
            assert doc["total"] == 5
            starts += [r["window_start_s"] for r in doc["rows"]]
            pages += 1
        assert starts == [0.0, 60.0, 120.0, 180.0, 240.0] and pages == 3
        assert doc["next_cursor"] is None and "link" not in page.headers and "x-next-cursor" not in page.headers
        # CSV pages the same way, the counts in its headers
        csv = c.get("/api/trends", params={"limit": 4, "format": "csv", "from": "60"})
        assert (csv.headers["x-count"], csv.headers["x-total-count"], csv.headers["x-truncated"]) == ("4", "4", "false")
        cut = c.get("/api/trends", params={"limit": 3, "format": "csv"})
        rest = c.get("/api/trends", params={"limit": 3, "format": "csv", "cursor": cut.headers["x-next-cursor"]})
        assert [line.split(",")[1] for line in rest.text.splitlines()[1:]] == ["180.0", "240.0"]
        assert rest.headers["x-total-count"] == "5" and rest.headers["x-count"] == "2"


def test_a_cursor_of_another_list_or_not_ours_is_refused(running):
    with httpx.Client(base_url=running) as c:
        trends_cursor = c.get("/api/trends", params={"limit": 1}).json()["next_cursor"]
        r = c.get("/api/alarms", params={"cursor": trends_cursor})
        assert r.status_code == 422 and "cursor" in r.json()["detail"]
        for bad in ("x", "%%%", "WyJ0cmVuZHMiLDFd"):  # the last: ["trends",1], a key of the wrong shape
            r = c.get("/api/trends", params={"cursor": bad})
            assert r.status_code == 422 and bad[:20] in r.json()["detail"], bad


def test_alarms_page_newest_first(running, served_db):
    import time

    from shm_service.service import AlarmChange, Storage, WindowCommit

    storage = Storage(served_db)
    for k in range(5):
        change = AlarmChange("raise", f"mode{k + 1}", "frequency", k + 1, "warning", 100.0 + k, 1.0, 0.5, f"alarm {k}")
        storage.commit_window(WindowCommit("ingest", 100.0 + k, time.time(), [], None, None, [change]))
    storage.close()
    with httpx.Client(base_url=running) as c:
        doc = c.get("/api/alarms", params={"limit": 2}).json()
        assert (doc["count"], doc["total"], doc["truncated"]) == (2, 5, True)
        ids = [a["id"] for a in doc["alarms"]]
        while doc["truncated"]:
            doc = c.get("/api/alarms", params={"limit": 2, "cursor": doc["next_cursor"]}).json()
            ids += [a["id"] for a in doc["alarms"]]
        assert ids == sorted(ids, reverse=True) and len(set(ids)) == 5
        active = c.get("/api/structures/ingest/alarms", params={"state": "active", "limit": 4}).json()
        assert (active["count"], active["total"], active["truncated"]) == (4, 5, True)


def test_the_apps_lifespan_starts_and_stops_its_port(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": "t0ken-for-tests"})
    structure = next(iter(service.structures.values()))
    assert not structure.started
    api = ApiServer(create_app(service, start_port=True), "127.0.0.1", 0).start()
    try:
        assert structure.started and not service._stopping.is_set()
        with httpx.Client(base_url=api.url) as c:
            assert c.get("/api/trends").json()["total"] == 0
    finally:
        api.stop()
    assert service._stopping.is_set()  # stopped by the app's lifespan, with the server


def test_the_structures_of_a_fleet_page_in_their_order(tmp_path):
    settings = load_settings(None, {**fast_overrides(tmp_path), "workers": 1, "archive": {"enabled": False},
                                    "structures": [{"id": i, "source": "ingest"} for i in ("c", "a", "b")]})
    service = MonitoringService(settings, environ={})
    api = ApiServer(create_app(service, start_port=True), "127.0.0.1", 0).start()
    try:
        with httpx.Client(base_url=api.url) as c:
            whole = c.get("/api/structures").json()
            assert [s["id"] for s in whole["structures"]] == ["c", "a", "b"]
            assert (whole["count"], whole["total"], whole["truncated"], whole["next_cursor"]) == (3, 3, False, None)
            first = c.get("/api/structures", params={"limit": 2})
            assert [s["id"] for s in first.json()["structures"]] == ["c", "a"] and first.json()["truncated"]
            assert first.headers["x-total-count"] == "3" and first.headers["x-next-cursor"] == first.json()["next_cursor"]
            rest = c.get("/api/structures", params={"limit": 2, "cursor": first.json()["next_cursor"]}).json()
            assert [s["id"] for s in rest["structures"]] == ["b"] and not rest["truncated"] and rest["total"] == 3
            trends_cursor = c.get("/api/trends", params={"limit": 1}).json()["next_cursor"]
            assert trends_cursor is None  # no rows: nothing follows
            assert c.get("/api/structures", params={"cursor": "bm90LW91cnM"}).status_code == 422
    finally:
        api.stop()
