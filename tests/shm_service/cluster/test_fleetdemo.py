"""The pieces of the two-node demo (``make fleet-demo``): its configuration, and two nodes that
start on real servers, share the fleet and stop without leaving a process behind."""

from __future__ import annotations

import time
import tomllib

import httpx
import pytest

from shm_service._fleetdemo import fleet_toml, start_nodes, stop_nodes


def test_the_demo_configuration_names_both_servers_and_every_structure():
    doc = tomllib.loads(fleet_toml(["mast-01", "mast-02"], "postgresql://u@h:5/d", "mqtt://h:7", lease_s=4))
    assert doc["storage"] == {"url": "postgresql://u@h:5/d"}
    assert doc["mqtt"] == {"url": "mqtt://h:7"}
    assert doc["nodes"] == {"lease_s": 4}
    assert doc["structures"] == [{"id": "mast-01", "source": "mqtt"}, {"id": "mast-02", "source": "mqtt"}]
    with pytest.raises(ValueError, match="ids"):
        fleet_toml([], "postgresql://u@h:5/d", "mqtt://h:7")


@pytest.mark.e2e
def test_two_nodes_start_share_the_fleet_and_stop(tmp_path, fresh_postgres_url, mqtt_server):
    config = tmp_path / "fleet.toml"
    config.write_text(fleet_toml(["mast-01", "mast-02"], fresh_postgres_url, mqtt_server.url, lease_s=3), encoding="utf-8")
    nodes = start_nodes(config, ["a", "b"], tmp_path, dashboard=False)
    try:
        holders: dict[str, str | None] = {}
        for _ in range(120):  # each node takes its share (one of two) within a few lease rounds
            rows = httpx.get(f"{nodes[0].url}/api/structures", timeout=30).json()["structures"]
            holders = {r["id"]: r["node"] for r in rows}
            if sorted(holders.values(), key=str) == ["a", "b"]:
                break
            assert all(node.process.poll() is None for node in nodes)
            time.sleep(1.0)
        assert sorted(holders.values(), key=str) == ["a", "b"]
    finally:
        stop_nodes(nodes)
    assert [node.process.returncode for node in nodes] == [0, 0]
