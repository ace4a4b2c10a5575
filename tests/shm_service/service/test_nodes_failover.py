"""The failover of a fleet across machines, end to end: two ``shm serve --node`` processes, one
PostgreSQL, one Mosquitto, six ``mqtt`` structures fed at 4x real time in 1 s bodies; one node is
SIGKILLed mid-stream, the other holds all six within 30 s, and every structure's committed
windows run from the first to the last, none missing and none doubled."""

from __future__ import annotations

import signal
import threading
import time

import httpx
import orjson
import psycopg
import pytest
import tomli_w
from mqtt_helpers import Publisher, simulated_bodies
from svc_helpers import FAST, wait_for

from shm_service.service import start_serve

pytestmark = [pytest.mark.slow, pytest.mark.e2e]

IDS = [f"mast-{k}" for k in range(1, 7)]
DATA_S = 100.0
SPEED = 4.0
STEP_S = FAST["analytics"]["window_s"] * (1 - FAST["analytics"]["overlap"])


def _structures(url):
    return {s["id"]: s for s in httpx.get(f"{url}/api/structures", timeout=10).json()["structures"]}


def test_a_node_killed_mid_stream_is_taken_over_with_no_window_missing_or_doubled(tmp_path, fresh_postgres_url,
                                                                                  mqtt_server):
    config = {**{k: v for k, v in FAST.items() if k != "server"}, "archive": {"enabled": False},
              "storage": {"url": fresh_postgres_url}, "mqtt": {"url": mqtt_server.url, "topic_prefix": "failover"},
              "nodes": {"lease_s": 6.0}, "structures": [{"id": i, "source": "mqtt"} for i in IDS]}
    path = tmp_path / "fleet.toml"
    path.write_text(tomli_w.dumps(config))
    # the last body's stamps about when it is published (within source.future_tolerance_s of the wall clock)
    end_ns = time.time_ns() + int(DATA_S / SPEED * 1e9) + 30 * 10**9
    bodies = {sid: simulated_bodies(DATA_S, seed=k, end_ns=end_ns) for k, sid in enumerate(IDS, 1)}
    nodes = {name: start_serve(["--config", str(path), "--node", name, "--port", "0"], cwd=tmp_path,
                               ready_file=tmp_path / f"{name}.json", timeout=300) for name in ("a", "b")}
    try:
        urls = {name: p.url for name, p in nodes.items()}
        def counts(view):
            return [sum(s["node"] == n for s in view.values()) for n in ("a", "b")]

        # b started after a had taken all six: a hands three back, b takes them
        shared = wait_for(lambda: (lambda v: v if counts(v) == [3, 3] else None)(_structures(urls["a"])), 60,
                          "the structures shared three and three")
        assert {k: v["node"] for k, v in _structures(urls["b"]).items()} == {k: v["node"] for k, v in shared.items()}
        def connected() -> bool:
            return all(httpx.get(f"{urls[s['node']]}/api/structures/{sid}/status", timeout=10).json()["sources"][0]
                       ["broker"]["connected"] for sid, s in _structures(urls["a"]).items())

        wait_for(lambda: connected() or None, 60, "every structure connected to the broker")

        sent = threading.Event()
        published = [0]

        def feed() -> None:
            with Publisher(mqtt_server.url, client_id="failover-gateway") as gateway:
                for k in range(len(bodies[IDS[0]])):
                    for sid in IDS:
                        gateway.publish(f"failover/{sid}/ingest", [bodies[sid][k]])
                    published[0] = k + 1
                    time.sleep(1.0 / SPEED)
            sent.set()

        threading.Thread(target=feed, daemon=True).start()
        wait_for(lambda: published[0] >= 0.45 * DATA_S or None, 120, "half of the data")
        killed = time.monotonic()
        nodes["a"].process.send_signal(signal.SIGKILL)
        nodes["a"].process.wait(10)
        view = wait_for(lambda: (lambda v: v if all(s["node"] == "b" for s in v.values()) else None)(
            _structures(urls["b"])), 60, "b to hold every structure")
        assert time.monotonic() - killed <= 30.0
        assert list(view) == IDS
        assert sent.wait(120)
        last_s = max(max(x["log_time_ns"] for x in orjson.loads(bodies[sid][-1])["messages"]) for sid in IDS) / 1e9
        try:
            wait_for(lambda: all((s["data_time_s"] or 0) >= last_s - 1.0 for s in _structures(urls["b"]).values())
                     or None, 300, "b to take every body")
        except AssertionError:
            sources = {sid: httpx.get(f"{urls['b']}/api/structures/{sid}/status", timeout=10).json()["sources"][0]
                       for sid in IDS}
            raise AssertionError(f"b did not take every body up to {last_s}: {_structures(urls['b'])} {sources}") from None
    finally:
        for p in nodes.values():
            if p.process.poll() is None:
                p.process.send_signal(signal.SIGTERM)
        for p in nodes.values():
            try:
                p.process.wait(120)
            except Exception:
                p.process.kill()
    with psycopg.connect(fresh_postgres_url) as db:
        for sid in IDS:
            rows = db.execute("SELECT window_start_s, mode FROM trends WHERE source = %s ORDER BY window_start_s, mode",
                              (sid,)).fetchall()
            assert len(rows) == len(set(rows)), f"{sid}: a window written twice"
            starts = sorted({r[0] for r in rows})
            assert len(starts) >= 5, (sid, starts)
            gaps = [round(b - a, 6) for a, b in zip(starts, starts[1:])]
            assert gaps == [STEP_S] * len(gaps), f"{sid}: windows missing: {starts}"
            # the whole run: its first window after the rest and warm-up, its last at the end of the data
            first_s = end_ns / 1e9 - DATA_S
            assert starts[0] <= first_s + 10.0 + FAST["estimator"]["warmup_s"] + 2 * STEP_S, (sid, starts, first_s)
            assert starts[-1] >= last_s - FAST["analytics"]["window_s"] - 2 * STEP_S, (sid, starts, last_s)
