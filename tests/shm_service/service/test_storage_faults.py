"""Storage faults for real: a full disk (SQLite's own SQLITE_FULL, from
``max_page_count``) while an alarm is raised, and another process holding the write lock."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import threading
import time

import httpx
import pytest
from svc_helpers import fast_overrides

from shm_service.service import (
    AlarmChange,
    ApiServer,
    MonitoringService,
    Storage,
    StorageUnavailable,
    WindowCommit,
    create_app,
    load_settings,
)

TOKEN = "test-token-123"


def _full(storage: Storage, full: bool) -> None:
    with storage._lock:  # between transactions
        pages = storage._db.execute("PRAGMA page_count").fetchone()[0]
        storage._db.execute(f"PRAGMA max_page_count = {pages if full else 1_073_741_823}")


def test_a_commit_that_fails_leaves_nothing_and_the_next_one_works(tmp_path):
    st = Storage(tmp_path / "s.sqlite", notify_targets=[("webhook", "http://127.0.0.1:1/x")], retry_s=0.1)
    change = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 40.0, 6.0, 5.0, "m")
    _full(st, True)
    with pytest.raises(StorageUnavailable, match="full"):
        st.commit_window(WindowCommit("src", 20.0, 40.0, [], {"monitor": "x" * 20000}, None, [change]))
    assert st.failures == 1 and st.retries >= 1 and not st._db.in_transaction
    assert st.alarms() == [] and st.outbox() == []
    _full(st, False)
    st.commit_window(WindowCommit("src", 20.0, 40.0, [], {"monitor": "x" * 20000}, None, [change]))
    assert len(st.alarms()) == 1 and len(st.outbox()) == 1 and st.integrity_check() == "ok"


def test_a_full_disk_while_an_alarm_is_raised_loses_no_alarm(tmp_path, short_recording):
    settings = load_settings(None, fast_overrides(tmp_path, **{
        "source.spec": f"replay:{short_recording}", "source.speed": "max", "archive.enabled": False, "storage_retry_s": 0.1}))
    service = MonitoringService(settings, environ={})
    st, pipeline = service.storage, service.pipeline
    _full(st, True)
    ahead, degraded = [], []

    def watch() -> None:
        while not service.done:
            pending = list(pipeline.commits.pending)
            stored = {a.chart for a in st.alarms(state="active")}
            ahead.extend(set(pipeline.committed_alarms) - stored)  # memory must never be ahead of the database
            if pending:
                degraded.append(service.health())
            first = next((i for i, p in enumerate(pending) if p.commit.alarm_changes), None)
            if first is not None and (len(pending) >= first + 3 or service.source.state != "running"):
                _full(st, False)  # the disk has room again
                return
            time.sleep(0.005)

    watcher = threading.Thread(target=watch)
    service.start()
    watcher.start()
    assert service.wait(240)
    watcher.join(5)
    status, health = service.status(), service.health()
    service.stop(drain_s=0)
    assert pipeline.storage_errors > 0, "the disk was never full while a window was written"
    assert any(h.status == "degraded" and any("storage" in r for r in h.reasons) for h in degraded)
    assert ahead == []
    # processing resumed: the error cleared and every analysed window is stored
    assert status.service.pipeline_error is None and health.status == "ok", health
    assert status.pipeline.windows == status.pipeline.windows_committed > 0
    rows = Storage(settings.db).trends(limit=10**6)
    alarms = Storage(settings.db).alarms()
    assert alarms, "the recording's damage raised no alarm"
    for row in rows:  # every window judged at 'alarm' has its alarm, raised by then
        if row.level == "alarm":
            assert any(a.chart == f"mode{row.mode}" and a.raised_at_s <= row.window_end_s for a in alarms), row


def test_reads_answer_while_another_process_holds_the_write_lock(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest"}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    service.start()
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sqlite3, sys, time\n"
         f"c = sqlite3.connect({str(settings.db)!r}, isolation_level=None)\n"
         "c.execute('BEGIN IMMEDIATE')\nprint('held', flush=True)\ntime.sleep(8)\n"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        auth = {"Authorization": f"Bearer {TOKEN}"}
        with httpx.Client(base_url=api.url, timeout=60) as c:
            answer: dict = {}

            def baseline() -> None:  # an operator's write, waiting for the lock meanwhile
                answer["response"] = c.post("/api/baseline", headers=auth)

            writer = threading.Thread(target=baseline)
            writer.start()
            time.sleep(0.3)
            for path in ("/healthz", "/api/status", "/api/alarms", "/api/trends"):
                r = c.get(path)
                # answered while the write still waits for the lock: a read does not queue behind it
                assert r.status_code == 200 and writer.is_alive(), path
            writer.join(30)
            r = answer["response"]
            assert r.status_code == 503 and r.headers["Retry-After"] and "unavailable" in r.json()["detail"]
            assert holder.poll() is None  # the write gave up while the lock was still held
            holder.kill()
            holder.wait()
            assert c.post("/api/baseline", headers=auth).status_code == 202
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.wait()
        holder.stdout.close()
        api.stop()
        service.stop(drain_s=0)


def test_housekeeping_on_a_locked_database_counts_it_without_a_traceback(tmp_path, caplog):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest", "storage_retry_s": 0.2}))
    service = MonitoringService(settings, environ={})
    try:
        structure = service.primary
        structure.touched(-1)  # samples seen since the last note: the next housekeeping writes
        other = sqlite3.connect(str(settings.db), isolation_level=None)
        other.execute("BEGIN IMMEDIATE")  # another process's writer
        try:
            with caplog.at_level("WARNING", logger="shm.serve"):
                service.housekeeping()
                service.housekeeping()
        finally:
            other.execute("ROLLBACK")
            other.close()
        doc = service.housekeeping_guard.status()
        assert doc.errors_by_kind == {"storage": 2} and "locked" in doc.last_error
        logged = [r for r in caplog.records if "housekeeping storage failed" in r.getMessage()]
        assert len(logged) == 1 and logged[0].exc_info is None  # once, as a line: an expected, passing fault
        service.housekeeping()  # the lock is free: the note is written
        assert service.housekeeping_guard.errors == 2
    finally:
        service.stop(drain_s=0)
