"""The PostgreSQL storage when its server goes away: sessions killed under it (as a restart of
the server does) are opened anew and the window is written once; a server that does not answer
is ``StorageUnavailable``, naming the database (its password hidden)."""

from __future__ import annotations

import pytest

from shm_service.service import Storage, WindowCommit


def _commit(source: str, k: int) -> WindowCommit:
    return WindowCommit(source, 30.0 * k, 30.0 * k + 60.0, [], {"monitor": {"k": k}}, None)


def test_a_connection_killed_under_the_storage_is_opened_anew_and_the_window_written_once(fresh_postgres_url):
    import psycopg

    store = Storage(fresh_postgres_url, retry_s=10.0)
    try:
        assert store.commit_window(_commit("mast-01", 0)) == []
        name = fresh_postgres_url.rsplit("/", 1)[1]
        with psycopg.connect(fresh_postgres_url, autocommit=True) as admin:  # what a server restart does to the sessions
            killed = admin.execute("SELECT COUNT(pg_terminate_backend(pid)) FROM pg_stat_activity WHERE datname = %s "
                                   "AND pid <> pg_backend_pid()", (name,)).fetchone()[0]
        assert killed >= 2  # the writer's and the reader's connections
        assert store.commit_window(_commit("mast-01", 1)) == []
        assert store.retries >= 1 and store.failures == 0
        assert store.load_state("mast-01")["last_window_start_s"] == 30.0
    finally:
        store.close()


def test_a_database_that_does_not_answer_is_unavailable_by_name():
    from shm_service.devservers import free_port
    from shm_service.service import StorageUnavailable

    url = f"postgresql://shm:secret@127.0.0.1:{free_port()}/shm"
    with pytest.raises(StorageUnavailable, match=r"(?s)postgresql://shm:\*\*\*@127\.0\.0\.1:\d+/shm: .*attempts in 0\.3 s"):
        Storage(url, retry_s=0.3)
