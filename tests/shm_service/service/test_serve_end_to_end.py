"""End to end: replay into a real SQLite file (trend rows, no duplicates on a second replay,
recordings readable), truncated input, and SIGKILL mid-run of ``shm serve`` as a subprocess
with a real webhook receiver: nothing committed is lost, no notification is sent twice."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from svc_helpers import fast_overrides

from shm_service.recording import read_recording
from shm_service.service import ArchiveSettings, MonitoringService, Storage, load_settings

ROOT = Path(__file__).resolve().parents[3]


def _replay(tmp_path, recording, url=None, **extra):
    overrides = fast_overrides(tmp_path, **{"source.spec": f"replay:{recording}", "source.speed": "max", **extra})
    if url is not None:  # the PostgreSQL storage instead of the data directory's SQLite file
        del overrides["db"]
        overrides["storage"] = {"url": url}
    settings = load_settings(None, overrides)
    service = MonitoringService(settings, environ={})
    service.start()
    assert service.wait(120)
    status = service.status()
    service.stop(drain_s=0)
    return status


def _stored(db: str) -> tuple[list[tuple], int]:
    storage = Storage(db)
    try:
        return [(r.window_start_s, r.mode, r.frequency_hz) for r in storage.trends()], storage.count("alarms")
    finally:
        storage.close()


def test_replay_stores_trends_once_and_records_estimates(tmp_path, short_recording, storage_target):
    url = None if storage_target.endswith(".sqlite") else storage_target
    db = url or str(tmp_path / "shm.sqlite")
    st = _replay(tmp_path, short_recording, url)
    assert st.sources[0].state == "finished" and st.service.pipeline_error is None and st.service.pipeline_errors == 0
    rows, alarms = _stored(db)
    starts = sorted({r[0] for r in rows})
    assert len(starts) >= 8 and max(abs(b - a) for a, b in zip(starts, starts[1:])) <= 300
    assert {r[1] for r in rows} == {1, 2, 3, 4, 5}
    st2 = _replay(tmp_path, short_recording, url, **{"archive.enabled": False})
    assert st2.pipeline.windows == 0  # every window already stored
    assert _stored(db) == (rows, alarms)
    files = sorted((tmp_path / "recordings").glob("*.mcap"))
    assert files
    rec = read_recording(files[0])
    decimation = ArchiveSettings().estimate_decimation  # every n-th 200 Hz estimate is recorded
    assert len(rec.channels["/estimate/state"]) > 0.5 * 200 * 150 / decimation and not rec.report.truncated


def test_truncated_replay_keeps_what_is_valid(tmp_path, short_recording):
    cut = tmp_path / "cut.mcap"
    data = short_recording.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    st = _replay(tmp_path, cut)
    src = st.sources[0]
    assert src.state == "finished" and src.messages > 100_000
    assert any("cut off" in p for p in src.problems)


def test_silent_sensor_is_degraded_and_estimation_goes_on(tmp_path):
    from shm_service.recording import RecordingWriter
    from shm_service.virtual_rig import SimulationSettings, VirtualRig
    from shm_service.virtual_rig._record import encode_payloads

    vr = VirtualRig(SimulationSettings(duration=40.0, rest=10.0, excitation="ambient", seed=5))
    path = tmp_path / "silent.mcap"
    start = vr.settings.start_time_ns
    with RecordingWriter(path, vr.nominal_rig) as w:
        for block in vr.blocks(5.0):
            for topic, (times, values) in block.measurements.items():
                if topic == "/imu/s2" and times[0] >= 20.0:
                    continue  # the sensor goes silent after 20 s
                for t, p in zip(times.tolist(), encode_payloads(topic, values)):
                    w.write(topic, start + int(round(t * 1e9)), p)
    st = _replay(tmp_path, path)
    assert "/imu/s2" in st.degraded_sensors
    assert st.pipeline.estimates > 7000  # the estimator carried on (40 s at 200 Hz, less the tail)
    assert any(d.sensor == "/imu/s2" for d in st.pipeline.estimator.degraded_imus)


def _serve(tmp_path, recording, webhook, speed, *extra):
    cfg = fast_overrides(tmp_path)
    toml = tmp_path / "serve.toml"
    import tomli_w

    cfg.pop("db")
    toml.write_text(tomli_w.dumps(cfg))
    cmd = [sys.executable, "-m", "shm_service.cli", "serve", "--config", str(toml), "--source", f"replay:{recording}",
           "--speed", speed, "--no-dashboard", "--port", "0", "--db", str(tmp_path / "shm.sqlite"), "--webhook", webhook,
           "--json", *extra]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _snapshot(db):
    con = sqlite3.connect(db)
    try:
        trends = con.execute("SELECT source, window_start_s, mode, frequency_hz FROM trends").fetchall()
        alarms = con.execute("SELECT id, chart, raised_at_s FROM alarms").fetchall()
        sent = con.execute("SELECT id FROM outbox WHERE status='sent'").fetchall()
    finally:
        con.close()
    return set(trends), set(alarms), {r[0] for r in sent}


def test_sigkill_mid_run_loses_nothing_and_sends_no_duplicate(tmp_path, short_recording, receiver):
    db = tmp_path / "shm.sqlite"
    # --keep-running: on a loaded machine the replay may end before the first notification is
    # out; the kill must find the service alive either way (it comes mid-replay when not loaded).
    proc = _serve(tmp_path, short_recording, receiver.url, "4", "--keep-running")
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            if db.exists() and receiver.posts:
                trends, alarms, sent = _snapshot(db)
                if len(trends) >= 10 and sent:
                    break
            if proc.poll() is not None:
                pytest.fail(f"serve ended early: {proc.stderr.read().decode()[-2000:]}")
            time.sleep(0.1)
        else:
            pytest.fail("no trend rows and notifications in time")
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)  # closes the pipes
    before_trends, before_alarms, before_sent = _snapshot(db)
    posts_before = len(receiver.posts)
    proc = _serve(tmp_path, short_recording, receiver.url, "max")
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err.decode()[-2000:]
    summary = json.loads(out.decode().strip().splitlines()[-1])
    assert summary["state"] == "finished"
    after_trends, after_alarms, after_sent = _snapshot(db)
    assert before_trends <= after_trends and before_alarms <= after_alarms and before_sent <= after_sent
    assert len(after_trends) > len(before_trends)
    # every notification delivered, including those pending at the kill; again only the one that
    # was in flight at the kill (answered, not yet marked sent: at most one for the one target),
    # with the same Idempotency-Key, so a deduplicating receiver sees each exactly once
    unique = set(receiver.keys)
    assert len(unique) >= posts_before - 1 and len(receiver.keys) - len(unique) <= 1
    con = sqlite3.connect(db)
    outbox = con.execute("SELECT status, COUNT(*) FROM outbox GROUP BY status").fetchall()
    logged = con.execute("SELECT COUNT(*) FROM notification_log WHERE ok=1").fetchone()[0]
    con.close()
    assert dict(outbox) == {"sent": len(unique)} and logged == len(unique)


def test_replay_of_a_recording_written_channel_after_channel(tmp_path):
    # The contract lets another tool write one channel after the other (not interleaved in time):
    # the replay merges by log_time and loses nothing.
    from benchmarks.other_tool import write_other_tool_recording
    from shm_service.virtual_rig import SimulationSettings

    path = tmp_path / "other.mcap"
    write_other_tool_recording(path, SimulationSettings(duration=60.0, rest=10.0, excitation="ambient", seed=4, ideal=True))
    st = _replay(tmp_path, path)
    src = st.sources[0]
    assert src.state == "finished" and src.dropped == 0 and src.rejected == 0
    assert st.pipeline.estimates > 59 * 200


def test_replay_with_the_dashboard_on_commits_every_window_and_logs_no_error(tmp_path, short_recording):
    """``shm serve`` as a subprocess with its dashboard on (free port), the log read afterwards."""
    import tomli_w

    cfg = fast_overrides(tmp_path)
    cfg.pop("db")
    cfg["dashboard"] = {"enabled": True, "port": 0}
    toml = tmp_path / "serve.toml"
    toml.write_text(tomli_w.dumps(cfg))
    db = tmp_path / "shm.sqlite"
    cmd = [sys.executable, "-m", "shm_service.cli", "serve", "--config", str(toml), "--source", f"replay:{short_recording}",
           "--speed", "max", "--port", "0", "--db", str(db), "--json"]
    proc = subprocess.run(cmd, cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=300)
    log = proc.stderr
    assert proc.returncode == 0, log[-3000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["state"] == "finished" and summary["pipeline_errors"] == 0 and summary["sink_errors"] == {}, summary
    # every analysed window was committed, and the committed windows reach the end of the recording
    assert summary["windows"] == summary["windows_committed"] >= 8, summary
    con = sqlite3.connect(db)
    starts = [r[0] for r in con.execute("SELECT DISTINCT window_start_s FROM trends ORDER BY window_start_s")]
    con.close()
    assert len(starts) == summary["windows_committed"]
    rec = read_recording(short_recording)
    window = cfg["analytics"]["window_s"]
    step = window * (1 - cfg["analytics"]["overlap"])
    assert rec.end_ns / 1e9 - (starts[-1] + window) < step + 1e-6
    assert all(abs(b - a - step) < 1e-6 for a, b in zip(starts, starts[1:])), "a window is missing"
    levels = [line.split()[2] for line in log.splitlines() if len(line.split()) > 2]
    assert "Traceback" not in log and "ERROR" not in levels and "WARNING" not in levels, log[-3000:]
    assert "dashboard at http://" in proc.stdout
