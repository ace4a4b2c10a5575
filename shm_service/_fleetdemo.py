"""A demo of two nodes (``make fleet-demo``, ``python -m shm_service.devservers --two-nodes``).

A throwaway PostgreSQL and Mosquitto (:mod:`shm_service.devservers`), a fleet of a few structures
with ``source = "mqtt"``, two ``shm serve --node`` processes sharing them through leases, and a
field gateway in this process that publishes the virtual rig's data at real time in 1 s bodies.
Ctrl-C (or SIGTERM) stops the gateway, the nodes (SIGINT: each releases its leases) and then the
servers; every child also has a parent-death signal, so none outlives this process.
"""

from __future__ import annotations

import signal
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

__all__ = ["fleet_toml", "run_two_nodes", "start_nodes", "stop_nodes"]


def fleet_toml(ids: Sequence[str], storage_url: str, mqtt_url: str, *, lease_s: float = 15.0) -> str:
    """The configuration both nodes read: storage, broker, leases and the structures."""
    if not ids:
        raise ValueError("ids: a fleet needs at least one structure")
    lines = ["[storage]", f'url = "{storage_url}"', "", "[mqtt]", f'url = "{mqtt_url}"', "", "[nodes]", f"lease_s = {lease_s:g}", ""]
    for sid in ids:
        lines += ["[[structures]]", f'id = "{sid}"', 'source = "mqtt"', ""]
    return "\n".join(lines)


def start_nodes(config: Path, names: Sequence[str], directory: Path, *, dashboard: bool = True,
                timeout_s: float = 300.0) -> list[Any]:
    """Start ``shm serve --config CONFIG --node NAME`` for each name (its own session: a Ctrl-C of
    the terminal reaches this process only, which stops the nodes in order) and wait for each API."""
    from shm_service.service import start_serve

    nodes: list[Any] = []
    try:
        for name in names:
            args = ["--config", str(config), "--node", name, "--port", "0", "--no-archive"]
            args += ["--dashboard-port", "0"] if dashboard else ["--no-dashboard"]
            with open(directory / f"node-{name}.log", "w") as log:  # the node writes to its own copy of the descriptor
                nodes.append(start_serve(args, stdout=log, stderr=log, timeout=timeout_s, start_new_session=True,
                                         ready_file=directory / f"ready-{name}.json"))
    except BaseException:
        stop_nodes(nodes)
        raise
    return nodes


def stop_nodes(nodes: Sequence[Any], timeout_s: float = 60.0) -> None:
    """SIGINT to every node (each releases its leases as it stops), then wait; SIGKILL after ``timeout_s``."""
    for node in nodes:
        if node.process.poll() is None:
            node.process.send_signal(signal.SIGINT)
    for node in nodes:
        try:
            node.process.wait(timeout_s)
        except Exception:  # noqa: BLE001  (a node that does not stop in time is killed)
            node.process.kill()
            node.process.wait()


def _gateway(mqtt_url: str, ids: Sequence[str], stop: threading.Event, duration_s: float = 3600.0) -> None:
    """Publish each structure's virtual rig (seeded by its rank) at real time, 1 s bodies, QoS 1."""
    import orjson
    from paho.mqtt.client import Client
    from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

    from shm_service.virtual_rig import SimulationSettings, VirtualRig
    from shm_service.virtual_rig._record import encode_payloads

    parts = urlsplit(mqtt_url)
    client = Client(CallbackAPIVersion.VERSION2, client_id="fleet-demo-gateway", protocol=MQTTProtocolVersion.MQTTv5)
    client.connect(parts.hostname or "127.0.0.1", parts.port or 1883)
    client.loop_start()
    rigs = [VirtualRig(SimulationSettings(duration=duration_s, excitation="ambient", seed=k + 1)).blocks(1.0) for k in range(len(ids))]
    start_ns = time.time_ns()
    try:
        k = 0
        while not stop.is_set():
            if stop.wait(max(0.0, start_ns / 1e9 + k + 1 - time.time())):
                break
            for sid, blocks in zip(ids, rigs):
                block = next(blocks, None)
                if block is None:
                    return
                messages = []
                for topic, (times, values) in block.measurements.items():
                    stamps = (start_ns + (times * 1e9).round()).astype("int64").tolist()
                    messages += [{"topic": topic, "log_time_ns": t, "payload": orjson.loads(p)}
                                 for t, p in zip(stamps, encode_payloads(topic, values))]
                client.publish(f"shm/{sid}/ingest", orjson.dumps({"messages": messages}), qos=1)
            k += 1
    finally:
        client.disconnect()
        client.loop_stop()


def run_two_nodes(start_postgres: Callable[[], Any], start_mosquitto: Callable[[], Any], structures: int = 4, *,
                  lease_s: float = 15.0, seconds: float | None = None) -> int:
    """Both servers (started by the two callables, :mod:`shm_service.devservers`'), two nodes on
    ``structures`` mqtt structures and the gateway, until Ctrl-C (or ``seconds``); everything
    stopped in order at the end."""
    if structures < 1:
        raise ValueError(f"structures={structures}: at least one")
    ids = [f"mast-{k + 1:02d}" for k in range(structures)]
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    with tempfile.TemporaryDirectory(prefix="shm-fleet-demo-") as tmp, start_postgres() as postgres, \
            start_mosquitto() as broker:
        config = Path(tmp) / "fleet.toml"
        config.write_text(fleet_toml(ids, postgres.url, broker.url, lease_s=lease_s), encoding="utf-8")
        print(f"PostgreSQL: {postgres.url}\nMosquitto:  {broker.url}\nConfiguration: {config}", flush=True)
        nodes = start_nodes(config, ["a", "b"], Path(tmp))
        gateway = threading.Thread(target=_gateway, args=(broker.url, ids, stop), daemon=True)
        gateway.start()
        try:
            for name, node in zip("ab", nodes):
                board = f"   dashboard {node.dashboard_url}" if node.dashboard_url else ""
                print(f"node {name} (pid {node.pid}): API {node.url}{board}   log {tmp}/node-{name}.log", flush=True)
            print(f"{structures} structures published at real time to {broker.url} (shm/<id>/ingest). "
                  "Kill a node (kill -9 PID) to see the other take over within lease_s; Ctrl-C stops everything.", flush=True)
            deadline = None if seconds is None else time.monotonic() + seconds
            while not stop.is_set() and (deadline is None or time.monotonic() < deadline):
                if all(node.process.poll() is not None for node in nodes):
                    print("both nodes exited", flush=True)
                    break
                stop.wait(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            stop.set()
            gateway.join(10)
            stop_nodes(nodes)
    print("stopped: both nodes, the gateway, PostgreSQL and Mosquitto", flush=True)
    return 0
