"""One writer per database: a fleet's workers hand their writes to the front's
``WriterServer`` and only read the database; a worker killed mid-stream loses no committed
window and doubles nothing; a window sent again changes nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from contract import TrendRow
from shm_service.service import AlarmChange, Storage, StorageUnavailable, WindowCommit
from shm_service.service.storage._writer import WRITER_ADDRESS, WRITER_KEY, RemoteStorage, WriterServer, open_storage


def _window(source: str, k: int, alarm: str | None = None) -> WindowCommit:
    rows = [TrendRow(source=source, window_start_s=60.0 * k, window_end_s=60.0 * k + 60.0, mode=m, unit=m, kind="ambient",
                     frequency_hz=1.0 * m) for m in (1, 2)]
    changes = [] if alarm is None else [AlarmChange(alarm, "mode1", "frequency", 1, "warning", 60.0 * k, 1.2, 1.0, "shift")]
    return WindowCommit(source, 60.0 * k, 60.0 * k + 60.0, rows, {"window": k}, None, changes)


@pytest.fixture()
def front(tmp_path):
    storage = Storage(tmp_path / "shm.sqlite", notify_targets=[("webhook", "http://127.0.0.1:9/x")])
    server = WriterServer(storage)
    yield storage, server
    server.stop()
    storage.close()


def test_a_worker_writes_through_the_front_and_never_itself(front, tmp_path):
    storage, server = front
    worker = open_storage(tmp_path / "shm.sqlite", environ=server.environ())
    assert isinstance(worker, RemoteStorage)
    own: list[str] = []
    worker._db.set_trace_callback(own.append)  # the worker's own writing connection stays silent
    assert worker.commit_window(_window("a", 0)) == []
    events = worker.commit_window(_window("a", 1, alarm="raise"))
    assert len(events) == 1 and server.calls == 2
    worker.touch_source("a", "sim", "", time.time())
    baseline = worker.request_baseline("a")
    assert baseline >= 1
    # what the worker reads it reads itself: the front's commits, at once
    assert [r.window_start_s for r in worker.trends(source="a")] == [0.0, 0.0, 60.0, 60.0]
    assert worker.load_state("a")["monitor"] is None  # the baseline request reset the monitor
    assert [a.chart for a in worker.alarms(state="active")] == ["mode1"]
    assert not [s for s in own if not s.startswith(("SELECT", "PRAGMA"))], own
    # its errors cross as themselves
    bad = _window("a", 2)
    bad.rows[0] = bad.rows[0].model_copy(update={"source": "b"})
    with pytest.raises(ValueError, match="source 'b' in a commit of source 'a'"):
        worker.commit_window(bad)
    assert storage.count("trends") == 4 and storage.integrity_check() == "ok"
    worker.close()


def test_a_window_sent_again_changes_nothing(front, tmp_path):
    storage, server = front
    worker = open_storage(tmp_path / "shm.sqlite", environ=server.environ())
    first = worker.commit_window(_window("a", 3, alarm="raise"))
    again = worker.commit_window(_window("a", 3, alarm="raise"))  # its answer was lost: sent again
    assert len(first) == 1 and again == []
    assert storage.count("trends") == 2 and storage.count("alarms") == 1 and storage.count("alarm_events") == 1
    assert storage.count("outbox") == 1
    cleared = worker.commit_window(_window("a", 4, alarm="clear"))
    assert len(cleared) == 1 and worker.commit_window(_window("a", 4, alarm="clear")) == []
    assert storage.count("alarm_events") == 2 and storage.count("outbox") == 2
    worker.close()


def test_a_writer_gone_is_a_passing_fault_for_the_worker(front, tmp_path):
    storage, server = front
    worker = RemoteStorage(tmp_path / "shm.sqlite", server.address, server.key, answer_s=5.0)
    worker.commit_window(_window("a", 0))
    server.stop()
    with pytest.raises(StorageUnavailable, match="writer"):
        worker.commit_window(_window("a", 1))
    wrong = RemoteStorage(tmp_path / "shm.sqlite", server.address, b"not the key")
    with pytest.raises(StorageUnavailable):
        wrong.touch_source("a", "sim", "", 0.0)
    worker.close()
    wrong.close()


_WORKER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {tests!r})
    from test_one_writer import _window
    from shm_service.service.storage._writer import open_storage
    storage = open_storage({db!r})
    for k in range(100000):
        storage.commit_window(_window("k", k, alarm="raise" if k % 2 == 0 else "clear"))
        print(k, flush=True)
""")


def test_a_worker_killed_mid_stream_loses_and_doubles_nothing(front, tmp_path):
    storage, server = front
    db = str(tmp_path / "shm.sqlite")
    env = {**os.environ, **server.environ()}
    assert env[WRITER_ADDRESS] and env[WRITER_KEY]
    script = _WORKER.format(tests=os.path.dirname(__file__), db=db)
    process = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, text=True)
    acked = -1
    for line in process.stdout:
        acked = int(line)
        if acked >= 40:
            break
    process.send_signal(signal.SIGKILL)  # between, during or after a commit: wherever it is
    process.wait(30)
    for line in process.stdout:  # the commits acknowledged before the kill that were not read yet
        acked = int(line)
    process.stdout.close()
    stored = sorted({r.window_start_s for r in storage.trends(source="k")})
    # every window the worker was told committed is there, whole, once; at most the one in flight more
    assert stored[: acked + 1] == [60.0 * k for k in range(acked + 1)]
    assert len(stored) in (acked + 1, acked + 2) and storage.count("trends") == 2 * len(stored)
    state = storage.load_state("k")
    assert state["last_window_start_s"] == stored[-1] and state["monitor"] == {"window": len(stored) - 1}
    # each window raised or cleared mode1's alarm once: one event each, one outbox row each
    assert storage.count("alarm_events") == len(stored) == storage.count("outbox")
    assert storage.integrity_check() == "ok"
