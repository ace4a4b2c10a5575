"""A ``follow:`` source, with the faults made for real on disk: a file that is not
there at start-up (the API comes up meanwhile), a file replaced under the same name (new inode,
shorter, rewritten in place), a deleted file (one problem entry with a count, not one per poll)."""

from __future__ import annotations

import os
import re
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from shm_service.recording import RecordingFollower, RecordingWriter
from shm_service.rig_layouts import default_rig
from shm_service.service import ServeStartError, start_serve

from svc_helpers import fast_overrides, wait_for

_T0 = 1_767_225_600_000_000_000
_STEP = 5_000_000  # 200 Hz


def _imu(i: int) -> dict:
    return {"accel": [-9.81, 0.001 * (i % 7), 0.0], "gyro": [0.0, 0.0, 1e-4 * (i % 5)]}


def _write(path: Path, start: int, n: int, *, close: bool = True, note: str = "a") -> RecordingWriter:
    """``n`` samples of /imu/D from sample number ``start`` (200 Hz), flushed; closed unless told."""
    w = RecordingWriter(path, default_rig("benchmark"), chunk_size=16_384)
    w.add_metadata("note", {"file": note})
    for i in range(start, start + n):
        w.write("/imu/D", _T0 + i * _STEP, _imu(i))
    w.flush()
    if close:
        w.close()
    return w


def _drain(f: RecordingFollower, polls: int = 50) -> int:
    n = 0
    for _ in range(polls):
        n += sum(len(b) for b in f.poll())
    return n


def test_a_replaced_file_is_read_from_its_start(tmp_path):
    path = tmp_path / "live.mcap"
    writer = _write(path, 0, 500, close=False)  # a logger still writing
    f = RecordingFollower(path, reopen_finished=True)
    assert _drain(f) == 500 and not f.finished
    # rotation: a new file moved over the name (os.replace: a new inode), 3000 later samples
    new = tmp_path / "next.mcap"
    _write(new, 500, 3000, note="b")
    os.replace(new, path)
    assert _drain(f) == 3000 and f.replaced == 1
    writer.close()
    assert sum(1 for p in f.report.problems if "replaced" in p) == 1
    # the same file again under a new inode: nothing twice, the repeats counted
    again = tmp_path / "again.mcap"
    _write(again, 500, 3000, note="b")
    os.replace(again, path)
    r = f.topic_reports["/imu/D"]
    assert _drain(f) == 0 and (r := f.topic_reports["/imu/D"]).duplicate + r.backwards == 3000
    # rewritten in place (same inode), shorter: detected, its new samples taken
    with open(path, "r+b") as fh:
        fh.truncate(0)
    _write(path, 3500, 200, note="c")
    assert _drain(f) == 200 and f.replaced == 3
    # rewritten in place, as long or longer, with another start (metadata differs): detected
    _write(path, 3700, 400, note="d-different-start")
    assert _drain(f) == 400 and f.replaced == 4
    assert f.topic_reports["/imu/D"].accepted == 500 + 3000 + 200 + 400


def test_a_deleted_file_gives_one_problem_with_a_count(tmp_path):
    path = tmp_path / "live.mcap"
    _write(path, 0, 100)
    f = RecordingFollower(path, reopen_finished=True)
    assert _drain(f) == 100
    path.unlink()
    for _ in range(200):
        assert f.poll() == []
    missing = [p for p in f.report.problems if "does not exist" in p]
    assert len(missing) == 1 and "seen 200 times" in missing[0] and f.missing
    assert len(f.report.problems) == 1
    _write(path, 100, 50)  # it comes back: read from its start
    assert _drain(f) == 50 and not f.missing


def test_a_missing_file_waits_without_a_problem_per_poll(tmp_path):
    f = RecordingFollower(tmp_path / "later.mcap")
    for _ in range(30):
        assert f.poll() == []
    assert f.missing and len(f.report.problems) == 1 and "seen 30 times" in f.report.problems[0]


def _serve(tmp_path: Path, path: Path) -> tuple[subprocess.Popen, str]:
    o = fast_overrides(tmp_path)
    toml = tmp_path / "serve.toml"
    a, e = o["analytics"], o["estimator"]
    toml.write_text(
        f'db = "{o["db"]}"\n[server]\nport = 0\n[dashboard]\nenabled = false\n[archive]\nenabled = false\n'
        f'[source]\nfollow_poll_s = 0.05\n'
        f'[analytics]\nwindow_s = {a["window_s"]}\noverlap = {a["overlap"]}\nbaseline_s = {a["baseline_s"]}\n'
        f'baseline_min_windows = {a["baseline_min_windows"]}\n'
        f'[estimator]\ncalibration_s = {e["calibration_s"]}\nwarmup_s = {e["warmup_s"]}\nchunk_s = {e["chunk_s"]}\n')
    serve = start_serve(["--config", str(toml), "--source", f"follow:{path}"], stdout=subprocess.DEVNULL,
                        stderr=subprocess.PIPE, env={**os.environ, "SHM_TOKEN": "test-token-123"}, timeout=None,
                        ready_file=tmp_path / "ready.json")
    try:
        serve.wait_ready(60)
    except ServeStartError as exc:
        serve.kill()
        pytest.fail(f"shm serve did not start ({exc}): {serve.process.stderr.read()[-2000:]}")
    return serve.process, serve.url




def test_serve_follow_of_a_missing_file_serves_the_api_and_starts_when_it_appears(tmp_path):
    """A missing file blocked start-up (no API) for up to 24 h; a replaced one gave 0 of 3000
    samples; a deleted one added a problem per poll. ``shm serve`` as a subprocess."""
    path = tmp_path / "live.mcap"
    proc, url = _serve(tmp_path, path)
    try:
        with httpx.Client(base_url=url, timeout=10) as c:
            health = c.get("/healthz").json()
            assert health["status"] == "degraded" and any("waiting for" in r and str(path) in r for r in health["reasons"])
            r = c.get("/api/status")
            assert r.status_code == 503 and "waiting for" in r.json()["detail"] and r.headers["Retry-After"]
            writer = _write(path, 0, 2000, close=False)
            st = wait_for(lambda: (s := c.get("/api/status")).status_code == 200 and s.json()["sources"][0]["messages"] >= 2000
                       and s.json())
            assert st["sources"][0]["kind"] == "follow" and st["sources"][0]["messages"] == 2000
            new = tmp_path / "rotated.mcap"
            _write(new, 2000, 3000, note="b")
            os.replace(new, path)
            writer.close()
            st = wait_for(lambda: (s := c.get("/api/status").json())["sources"][0]["messages"] >= 5000 and s)
            assert st["sources"][0]["messages"] == 5000
            assert sum("replaced" in p for p in st["sources"][0]["problems"]) == 1
            path.unlink()
            time.sleep(1.0)  # ~20 polls
            st = wait_for(lambda: (s := c.get("/api/status").json())["sources"][0]["state"] == "waiting for the file" and s)
            problems = st["sources"][0]["problems"]
            assert sum("does not exist" in p for p in problems) <= 2  # the follower's entry (counted) and the health line
            assert any(re.search(r"does not exist.*seen \d+ times", p) for p in problems)
            assert c.get("/healthz").json()["status"] == "degraded"
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        proc.stderr.close()
