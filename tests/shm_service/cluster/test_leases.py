"""Leases of a fleet's nodes in a real PostgreSQL: two nodes are two ``Leases`` (two connections)
and two ``Storage`` objects on one database. A lease is held by one node at a time, taken by the
other when it expires (its fencing token raised), and a commit with the stale token is refused
and counted, with nothing of it written."""

from __future__ import annotations

import threading
import time

import pytest

from shm_service.service import AlarmChange, Storage, WindowCommit
from shm_service.service.storage.postgres import Leases, StaleLease, check_fence


def _commit(source: str, k: int, token: int | None) -> WindowCommit:
    return WindowCommit(source, 30.0 * k, 30.0 * k + 60.0, [], {"monitor": {"k": k}}, None, fencing_token=token)


def _until_expired(leases: Leases, expires_at: float) -> None:
    """Wait (on the database's clock, which judges expiry) until ``expires_at`` has passed."""
    deadline = time.monotonic() + 30.0
    while leases.now() <= expires_at:
        assert time.monotonic() < deadline, "the database's clock does not advance"
        time.sleep(0.02)


@pytest.fixture()
def nodes(fresh_postgres_url):
    a, b = Leases(fresh_postgres_url, lease_s=60.0), Leases(fresh_postgres_url, lease_s=60.0)
    yield a, b
    a.close()
    b.close()


def test_a_lease_is_one_nodes_until_it_expires_then_the_others_with_a_new_token(nodes):
    a, b = nodes
    first = a.acquire("mast-01", "node-a", lease_s=0.3)
    assert (first.holder, first.token, first.expired) == ("node-a", 1, False)
    assert b.acquire("mast-01", "node-b") is None  # held, unexpired
    assert b.take_expired("node-b") == []
    again = a.acquire("mast-01", "node-a", lease_s=0.3)  # its holder again: a renewal, the token kept
    assert again.token == 1 and again.expires_at >= first.expires_at
    _until_expired(b, again.expires_at)
    (taken,) = b.take_expired("node-b")
    assert (taken.structure_id, taken.holder, taken.token) == ("mast-01", "node-b", 2)
    with pytest.raises(StaleLease, match="no longer 'node-a'"):
        a.renew(again)  # node-a was only slow: it learns it lost the structure
    assert [(x.structure_id, x.holder, x.token, x.expired) for x in a.all()] == [("mast-01", "node-b", 2, False)]
    assert a.held("node-a") == [] and [x.token for x in a.held("node-b")] == [2]


def test_renew_release_and_the_heartbeat_of_all_leases(nodes):
    a, b = nodes
    a.register(["s1", "s2", "s3"])
    a.register(["s1"])  # idempotent
    assert [(x.structure_id, x.holder, x.token, x.expired) for x in a.all()] == [
        ("s1", None, 0, True), ("s2", None, 0, True), ("s3", None, 0, True)]
    taken = a.take_expired("node-a", limit=2)
    assert [(x.structure_id, x.token) for x in taken] == [("s1", 1), ("s2", 1)]
    (s3,) = b.take_expired("node-b")
    assert (s3.structure_id, s3.token) == ("s3", 1)
    assert [x.structure_id for x in a.renew_all("node-a")] == ["s1", "s2"]
    assert a.renew(taken[0]).token == 1
    assert a.release(taken[0]) and not a.release(taken[0])  # the second: no longer ours
    s1 = b.acquire("s1", "node-b")
    assert (s1.holder, s1.token) == ("node-b", 2)  # every acquisition raises the token
    assert b.release_all("node-b") == 2 and [x.structure_id for x in b.all() if x.holder is None] == ["s1", "s3"]
    with pytest.raises(ValueError, match="lease_s=0"):
        a.acquire("s1", "node-a", lease_s=0)
    with pytest.raises(ValueError, match="limit=-1"):
        a.take_expired("node-a", limit=-1)


def test_a_stale_tokens_commit_is_refused_and_counted_and_writes_nothing(nodes, fresh_postgres_url):
    a, b = nodes
    store_a, store_b = Storage(fresh_postgres_url), Storage(fresh_postgres_url)
    try:
        lease_a = a.acquire("mast-01", "node-a", lease_s=0.3)
        assert store_a.commit_window(_commit("mast-01", 0, lease_a.token)) == []
        _until_expired(a, lease_a.expires_at)
        (lease_b,) = b.take_expired("node-b")
        with pytest.raises(StaleLease, match="fencing token 1 is stale"):
            store_a.commit_window(_commit("mast-01", 1, lease_a.token))
        raise_ = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 60.0, 6.0, 5.0, "m")  # a window of its own savepoint
        with pytest.raises(StaleLease, match="fencing token 1 is stale"):
            store_a.commit_window(WindowCommit("mast-01", 30.0, 90.0, [], None, None, [raise_], fencing_token=lease_a.token))
        assert (store_a.fenced, store_b.fenced) == (2, 0) and store_b.alarms() == []
        assert store_b.load_state("mast-01")["last_window_start_s"] == 0.0  # nothing of the refused window
        assert store_b.commit_window(_commit("mast-01", 1, lease_b.token)) == []
        assert store_a.load_state("mast-01")["last_window_start_s"] == 30.0
        with pytest.raises(StaleLease, match="has no lease"):
            store_b.commit_window(_commit("other", 0, 1))
    finally:
        store_a.close()
        store_b.close()


def test_a_takeover_waits_for_a_commit_under_way(nodes, fresh_postgres_url):
    """The fencing check locks the lease's row until its transaction ends: a takeover cannot
    slip in between the check and the commit."""
    a, b = nodes
    store = Storage(fresh_postgres_url)
    try:
        lease = a.acquire("mast-01", "node-a", lease_s=0.3)
        with store.transaction() as db:
            check_fence(db, "mast-01", lease.token)
            _until_expired(b, lease.expires_at)
            assert b.take_expired("node-b") == []  # the row is locked by the commit: skipped
        (taken,) = b.take_expired("node-b")
        assert taken.token == 2
    finally:
        store.close()


def test_nodes_starting_together_migrate_once(fresh_postgres_url):
    stores: list[Storage] = []
    errors: list[BaseException] = []

    def start() -> None:
        try:
            stores.append(Storage(fresh_postgres_url))
        except BaseException as exc:  # what a node would get is the test's subject
            errors.append(exc)

    threads = [threading.Thread(target=start) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    try:
        assert errors == [] and len(stores) == 4
        assert {s.schema_version for s in stores} == {stores[0].database.schema_latest}
        assert len({s.instance for s in stores}) == 1  # one database, one instance id
    finally:
        for s in stores:
            s.close()


def test_a_newer_schema_is_refused_and_a_token_needs_postgres(fresh_postgres_url, tmp_path):
    import psycopg

    Storage(fresh_postgres_url).close()
    with psycopg.connect(fresh_postgres_url, autocommit=True) as db:
        db.execute("INSERT INTO schema_version (version, applied_at) VALUES (99, 0)")
    with pytest.raises(RuntimeError, match="schema version 99 is newer"):
        Storage(fresh_postgres_url)
    local = Storage(tmp_path / "s.sqlite")
    try:
        with pytest.raises(ValueError, match="fencing_token=3: leases need the PostgreSQL storage"):
            local.commit_window(_commit("mast-01", 0, 3))
    finally:
        local.close()



def test_two_nodes_notifiers_take_each_notification_once(fresh_postgres_url):
    targets = [("webhook", "http://127.0.0.1:1/x")]
    a, b = Storage(fresh_postgres_url, notify_targets=targets), Storage(fresh_postgres_url, notify_targets=targets)
    try:
        change = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 20.0, 6.0, 5.0, "m")
        a.commit_window(WindowCommit("mast-01", 0.0, 20.0, [], None, None, [change]))
        (row,) = b.due_notifications(time.time())  # due to both nodes' notifiers
        assert a.claim_notification(row["id"], 60.0) and not b.claim_notification(row["id"], 60.0)
        assert b.due_notifications(time.time()) == []  # taken by a for its attempt
        a.record_attempt(row["id"], True, "HTTP 200", next_attempt_at=None, give_up=False)
        assert not b.claim_notification(row["id"], 60.0) and [r["status"] for r in b.outbox()] == ["sent"]
        with pytest.raises(ValueError, match="hold_s=0"):
            a.claim_notification(row["id"], 0)
    finally:
        a.close()
        b.close()
