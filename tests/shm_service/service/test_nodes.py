"""Nodes of a fleet across machines (``shm serve --node NAME``) on a real PostgreSQL and Mosquitto:
they share the structures by leases (each its fair share), list the whole fleet with each
structure's node, take over the structures of a node that stopped or died, and a node refuses to
start without a PostgreSQL database."""

from __future__ import annotations

import pytest
from svc_helpers import fast_overrides, wait_for

from shm_service.service import SettingsError, load_settings
from shm_service.service.runtime._node import NodeService

pytestmark = pytest.mark.e2e

IDS = ["m1", "m2", "m3", "m4", "m5"]


def _settings(tmp_path, url, mqtt_url):
    return load_settings(None, {**fast_overrides(tmp_path, **{"archive.enabled": False, "storage.url": url}),
                                "structures": [{"id": i, "source": "mqtt"} for i in IDS],
                                "db": None, "mqtt": {"url": mqtt_url, "topic_prefix": "nodes"}, "nodes": {"lease_s": 3.0}})


def _holders(node):
    return {s.id: s.node for s in node.structures_document().structures}


def test_a_node_needs_postgresql_and_a_fleet(tmp_path):
    with pytest.raises(SettingsError, match="storage.url"):
        NodeService(load_settings(None, {**fast_overrides(tmp_path), "structures": [{"id": "a"}]}), "n1")
    with pytest.raises(SettingsError, match="--node"):
        NodeService(load_settings(None, fast_overrides(tmp_path)), "bad name")


def test_nodes_share_the_fleet_and_take_over_a_stopped_and_a_dead_node(tmp_path, fresh_postgres_url, mqtt_server):
    settings = _settings(tmp_path, fresh_postgres_url, mqtt_server.url)
    a, b = NodeService(settings, "a", environ={}), NodeService(settings, "b", environ={})
    nodes = [a, b]
    try:
        for node in nodes:
            node.start()
        # five structures on two nodes: three and two (ceil(5/2) = 3 at most on one)
        wait_for(lambda: sorted([len(a.running_structures()), len(b.running_structures())]) == [2, 3] or None, 60,
                 "the structures shared")
        wait_for(lambda: _holders(a) == _holders(b) and None not in _holders(a).values() or None, 30, "one view")
        view = _holders(a)
        assert list(view) == IDS
        assert {sid for sid, n in view.items() if n == "a"} == {s.id for s in a.running_structures()}
        assert {sid for sid, n in view.items() if n == "b"} == {s.id for s in b.running_structures()}
        rows = {s.id: s for s in b.structures_document().structures}
        assert all(r.kind == "mqtt" and r.state in ("running", "degraded", "starting") for r in rows.values())
        # another node's structure: its live routes are there, said so
        remote = next(sid for sid, n in view.items() if n == "a")
        with pytest.raises(Exception, match="runs on node 'a'"):
            b.structure(remote)
        b.trends(None, None, source=remote)  # its stored rows are answered by any node
        # /metrics per node: its own structures only
        states = [line for line in b.fleet_metrics().splitlines() if line.startswith("shm_structure_state{")]
        assert sorted(line.split('structure="')[1].split('"')[0] for line in states) == sorted(
            sid for sid, n in view.items() if n == "b")

        # b stops cleanly: its leases released, a takes all five
        b.stop(drain_s=0)
        nodes.remove(b)
        wait_for(lambda: len(a.running_structures()) == 5 or None, 30, "a to hold all after b stopped")

        # c joins: it takes its share from a, which hands it back (stops, then releases)
        c = NodeService(settings, "c", environ={})
        nodes.append(c)
        c.start()
        wait_for(lambda: sorted([len(a.running_structures()), len(c.running_structures())]) == [2, 3] or None, 60,
                 "the structures shared again")
        # c dies without a word (its leases not released): a holds all within the lease
        c.leases.release_all = lambda node: 0
        c._node_stop.set()
        c._node_thread.join(10)
        tokens = {sid: a.view[sid].token for sid in IDS}
        c.stop(drain_s=0)
        nodes.remove(c)
        wait_for(lambda: len(a.running_structures()) == 5 or None, 30, "a to hold all after c died")
        assert set(_holders(a).values()) == {"a"}
        # each structure taken over has a new fencing token; the ones a kept, theirs
        taken = {sid for sid, n in view.items()}
        after = {lease.structure_id: lease.token for lease in a.leases.held("a")}
        assert all(after[sid] >= tokens[sid] for sid in taken)
        assert any(after[sid] > tokens[sid] for sid in taken)
    finally:
        for node in nodes:
            node.stop(drain_s=0)


def test_a_paused_node_stops_the_structures_taken_from_it(tmp_path, fresh_postgres_url, mqtt_server):
    """A node that paused past its lease (its renewals stopped) finds at its next round that
    another holds one of its structures: it stops that one and takes back what is still free."""
    from shm_service.service.storage.postgres import Leases

    settings = _settings(tmp_path, fresh_postgres_url, mqtt_server.url)
    a = NodeService(settings, "a", environ={})
    intruder = Leases(fresh_postgres_url, lease_s=60.0)
    try:
        a.start()
        wait_for(lambda: len(a.running_structures()) == len(IDS) or None, 60, "a to hold every structure")
        before = a.view["m1"].token
        a._node_stop.set()  # paused: no renewal
        a._node_thread.join(10)
        taken = wait_for(lambda: intruder.acquire("m1", "z"), 30, "m1's lease to expire")
        assert taken.token == before + 1
        wait_for(lambda: all(r.expired for r in intruder.all() if r.holder == "a") or None, 30, "a's leases to expire")
        a.step()
        assert "m1" not in a.structures and a.view["m1"].holder == "z"
        assert sorted(s.id for s in a.running_structures()) == IDS[1:]  # the others expired too: taken back
        assert all(a.view[sid].token > before for sid in IDS[1:])
        assert all(s.pipeline.commits.fencing_token == a.view[s.id].token for s in a.running_structures())
    finally:
        intruder.close()
        a.stop(drain_s=0)
