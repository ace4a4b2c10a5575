"""One service per database: the lock beside the database, real processes."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from shm_service.rig_layouts import default_rig
from shm_service.service.storage.sqlite._lock import DatabaseBusy, DatabaseLock


def test_a_second_lock_is_refused_naming_the_holder_and_released_locks_are_free(tmp_path):
    db = tmp_path / "shm.sqlite"
    with DatabaseLock.acquire(db) as lock:
        assert lock.took_over is None
        record = json.loads(DatabaseLock.path_of(db).read_text())
        assert record["pid"] == os.getpid() and record["host"] == socket.gethostname()
        with pytest.raises(DatabaseBusy, match=f"served by process {os.getpid()} on host '{socket.gethostname()}'"):
            DatabaseLock.acquire(db)
    assert not DatabaseLock.path_of(db).exists()
    DatabaseLock.acquire(db).release()


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    db = tmp_path / "shm.sqlite"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    DatabaseLock.path_of(db).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": 0.0}))
    lock = DatabaseLock.acquire(db)
    try:
        assert lock.took_over is not None and f"process {dead.pid}" in lock.took_over
    finally:
        lock.release()


def test_a_lock_of_another_host_is_honoured(tmp_path):
    db = tmp_path / "shm.sqlite"
    DatabaseLock.path_of(db).write_text(json.dumps({"pid": 1234, "host": "elsewhere", "started": 0.0}))
    with pytest.raises(DatabaseBusy, match="process 1234 on host 'elsewhere'.*delete"):
        DatabaseLock.acquire(db)


def _serve(tmp_path: Path, rig: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])}
    return subprocess.Popen([sys.executable, "-m", "shm_service.cli", "serve", "--source", "ingest", "--rig", str(rig),
                             "--db", str(tmp_path / "shm.sqlite"), "--port", "0", "--no-dashboard", "--no-archive"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _wait_for_api(proc: subprocess.Popen) -> str:
    assert proc.stdout is not None
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if "API at" in line:
            return line
        if not line and proc.poll() is not None:
            raise AssertionError(f"shm serve exited {proc.returncode}: {proc.stderr.read() if proc.stderr else ''}")
    raise AssertionError("shm serve did not start in 180 s")


def test_a_second_service_on_a_served_database_exits_naming_the_first(tmp_path):
    # a rig without truth stations (as examples/dropbear/rig.json) starts an ingest service
    doc = json.loads(default_rig().to_json())
    doc["truth_stations"] = []
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps(doc))
    first = _serve(tmp_path, rig)
    try:
        _wait_for_api(first)
        second = _serve(tmp_path, rig)
        _, err = second.communicate(timeout=120)
        assert second.returncode == 3
        assert f"is served by process {first.pid} on host '{socket.gethostname()}'" in err
        first.send_signal(signal.SIGKILL)  # dies holding the lock: the next one takes it over
        first.wait(timeout=30)
        third = _serve(tmp_path, rig)
        try:
            _wait_for_api(third)
            assert third.stderr is not None
            third.send_signal(signal.SIGTERM)
            third.wait(timeout=60)
            assert f"took over the stale lock of process {first.pid}" in third.stderr.read()
        finally:
            _close(third)
        _close(second)
    finally:
        _close(first)


def _close(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    for stream in (proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()
