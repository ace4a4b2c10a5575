"""The process side of ``shm serve``: the ready document, ending with the parent however it ends
(real processes, SIGKILL of the parent), a front that finds an earlier front's worker on its
database, and the one helper that starts ``shm serve``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from shm_service.service import ServeStartError, read_ready, start_serve
from shm_service.service.runtime._processes import (
    DEATHSIG_ENV,
    end_with_parent,
    hold_worker_lock,
    stale_worker_pids,
    stop_stale_workers,
    write_ready,
)

ROOT = Path(__file__).resolve().parents[3]
needs_proc = pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads /proc")


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _gone_within(pid: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not _alive(pid)


def test_the_ready_document_is_written_whole_and_read_back(tmp_path):
    path = tmp_path / "ready.json"
    assert read_ready(path) is None
    write_ready(path, {"state": "serving", "api": "http://127.0.0.1:1234"})
    doc = read_ready(path)
    assert doc == {"version": 1, "pid": os.getpid(), "state": "serving", "api": "http://127.0.0.1:1234"}
    assert [p.name for p in tmp_path.iterdir()] == ["ready.json"]  # no temporary file left


def test_a_document_of_another_version_is_refused(tmp_path):
    path = tmp_path / "ready.json"
    path.write_text('{"version": 99, "api": "x"}')
    with pytest.raises(ValueError, match="version 1"):
        read_ready(path)


def test_a_parent_pid_must_be_positive():
    with pytest.raises(ValueError, match="parent_pid 0"):
        end_with_parent(0)


_CHILD = """
import signal, sys, time
from shm_service.service.runtime._processes import end_with_parent
signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
end_with_parent(int(sys.argv[1]), grace_s=2.0, poll_s=0.05)
time.sleep(600)
"""

_PARENT = """
import os, subprocess, sys, time
env = dict(os.environ)
if sys.argv[1] == "deathsig":
    env["{key}"] = "1"
else:
    env.pop("{key}", None)
child = subprocess.Popen([sys.executable, "-c", sys.argv[2], str(os.getpid())], env=env)
print(child.pid, flush=True)
time.sleep(600)
"""


@needs_proc
@pytest.mark.parametrize("how", ["deathsig", "watch"])
def test_a_child_ends_when_its_parent_is_killed(how):
    """SIGKILL of the parent: the child ends (the kernel's PDEATHSIG on Linux, else the watcher)."""
    parent = subprocess.Popen([sys.executable, "-c", _PARENT.replace("{key}", DEATHSIG_ENV), how, _CHILD],
                              stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        child = int(parent.stdout.readline())
        time.sleep(1.0)  # the child is up and watching
        assert _alive(child)
        parent.kill()
        parent.wait(10)
        assert _gone_within(child, 10.0)
    finally:
        parent.kill()
        parent.wait(10)
        parent.stdout.close()


_FAKE_WORKER = """
import signal, sys, time
from shm_service.service.runtime._processes import hold_worker_lock
lock = hold_worker_lock(sys.argv[1])
if sys.argv[2] == "stubborn":
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
print("locked", flush=True)
time.sleep(600)
"""


@needs_proc
@pytest.mark.parametrize("kind", ["polite", "stubborn"])
def test_a_front_ends_the_workers_an_earlier_front_left_on_its_database(tmp_path, kind):
    """A worker of an earlier front (it holds the database's worker lock, its command line is a
    worker's of this configuration) is ended before a new front starts: SIGTERM, else SIGKILL."""
    db, config = tmp_path / "shm.sqlite", tmp_path / "fleet-workers.toml"
    assert stop_stale_workers(db, str(config)) == []  # nobody there
    worker = subprocess.Popen([sys.executable, "-c", _FAKE_WORKER, str(db), kind, "serve", "--worker-of", "0/2",
                               "--config", str(config)], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert worker.stdout.readline().strip() == "locked"
        assert stale_worker_pids(db, str(config)) == [worker.pid]
        assert stop_stale_workers(db, str(config), term_s=1.0, kill_s=5.0) == [worker.pid]
        worker.wait(5)
        assert worker.returncode == (-signal.SIGTERM if kind == "polite" else -signal.SIGKILL)
        lock = hold_worker_lock(db)  # free again
        lock.close()
    finally:
        worker.kill()
        worker.wait(10)
        worker.stdout.close()


def test_start_serve_reports_a_process_that_ends_before_it_is_ready(tmp_path):
    with pytest.raises(ServeStartError, match="exit code 2"):
        start_serve(["--config", str(tmp_path / "missing.toml")], stderr=subprocess.DEVNULL, timeout=60)


def test_start_serve_knows_only_serve_and_demo():
    with pytest.raises(ValueError, match="'estimate'"):
        start_serve([], command="estimate")


def test_start_serve_gives_the_api_of_a_running_service(tmp_path):
    """``shm serve`` on an ingest source: its ready document names the API that answers."""
    import httpx

    serve = start_serve(["--source", "ingest", "--port", "0", "--no-dashboard", "--no-archive",
                         "--data-dir", str(tmp_path)], cwd=tmp_path, stdout=subprocess.DEVNULL, timeout=120,
                        ready_file=tmp_path / "ready.json")
    try:
        assert serve.ready["state"] == "serving" and serve.ready["pid"] == serve.pid
        assert serve.ready["docs"] == serve.url + "/docs" and serve.dashboard_url is None
        assert httpx.get(serve.url + "/healthz", timeout=30).status_code == 200
    finally:
        assert serve.stop() == 0
