"""A stop (SIGTERM) under a backlog ends within seconds and loses nothing committed: the
backlog is estimated for ``stop_drain_s``, the rest set aside — its raw samples in
the recording, every window already written still in the database."""

from __future__ import annotations

import os
import signal
import sqlite3
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import orjson
import pytest
from mcap.reader import make_reader
from svc_helpers import FAST, fast_overrides

from shm_service.recording import classify_topic
from shm_service.rig_layouts import default_rig
from shm_service.service import MonitoringService, load_settings, start_serve

TOKEN = "test-token-backlog"
_PAYLOAD = {"imu": lambda i: {"accel": [-9.81, 0.001 * (i % 7), 0.0], "gyro": [0.0, 0.0, 1e-4 * (i % 5)]},
            "tof": lambda i: {"distance": 0.5 + 1e-4 * (i % 3)}, "strain": lambda i: {"strain": 1e-5 * (i % 4)},
            "bearing": lambda i: {"distance": 0.001}, "temperature": lambda i: {"celsius": 20.0}}
T0 = 1_000_000_000_000  # a backfill of 1970


def _messages(k: int, seconds: float) -> list[dict]:
    """Request ``k`` of a backfill: ``seconds`` of every sensor of the benchmark rig at 200 Hz."""
    topics = [(s.topic, _PAYLOAD[classify_topic(s.topic).kind]) for s in default_rig("benchmark").sensors]
    n = int(seconds * 200)
    return [{"topic": topic, "log_time_ns": T0 + (k * n + i) * 5_000_000, "payload": f(i)}
            for i in range(n) for topic, f in topics]


def _recorded_samples(directory: Path) -> Counter:
    """Raw sensor messages per topic in the service's recordings."""
    out: Counter = Counter()
    for path in sorted(directory.glob("*.mcap")):
        with open(path, "rb") as f:
            for _, channel, _ in make_reader(f).iter_messages():
                if classify_topic(channel.topic) is not None and classify_topic(channel.topic).kind != "estimate":
                    out[channel.topic] += 1
    return out


def test_a_stop_under_a_backlog_sets_it_aside_and_records_what_it_did_not_analyse(tmp_path):
    settings = load_settings(None, fast_overrides(tmp_path, **{"source.spec": "ingest", "queue_batches": 64,
                                                               "stop_drain_s": 0.2}))
    service = MonitoringService(settings, environ={"SHM_TOKEN": TOKEN})
    accepted = 0
    for k in range(16):  # 96 s of data waiting before the pipeline runs: far more than a stop at once estimates
        result = service.ingest({"messages": _messages(k, 6.0)})
        assert result is not None and result.rejected == 0
        accepted += result.accepted
    assert service.queue.qsize() == 16
    service.start()  # and the stop at once: a short drain, the backlog left set aside (however fast the machine)
    service.stop(drain_s=0)  # returns with the backlog set aside, not estimated: the checks below say so
    pipeline = service.pipeline
    aside = pipeline.set_aside
    assert aside.samples > 0  # the backlog was not estimated to its end...
    assert sum(pipeline.samples.values()) + aside.samples == accepted  # ...and every sample was either
    recorded = _recorded_samples(Path(settings.archive.directory))
    assert sum(recorded.values()) == accepted and aside.recorded == aside.samples  # ...and all are in the recording
    with sqlite3.connect(settings.db) as db:
        windows = db.execute("SELECT COUNT(DISTINCT window_start_s) FROM trends").fetchone()[0]
    assert windows == pipeline.windows_committed


def _serve_config(tmp_path: Path) -> Path:
    lines = ["queue_batches = 64", "stop_drain_s = 4.0"]
    for table, values in FAST.items():
        if table in ("analytics", "estimator", "alarms"):
            lines.append(f"[{table}]")
            lines += [f"{key} = {value!r}" for key, value in values.items()]
    path = tmp_path / "serve.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.timeout(600)
def test_sigterm_of_shm_serve_fed_a_backlog_over_http_exits_within_10_s_and_loses_nothing(tmp_path):
    """A real ``shm serve --source ingest`` fed a backfill as fast as it takes it, SIGTERM while the
    client still sends: it exits within 10 s; every sample answered accepted is in its recording
    and every window it had written is still in its database."""
    bodies = [orjson.dumps({"messages": _messages(k, 6.0)}) for k in range(24)]
    env = {**os.environ, "SHM_TOKEN": TOKEN}
    with open(tmp_path / "out.txt", "w") as out, open(tmp_path / "err.txt", "w") as err_file:
        serve = start_serve(["--config", str(_serve_config(tmp_path)), "--source", "ingest", "--no-dashboard", "--port",
                             "0", "--data-dir", str(tmp_path), "--keep-running"], env=env, stdout=out, stderr=err_file)
    headers = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    accepted = [0]
    stop = threading.Event()

    def feed() -> None:
        with httpx.Client(base_url=serve.url, timeout=60, headers=headers) as c:
            for body in bodies:
                while not stop.is_set():
                    try:
                        r = c.post("/api/ingest", content=body)
                    except httpx.HTTPError:
                        return  # the service went away mid-request: that request was not answered accepted
                    if r.status_code == 200:
                        accepted[0] += r.json()["accepted"]
                        break
                    assert r.status_code == 503, r.text
                if stop.is_set():
                    return

    feeder = threading.Thread(target=feed)
    feeder.start()
    try:
        with httpx.Client(base_url=serve.url, timeout=30, headers=headers) as c:
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline:  # until windows were written and a backlog waits
                p = c.get("/api/status").json()["pipeline"]
                if p["windows_committed"] >= 2:  # while the client still sends
                    break
                time.sleep(0.5)
            committed = c.get("/api/trends").json()
        began = time.monotonic()
        serve.process.send_signal(signal.SIGTERM)
        code = serve.process.wait(60)
        took = time.monotonic() - began
    finally:
        stop.set()
        feeder.join(60)
        serve.kill()
    err = (tmp_path / "err.txt").read_text()
    print(f"SIGTERM -> exit {code} in {took:.1f} s; {accepted[0]} samples accepted")
    print(err[-1500:])
    assert took < 10.0, f"SIGTERM took {took:.1f} s:\n{err[-2000:]}"
    assert code == 0, err[-2000:]
    recorded = _recorded_samples(tmp_path / "recordings")
    assert sum(recorded.values()) >= accepted[0] > 0
    rows = committed["rows"] if isinstance(committed, dict) and "rows" in committed else committed
    with sqlite3.connect(tmp_path / "shm.sqlite") as db:
        stored = db.execute("SELECT COUNT(*) FROM trends").fetchone()[0]
    assert stored >= len(rows) > 0
