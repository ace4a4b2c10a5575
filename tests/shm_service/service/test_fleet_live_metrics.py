"""What a fleet's dashboard reads from the service: a structure's live ring (kept only while
watched), ``/api/structures/{id}/live`` and ``/rig`` over real HTTP, and ``/metrics`` of a fleet
(every structure's samples labelled ``structure``; a worker front's merge of its workers')."""

from __future__ import annotations

import re
import time

import httpx
import numpy as np
import pytest
from svc_helpers import fast_overrides, wait_for

from shm_service.service import ApiServer, MonitoringService, create_app, load_settings
from shm_service.service.runtime._live import LiveRing
from shm_service.service.http._metrics import merge_expositions


def test_the_live_ring_keeps_one_estimate_per_tick_only_while_watched():
    ring = LiveRing("s1", ["d", "h"], hz=10.0, capacity=50, watch_s=60.0)
    t = 1000.0 + np.arange(400) * 0.005  # 2 s at 200 Hz
    x = np.column_stack([t, -t])
    ring.add(t, x)
    assert ring.read(0) == (0, [], [])  # nobody watched: nothing kept (and this read starts the watch)
    ring.add(t + 2.0, x + 2.0)
    seq, times, states = ring.read(0)
    assert seq == 20 and np.allclose(times, 1002.0 + 0.1 * np.arange(20)), times  # the first of each 0.1 s tick
    assert states[3] == pytest.approx([1002.3, -998.3])  # (the second batch is x + 2)
    ring.add(t + 4.0, x)
    seq2, times2, _ = ring.read(seq)
    assert seq2 == 40 and times2[0] == pytest.approx(1004.0) and len(times2) == 20  # only the newer ones
    for k in range(3):
        ring.add(t + 6.0 + 2 * k, x)
    assert ring.read(0)[0] == 100 and len(ring.read(0)[1]) == 50  # at most capacity kept
    with pytest.raises(ValueError, match="after"):
        ring.read(-1)
    with pytest.raises(ValueError, match="hz"):
        LiveRing("s1", ["d"], hz=0.0)


def test_a_watch_ends_when_nobody_reads():
    ring = LiveRing("s1", ["d"], hz=10.0, watch_s=0.2)
    ring.read(0)
    ring.add(np.array([1.0]), np.array([[1.0]]))
    time.sleep(0.3)
    ring.add(np.array([2.0]), np.array([[2.0]]))  # the watch is over: not kept
    assert not ring.watched
    assert ring.read(0)[1] == []  # a new watch starts empty (what was kept is stale)


def test_merging_the_workers_expositions():
    w0 = ("# HELP shm_estimates_total estimator outputs\n# TYPE shm_estimates_total counter\n"
          'shm_estimates_total{structure="a"} 10\n'
          "# HELP shm_storage_write_retries_total retried\n# TYPE shm_storage_write_retries_total counter\n"
          "shm_storage_write_retries_total 2\n"
          "# HELP shm_trend_rows rows\n# TYPE shm_trend_rows gauge\nshm_trend_rows 40\n"
          "# HELP shm_structures by state\n# TYPE shm_structures gauge\nshm_structures{state=\"running\"} 1\n")
    w1 = w0.replace('structure="a"} 10', 'structure="b"} 7').replace("retries_total 2", "retries_total 3").replace(
        "shm_trend_rows 40", "shm_trend_rows 42")
    front = "# HELP shm_structures by state\n# TYPE shm_structures gauge\nshm_structures{state=\"running\"} 2\n"
    text = merge_expositions([w0, w1], {"shm_uptime_seconds": [({}, 5.0)]}, front=front)
    assert text.count("# TYPE shm_estimates_total counter") == 1
    assert 'shm_estimates_total{structure="a"} 10\n' in text and 'shm_estimates_total{structure="b"} 7\n' in text
    assert "shm_storage_write_retries_total 5\n" in text  # each process's counter: summed
    assert "shm_trend_rows 42\n" in text  # the one database: the newest (largest) count
    assert re.findall(r"^shm_structures.*$", text, re.M) == ['shm_structures{state="running"} 2']  # the front's


@pytest.fixture(scope="module")
def fleet_api(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fleet-live")
    settings = load_settings(None, {**fast_overrides(tmp, **{"archive.enabled": False, "source.speed": 4.0,
                                                             "sim.duration_s": 3600.0}),
                                    "structures": [{"id": "mast-01", "sim": {"seed": 1, "support": "clamped",
                                                                              "orientation": "standing", "length_m": 1.5,
                                                                              "layout": "benchmark",
                                                                              "damage": ["mass:0.05@1.5"]},
                                                    "estimator": {"modes": 3, "imus": 4}},
                                                   {"id": "pendulum-02", "sim": {"seed": 2}}]})
    service = MonitoringService(settings, environ={})
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    service.start()
    try:
        yield service, api.url
    finally:
        api.stop()
        service.stop(drain_s=0)


@pytest.mark.timeout(120)
def test_live_and_rig_of_a_structure_over_http(fleet_api):
    service, url = fleet_api
    with httpx.Client(base_url=url, timeout=30) as c:
        rig = c.get("/api/structures/mast-01/rig").json()
        assert rig["support"] == "clamped" and rig["orientation"] == "standing" and rig["beam"]["length"] == 1.5
        first = c.get("/api/structures/mast-01/live").json()
        assert first["seq"] == 0 and first["t_s"] == [] and "phi" not in first["state_names"]
        doc = wait_for(lambda: (lambda d: d if d["seq"] > 0 else None)(c.get("/api/structures/mast-01/live").json()),
                    60, "the mast's estimates")
        assert len(doc["x"]) == len(doc["t_s"]) == doc["seq"] and len(doc["x"][0]) == len(doc["state_names"])
        assert np.all(np.diff(doc["t_s"]) >= 0.1 - 1e-6)  # at most 10 per second of data
        newer = c.get("/api/structures/mast-01/live", params={"after": doc["seq"]}).json()
        assert all(t > doc["t_s"][-1] for t in newer["t_s"])
        # the other structure was never watched: it kept nothing
        assert service.structure("pendulum-02").live.read(0)[0] == 0
        assert c.get("/api/structures/nope/live").status_code == 404
        assert c.get("/api/structures/mast-01/live", params={"after": -1}).status_code == 422


@pytest.mark.timeout(120)
def test_metrics_of_a_fleet_in_one_process(fleet_api):
    service, url = fleet_api
    with httpx.Client(base_url=url, timeout=30) as c:
        wait_for(lambda: all(s["data_time_s"] for s in c.get("/api/structures").json()["structures"]), 60, "data of both")
        text = c.get("/metrics").text
        assert c.get("/api/status").status_code == 409  # the single-structure routes still point at the fleet's
    families = [line.split()[2] for line in text.splitlines() if line.startswith("# TYPE ")]
    assert len(families) == len(set(families))
    for sid in ("mast-01", "pendulum-02"):
        assert f'shm_source_messages_total{{structure="{sid}",source="{sid}",kind="sim"}}' in text
        assert f'shm_structure_state{{structure="{sid}",state="running"}} 1' in text
        assert f'shm_errors_total{{structure="{sid}",component="pipeline"}} 0' in text
    assert 'shm_structures{state="running"} 2' in text
    assert len(re.findall(r"^shm_trend_rows ", text, re.M)) == 1
    assert 'shm_errors_total{component="storage"} 0' in text  # the service's, once
    assert 'shm_sensor_degraded{structure="pendulum-02",topic="/imu/s4"}' in text


@pytest.mark.timeout(120)
def test_the_dashboard_of_a_fleet_in_one_process_reads_only_the_structure_shown(tmp_path):
    """``[[structures]]`` without workers: the dashboard (viser, its poller) reads the service in
    this process through the port: the structure asked for gets its model, rows and live
    estimates; the other is not watched."""
    settings = load_settings(None, {**fast_overrides(tmp_path, **{"archive.enabled": False, "source.speed": 4.0,
                                                                  "sim.duration_s": 3600.0, "dashboard.enabled": True,
                                                                  "dashboard.port": 0}),
                                    "structures": [{"id": "a", "sim": {"seed": 1}}, {"id": "b", "sim": {"seed": 2}}]})
    service = MonitoringService(settings, environ={})
    service.start()
    try:
        dash = service.dashboard
        assert dash is not None and dash.fleet
        poller = dash.poller
        time.sleep(1.0)
        assert poller.polls == {}  # no browser, nothing asked for: the dashboard reads nothing
        feed = wait_for(lambda: (lambda f: f if f is not None and not isinstance(f, str) else None)(poller.feed("b")), 30,
                     "the feed of b")  # asked for as a browser that chose b does (every frame)
        wait_for(lambda: (poller.feed("b"), poller.ids() == ["a", "b"])[1], 30, "the overview")
        assert feed.id == "b" and tuple(feed.layout.names) == tuple(service.structure("b").model.state_layout.names)

        def drawn():
            poller.feed("b")  # as a browser showing b does every frame
            feed.play()
            return feed.snapshot().estimate

        wait_for(drawn, 60, "b's live estimates drawn")
        assert service.structure("b").live.watched and not service.structure("a").live.watched
        assert poller.polls.get("structure_model") == 1 and poller.polls["live"] >= 1
        assert poller.feed("nope") is None
        wait_for(lambda: isinstance(poller.feed("nope"), str), 10, "the error of an unknown structure")
        assert "nope" in poller.feed("nope")
    finally:
        service.stop(drain_s=0)
