"""The group commit of windows (the fleet's write lock): windows handed to one
``Storage`` by many threads while a write is under way are written in one transaction, each in
a savepoint (a bad window fails alone), and a fault of the database fails the whole group."""

from __future__ import annotations

import sqlite3
import threading
import time

import pytest

from shm_service.service import AlarmChange, Storage, StorageUnavailable, WindowCommit


def _row_commit(source: str, k: int, changes=()) -> WindowCommit:
    return WindowCommit(source, 30.0 * k, 30.0 * k + 60.0, [], {"monitor": {"k": k}}, None, list(changes))


def _wait_queued(st: Storage, n: int, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while len(st.windows._queued) < n:
        assert time.monotonic() < deadline, f"only {len(st.windows._queued)} of {n} windows queued"
        time.sleep(0.005)


def _commit_in_threads(st: Storage, commits: list[WindowCommit]) -> tuple[list[threading.Thread], dict]:
    """The first commit starts (and becomes the group's writer), blocked on the held write lock;
    the others queue behind it."""
    outcome: dict = {}

    def one(c: WindowCommit) -> None:
        try:
            outcome[c.source] = st.commit_window(c)
        except Exception as exc:  # what the caller gets is the test's subject
            outcome[c.source] = exc

    threads = [threading.Thread(target=one, args=(c,)) for c in commits]
    threads[0].start()
    deadline = time.monotonic() + 10
    while not st.windows._leading:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    for t in threads[1:]:
        t.start()
    _wait_queued(st, len(commits) - 1)
    return threads, outcome


def test_windows_of_many_threads_are_written_in_one_transaction(storage_target):
    st = Storage(storage_target)
    commits = [_row_commit(f"mast-{i:02d}", i) for i in range(12)]
    with st._lock:  # a write under way: the windows arriving meanwhile queue
        threads, outcome = _commit_in_threads(st, commits)
    for t in threads:
        t.join(30)
    assert all(outcome[c.source] == [] for c in commits), outcome
    # the first window alone (it was taken before the lock was free), then the eleven together
    assert (st.groups, st.grouped_windows) == (2, 12)
    stored = {r["source"]: r["data_time_s"] for r in st._read(lambda db: db.execute("SELECT * FROM monitor_state").fetchall())}
    assert stored == {c.source: c.data_time_s for c in commits}
    assert st.integrity_check() == "ok" and not st.windows._leading and st.windows._queued == []


def test_a_bad_window_fails_alone_in_its_group(storage_target):
    st = Storage(storage_target)
    good = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 40.0, 6.0, 5.0, "m")
    bad = AlarmChange("bogus", "mode3", "frequency", 3, "alarm", 40.0, 6.0, 5.0, "m")
    commits = [_row_commit("a", 0), _row_commit("b", 1, [good]), _row_commit("c", 2, [good, bad]), _row_commit("d", 3, [good])]
    with st._lock:
        threads, outcome = _commit_in_threads(st, commits)
    for t in threads:
        t.join(30)
    assert isinstance(outcome["c"], ValueError) and "bogus" in str(outcome["c"])
    assert outcome["a"] == [] and len(outcome["b"]) == 1 and len(outcome["d"]) == 1
    # nothing of c is kept (not its first, good change either); the others of its group are
    assert sorted(a.source for a in st.alarms()) == ["b", "d"]
    assert st._read(lambda db: db.execute("SELECT COUNT(*) FROM monitor_state WHERE source='c'").fetchone()[0]) == 0
    assert (st.groups, st.grouped_windows) == (2, 4)


def test_a_locked_database_fails_the_whole_group_and_keeps_nothing(tmp_path):
    st = Storage(tmp_path / "s.sqlite", retry_s=0.3, busy_timeout_s=0.05)
    other = sqlite3.connect(str(tmp_path / "s.sqlite"), isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # another process's writer holds the lock throughout
    try:
        commits = [_row_commit(f"s{i}", i) for i in range(5)]
        with st._lock:
            threads, outcome = _commit_in_threads(st, commits)
        for t in threads:
            t.join(30)
        assert all(isinstance(outcome[c.source], StorageUnavailable) for c in commits), outcome
        assert st.failures == 2 and st.groups == 0  # the first window's group, then the other four's
    finally:
        other.execute("ROLLBACK")
        other.close()
    assert st._read(lambda db: db.execute("SELECT COUNT(*) FROM monitor_state").fetchone()[0]) == 0
    assert st.commit_window(commits[0]) == []  # the lock is free: the next window is written
    assert not st.windows._leading and st.windows._queued == []


def test_a_commit_of_another_source_row_is_refused_before_the_group(tmp_path):
    from contract import TrendRow

    st = Storage(":memory:")
    row = TrendRow(source="x", window_start_s=0.0, window_end_s=60.0, mode=1, unit=1, kind="ambient")
    with pytest.raises(ValueError, match="source 'x' in a commit of source 'y'"):
        st.commit_window(WindowCommit("y", 0.0, 60.0, [row], None, None))
    assert st.windows._queued == [] and st.groups == 0


def _contents(st: Storage) -> dict:
    def run(db):
        return {
            "trends": [tuple(r) for r in db.execute("SELECT source, window_start_s, mode, frequency_hz FROM trends ORDER BY 1, 2, 3")],
            "state": [tuple(r) for r in db.execute(
                "SELECT source, last_window_start_s, data_time_s, monitor, calibration FROM monitor_state ORDER BY 1")],
            "alarms": [tuple(r) for r in db.execute("SELECT source, chart, state, stale FROM alarms ORDER BY 1, 2")],
        }
    return st._read(run)


def _sequence() -> list[WindowCommit]:
    from contract import TrendRow

    def rows(source, k):
        return [TrendRow(source=source, window_start_s=30.0 * k, window_end_s=30.0 * k + 60, mode=m, unit=m, kind="ambient",
                         frequency_hz=1.0 + m + 0.01 * k) for m in (1, 2)]

    raise_ = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 60.0, 6.0, 5.0, "m")
    return [
        WindowCommit("a", 0.0, 60.0, rows("a", 0), {"monitor": 1}, {"cal": 1}),
        WindowCommit("b", 0.0, 60.0, rows("b", 0), {"monitor": 1}, None, [raise_]),
        WindowCommit("a", 30.0, 90.0, rows("a", 1), {"monitor": 2}, None),  # keeps a's calibration
        WindowCommit("a", 30.0, 90.0, rows("a", 1), {"monitor": 3}, None),  # the same window again: rows ignored
    ]


def test_plain_windows_in_one_statement_store_what_a_transaction_each_stores(tmp_path, monkeypatch):
    one = Storage(tmp_path / "one.sqlite")
    statements: list[str] = []
    one._db.set_trace_callback(statements.append)
    for c in _sequence():
        one.commit_window(c)
    one.touch_source("b", "sim", "", 0.0)
    assert one.mark_stale(silent_since=1e12, now=1.0)  # b's alarm goes stale; b's next window judges it again
    assert _contents(one)["alarms"] == [("b", "mode2", "active", 1)]
    one.commit_window(WindowCommit("b", 30.0, 90.0, [], {"monitor": 2}, None))
    one._db.set_trace_callback(None)

    each = Storage(tmp_path / "each.sqlite")
    monkeypatch.setattr(each.windows, "_write_plain", lambda batch: False)  # every window in a transaction of its own
    for c in _sequence():
        each.commit_window(c)
    each.touch_source("b", "sim", "", 0.0)
    assert each.mark_stale(silent_since=1e12, now=1.0)
    each.commit_window(WindowCommit("b", 30.0, 90.0, [], {"monitor": 2}, None))

    assert _contents(one) == _contents(each)
    got = _contents(one)
    assert got["state"][0][3:] == ('{"monitor": 3}', '{"cal": 1}') and len(got["trends"]) == 6
    assert got["alarms"] == [("b", "mode2", "active", 0)]
    # the plain windows took the database's lock in one statement each, not in a transaction
    # (whose statements each wait for the GIL while the lock is held)
    # (SQLite's trace names the trigger's statements by the statement that fired them)
    flushes = {s for s in statements if s.startswith("INSERT INTO stage_flush")}
    begins = [s for s in statements if s.startswith("BEGIN")]
    assert len(flushes) == 4 and len(begins) == 2  # the transactions: b's alarm, mark_stale


def test_a_plain_group_with_a_bad_window_falls_back_to_one_savepoint_each(tmp_path):
    st = Storage(tmp_path / "s.sqlite")
    commits = [_row_commit("a", 0), _row_commit("b", 1), _row_commit("c", 2)]
    # a value SQLite cannot store, in c only (a malformed window that bypassed its document's validation)
    from contract import TrendRow
    commits[2].rows = [TrendRow.model_construct(source="c", window_start_s=60.0, window_end_s=120.0, mode=1, unit=1,
                                                kind="ambient", frequency_hz=[1.0])]
    with st._lock:
        threads, outcome = _commit_in_threads(st, commits)
    for t in threads:
        t.join(30)
    assert outcome["a"] == [] and outcome["b"] == []
    assert isinstance(outcome["c"], sqlite3.ProgrammingError), outcome["c"]
    assert sorted(r[0] for r in _contents(st)["state"]) == ["a", "b"]
    assert st.integrity_check() == "ok" and st.commit_window(_row_commit("c", 3)) == []


def test_the_schema_version_is_read_without_the_writers_lock(tmp_path):
    from shm_service.service import SCHEMA_VERSION

    st = Storage(tmp_path / "s.sqlite")
    held, release = threading.Event(), threading.Event()

    def writer() -> None:  # a group being written, for as long as the test wants
        with st._lock:
            held.set()
            release.wait(10)

    t = threading.Thread(target=writer)
    t.start()
    try:
        assert held.wait(10)
        answer: list[int] = []
        reader = threading.Thread(target=lambda: answer.append(st.schema_version))
        reader.start()
        reader.join(2.0)
        assert answer == [SCHEMA_VERSION]  # a fleet's status asks it per structure: it must not wait for the writer
    finally:
        release.set()
        t.join(10)
