"""A service of one structure is read through its port like a fleet's: nothing is pushed into its
dashboard. The dashboard's poller watches the structure (its live ring keeps estimates, with the
simulation's true deflection), reads its latest window (``structure_window``, also
``GET /api/structures/{id}/windows/latest``: its charts, trust and curvature) and draws them; the
pipeline has no push sink."""

from __future__ import annotations

import httpx
import numpy as np
import pytest
from browser_helpers import service_test_helpers, wait

from contract import ServicePort, WindowDocument

pytestmark = pytest.mark.e2e


@pytest.mark.timeout(300)
def test_a_structure_of_one_is_pulled_through_its_port(tmp_path):
    from shm_service.service import ApiServer, MonitoringService, create_app, load_settings

    overrides = service_test_helpers().fast_overrides(tmp_path, **{
        "source.spec": "sim", "source.speed": "4", "sim.duration_s": 600.0, "archive.enabled": False,
        "dashboard.enabled": True, "dashboard.port": 0,
    })
    service = MonitoringService(load_settings(None, overrides), environ={})
    assert isinstance(service, ServicePort) and not service.fleet
    api = ApiServer(create_app(service), "127.0.0.1", 0).start()
    service.start()
    try:
        sid = service.primary.id
        poller = service.dashboard.poller
        with httpx.Client(base_url=api.url, timeout=10) as c:
            assert c.get(f"/api/structures/{sid}/windows/latest").status_code == 404  # before its first window
            feed = wait(lambda: (lambda f: None if f is None or isinstance(f, str) else f)(poller.feed(sid)), 60,
                        "the structure's feed")

            def drawn():
                poller.feed(sid)  # as a browser showing it does every frame
                feed.play()
                est = feed.snapshot().estimate
                return est if est is not None and est.truth_deflection is not None else None

            est = wait(drawn, 120, "live estimates with the simulation's truth")
            assert est.truth_deflection.shape == feed.stations.shape and np.all(np.isfinite(est.truth_deflection))
            assert service.primary.live.watched

            def windowed():
                poller.feed(sid)
                return service.structure_window(sid)

            window = wait(windowed, 180, "a committed window")
            assert isinstance(window, WindowDocument) and window.source == sid
            doc = c.get(f"/api/structures/{sid}/windows/latest").json()
            assert doc["source"] == sid and doc["end_s"] >= window.end_s
            assert c.get("/api/structures/nope/windows/latest").status_code == 404

            def recorded():  # the window read through the port (trend rows say nothing of its trust)
                poller.feed(sid)
                return [w for w in feed.snapshot().windows if w.trusted is not None]

            records = wait(recorded, 60, "the window read from the port drawn")
            if window.curvature is not None:  # and its curvature along the stations
                assert records[-1].curvature_profile.size == feed.stations.size
        assert poller.polls.get("structure_window", 0) >= 1 and poller.polls.get("structure_fatigue", 0) == 0  # no hot spots
    finally:
        api.stop()
        service.stop(drain_s=0)
