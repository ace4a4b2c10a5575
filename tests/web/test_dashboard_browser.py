"""The dashboard in a real browser: headless Chromium (Debian's package, software WebGL).

The dashboard on a free port reads a stand-in port (``dashboard_feeder.FakePort``: the virtual
rig's truth as live estimates, spectra, a window, stored rows, alarms); Playwright drives
/usr/bin/chromium and checks that the beam and the plots are drawn, that it updates live at >= 10
frames/s without growing memory, that a raised alarm shows up, that acknowledging needs the token
and that a paused browser stops the live reads. Then the real service (``MonitoringService`` and
``shm serve``) with its dashboard. The README's screenshot ``docs/dashboard.png`` is this test's:
``SHM_DASHBOARD_SCREENSHOT=docs/dashboard.png make test``.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from browser_helpers import (
    assert_chart_drawn,
    assert_tall_beam,
    browser_page,
    close_webgl_notice,
    rss_bytes,
    scene_picture,
    serve_urls,
    service_test_helpers,
    stop_process,
    support_offset,
    visible,
    wait,
)
from dashboard_feeder import ID, TOKEN, FakePort, alarm, demo_spectrum, history_rows, simulated_estimates

from contract import ModeDocument, StructureModel, WindowDocument
from shm_service.service import start_serve

# The README's screenshot is refreshed on request (SHM_DASHBOARD_SCREENSHOT=docs/dashboard.png);
# by default the test writes to a temporary file, so running the tests leaves the tree clean.
SCREENSHOT = Path(os.environ.get("SHM_DASHBOARD_SCREENSHOT", Path(tempfile.gettempdir()) / "shm-dashboard.png"))


@pytest.fixture(scope="module")
def live_dashboard():
    from web import Dashboard

    rig, units, layout, stations, times, states, truth = simulated_estimates(20.0)
    sensor_states = {s.topic: "ok" for s in rig.sensors}
    sensor_states["/tof/s3"] = "degraded"
    sensor_states["/strain/g2"] = "rejected"
    window = WindowDocument(
        source=ID, start_s=0.0, end_s=30.0, kind="ambient", trusted=True, temperature_c=20.5,
        modes=[ModeDocument(mode=m, unit=u, frequency_hz=f, damping_ratio=0.004, confidence=0.9, score_sigma=z, level=lvl)
               for m, u, f, z, lvl in zip(range(1, 6), (1, 1, 2, 3, 4), (0.301, 0.861, 1.885, 3.507, 5.645),
                                          (0.2, -6.2, 0.1, -0.3, 0.5), ("ok", "alarm", "ok", "ok", "ok"))],
        curvature={"index": np.linspace(0.02, 0.35, stations.size).tolist(), "total": 0.2, "eta_m": float(stations[-1]),
                   "third": "lower"},
    )
    model = StructureModel(id=ID, rig=rig, units=units, layout=layout, stations=stations)
    service = FakePort(model, times, states, truth, history=history_rows(40, units, t0=-40 * 30.0), sensors=sensor_states,
                       spectrum=demo_spectrum(layout, units, times, states), window=window)
    dash = Dashboard(host="127.0.0.1", port=0, service=service)
    yield dash, service
    dash.stop()


@pytest.mark.timeout(180)
def test_dashboard_in_headless_chromium(chromium, live_dashboard, tmp_path):
    dash, service = live_dashboard
    with browser_page(chromium, tmp_path) as page:
        t_start = time.monotonic()
        page.goto(dash.url)
        page.wait_for_selector("canvas", timeout=30_000)
        visible(page, "Pause live view").wait_for(timeout=30_000)
        visible(page, "b1 · mode 1+2", exact=False).wait_for(timeout=15_000)
        print(f"page ready after {time.monotonic() - t_start:.1f} s")
        # the sheet has no hot spots: no Loads tab (and its fatigue is never asked for)
        assert page.get_by_text("Loads", exact=True).count() == 0 and "structure_fatigue" not in dash.poller.polls
        # Live: frames keep coming at >= 10 per second, the estimates at the live ring's 10 per second,
        # and memory stays flat.
        time.sleep(2.0)
        rss0, frames0, served0, t0 = rss_bytes(), dash.frames, service.served, time.monotonic()
        time.sleep(3.0)
        dt = time.monotonic() - t0
        assert (dash.frames - frames0) / dt >= 10.0
        assert (service.served - served0) / dt >= 8.0
        assert dash.client_count == 1
        assert rss_bytes() - rss0 < 30 * 2**20
        (view,) = dash.views()
        assert view.feed.snapshot().estimate.truth_deflection is not None  # the simulation's truth travels with them

        # An alarm raised by the service shows up as a notification and in the header.
        service.add_alarm(alarm(42))
        visible(page, "ALARM #42 raised").wait_for(timeout=10_000)
        visible(page, "1 ALARM").wait_for(timeout=10_000)
        close_webgl_notice(page)
        time.sleep(1.0)
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        SCREENSHOT.write_bytes(page.screenshot())

        scene, height = scene_picture(page)
        assert_tall_beam(scene, height)
        background = np.all(np.abs(scene - scene[5, 5]) < 8, axis=-1)
        assert background.mean() < 0.97, "the scene looks blank"
        # The plots: uPlot charts in the DOM, the first spectrum visible and drawn.
        assert page.locator(".uplot").count() >= layout_gamma(dash)
        assert page.locator(".uplot canvas").first.is_visible()
        assert_chart_drawn(page)
        # The beam moves: two pictures of the scene differ.
        shot_a, _ = scene_picture(page)
        time.sleep(0.6)
        shot_b, _ = scene_picture(page)
        assert np.any(np.abs(shot_a - shot_b) > 30), "the beam did not move between frames"

        # The latest window read through the port: its curvature along the stations is drawn.
        page.get_by_text("Trends", exact=True).first.click()
        visible(page, "Curvature-change index along the beam", exact=False).wait_for(timeout=10_000)
        visible(page, "largest change at η", exact=False).wait_for(timeout=10_000)

        # Acknowledge needs the token: wrong token refused, right token accepted.
        page.get_by_text("Alarms", exact=True).first.click()
        visible(page, "mode 2 frequency 1.1 % below baseline").wait_for(timeout=10_000)
        token = (page.locator(".mantine-Flex-root", has=page.get_by_text("Operator token", exact=True))
                 .locator("input").filter(visible=True).first)

        def type_token(value: str) -> None:
            token.fill(value)
            wait(lambda: view.shown.alarms.token.value == value, 10, f"the token {value!r} to reach the view", poll=0.05)

        type_token("wrong")
        page.get_by_role("button", name="Acknowledge").click()
        visible(page, "Not acknowledged").wait_for(timeout=10_000)
        assert not service.alarms()[0].acknowledged
        type_token(TOKEN)
        page.get_by_role("button", name="Acknowledge").click()
        visible(page, "Alarm #42 acknowledged").wait_for(timeout=10_000)
        assert service.alarms()[0].acknowledged
        visible(page, "active, acknowledged by dashboard", exact=False).wait_for(timeout=10_000)

        # Pause freezes this browser's view and, with no live browser left, the live reads.
        page.get_by_text("Spectra", exact=True).first.click()
        page.get_by_text("Pause live view").first.click()
        # the click travels over the websocket to the view, and the header comes back on its next
        # render: on a loaded machine each leg may take seconds, so the server side is waited for first
        wait(lambda: view.paused, 30, "the pause to reach the view", poll=0.05)
        visible(page, "PAUSED").wait_for(timeout=30_000)
        time.sleep(1.0)
        live0 = dash.poller.polls.get("live", 0)
        time.sleep(2.0)
        assert dash.poller.polls.get("live", 0) == live0, "a paused browser still has the estimates read"
    wait(lambda: dash.client_count == 0, 10, "the browser to leave")


def layout_gamma(dash) -> int:
    (view,) = dash.views()
    return view.feed.gamma


@pytest.mark.timeout(300)
def test_alarm_raised_by_the_service_shows_on_the_page(chromium, tmp_path):
    """End to end: the service (replay of a damaged recording) with its dashboard on free ports, read
    through its port like a fleet's: the alarm the data raises is notified on the page."""
    from shm_service.service import MonitoringService, load_settings
    from shm_service.virtual_rig import SimulationSettings, simulate

    recording = tmp_path / "damaged.mcap"
    simulate(SimulationSettings(duration=150.0, rest=10.0, excitation="ambient", seed=3,
                                damage=("mass:0.126@4.0",), damage_at=90.0), recording)
    overrides = service_test_helpers().fast_overrides(tmp_path, **{
        # 8x: the page waits for the alarm at the end of the replay, not for a state in between
        "source.spec": f"replay:{recording}", "source.speed": "8", "source.keep_running": True,
        "dashboard.enabled": True, "dashboard.port": 0,
    })
    service = MonitoringService(load_settings(None, overrides), environ={})
    service.start()
    try:
        assert service.dashboard is not None
        with browser_page(chromium, tmp_path) as page:
            page.goto(service.dashboard.url)
            page.wait_for_selector("canvas", timeout=30_000)
            visible(page, "Pause live view").wait_for(timeout=30_000)
            # The pipeline raises the alarm from the data; the page shows its notification.
            visible(page, re.compile(r"ALARM #\d+ raised")).wait_for(timeout=150_000)
            assert any(a.level == "alarm" for a in service.alarms())
            # the window read through the port: the curvature along the stations
            page.get_by_text("Trends", exact=True).first.click()
            visible(page, "largest change at η", exact=False).wait_for(timeout=30_000)
    finally:
        service.stop(drain_s=0)


#: The two rigs of the real-service test: a standing clamped mast (Γ = 3, the benchmark layout scaled
#: to 1.5 m, a 1 % tip mass that fits the short beam) and the pinned pendulum with Γ = 5 (dense layout).
SERVICE_CASES = {
    "mast": {"estimator.modes": 3, "estimator.imus": 4, "sim.layout": "benchmark", "sim.support": "clamped",
             "sim.orientation": "standing", "sim.length_m": 1.5, "sim.damage": ["mass:0.05@1.5"]},
    "pendulum": {"estimator.modes": 5, "estimator.imus": 5, "sim.layout": "dense"},
}


@pytest.mark.timeout(480)
@pytest.mark.parametrize("case", list(SERVICE_CASES))
def test_the_real_service_with_its_dashboard_for_gamma(chromium, tmp_path, case):
    """``shm serve --source sim`` with ``[estimator] modes = Γ`` as a subprocess, its dashboard in
    Chromium: the beam drawn (a standing clamped mast upright above its clamp, the pendulum hanging
    from its pin), spectra before and after the baseline, the configured chart levels drawn,
    trends labelled like the spectra by the model's modes (no combimode for the clamp), an alarm
    acknowledged over the HTTP API shown as such."""
    import contextlib

    import httpx
    import tomli_w

    mast = case == "mast"
    modes = SERVICE_CASES[case]["estimator.modes"]
    token = "browser-test-token"
    (tmp_path / "token").write_text(token + "\n")
    config = service_test_helpers().fast_overrides(tmp_path, **{
        # Levels unlike the analytics' defaults (3, 5, 6 σ): the page must show these.
        "analytics.warning_sigma": 0.5, "analytics.alarm_sigma": 1.0, "analytics.curvature_alarm_sigma": 1.5,
        # A learning phase long enough to look at the spectra before the baseline exists.
        "analytics.baseline_s": 80.0,
        **SERVICE_CASES[case], "sim.duration_s": 900.0, "sim.damage_at_s": 150.0,
        "dashboard.enabled": True, "dashboard.port": 0, "archive.enabled": False,
    })
    (tmp_path / "serve.toml").write_text(tomli_w.dumps(config))
    out, log = tmp_path / "serve.out", tmp_path / "serve.log"
    args = ["--config", str(tmp_path / "serve.toml"), "--source", "sim", "--speed", "4", "--port", "0",
            "--token-file", str(tmp_path / "token")]
    root = Path(__file__).resolve().parents[2]
    with open(out, "w") as stdout, open(log, "w") as stderr:
        serve = start_serve(args, cwd=tmp_path, stdout=stdout, stderr=stderr, env={**os.environ, "PYTHONPATH": str(root)},
                            timeout=None, ready_file=tmp_path / "ready.json")
    proc = serve.process
    stack = contextlib.ExitStack()
    try:
        api_url, dash_url = wait(lambda: serve_urls(serve, log), 180, "shm serve to say where its API and dashboard are")
        api = stack.enter_context(httpx.Client(base_url=api_url, timeout=10))
        # The clamped mast: b_k is mode k (no combimode); the pendulum's b1 carries modes 1 and 2.
        gamma_text = "b3 · mode 3" if mast else "b5 · mode 6"
        with browser_page(chromium, tmp_path) as page:
            page.goto(dash_url)
            page.wait_for_selector("canvas", timeout=60_000)
            visible(page, "Pause live view").wait_for(timeout=60_000)
            # One spectrum per unit deformation, labelled by the modes it carries (the last: Γ's).
            visible(page, gamma_text, exact=False).wait_for(timeout=30_000)
            assert page.get_by_text(f"b{modes + 1} · mode", exact=False).count() == 0
            assert (page.get_by_text("mode 1+2", exact=False).count() == 0) == mast
            if mast:
                visible(page, "φ ≡ 0 (clamped)", exact=False).wait_for(timeout=30_000)

            # Spectra before the baseline exists: tracked frequencies drawn, no baseline yet.
            def learning_with_spectra():
                st = api.get("/api/status").json()
                return st["pipeline"]["baseline"] == "learning" and api.get("/api/spectra/latest").status_code == 200

            wait(learning_with_spectra, 120, "a committed window while the baseline is being learnt")
            # b1 carries modes 1 and 2 on the pendulum, mode 1 alone on the mast.
            tracked = re.compile(r"tracked \d+\.\d{3} Hz" if mast else r"tracked \d+\.\d{3} / \d+\.\d{3} Hz")
            page.get_by_text(tracked).filter(visible=True).first.wait_for(timeout=30_000)
            visible(page, "baseline – Hz").wait_for(timeout=30_000)
            assert api.get("/api/status").json()["baseline"]["modes"] is None, "the baseline came before the check"
            assert_chart_drawn(page)

            # The beam: blue pixels in a tall vertical strip of the 3D canvas.
            close_webgl_notice(page)
            scene, height = scene_picture(page)
            assert_tall_beam(scene, height)
            # Upright: the mast's clamp and rail below the beam; the pendulum's pin and rail above it.
            offset = support_offset(scene)
            print(f"{case}: support drawn {offset:+.2f} of the height from the beam")
            assert offset > 0.1 if mast else offset < -0.1, f"support drawn at {offset:+.2f} of the height from the beam"

            # After the baseline: its frequencies are marked too (both of the combimode's modes).
            wait(lambda: api.get("/api/status").json()["baseline"]["modes"] is not None, 180, "the baseline")
            baseline = re.compile(r"baseline \d+\.\d{3} Hz" if mast else r"baseline \d+\.\d{3} / \d+\.\d{3} Hz")
            page.get_by_text(baseline).filter(visible=True).first.wait_for(timeout=30_000)

            # Trends: labelled per eigenmode like the spectra, with the configured chart levels.
            page.get_by_text("Trends", exact=True).first.click()
            first_mode = "mode 1 (b1) eigenfrequency" if mast else "mode 2 (b1) eigenfrequency"
            last_mode = f"mode {modes} (b{modes}) eigenfrequency" if mast else f"mode {modes + 1} (b{modes}) eigenfrequency"
            visible(page, first_mode, exact=False).wait_for(timeout=60_000)
            visible(page, last_mode, exact=False).wait_for(timeout=60_000)
            visible(page, "alarm +1 σ").wait_for(timeout=60_000)  # frequency charts: alarm_sigma
            visible(page, "alarm +1.5 σ").wait_for(timeout=120_000)  # the curvature chart's own level

            # An alarm acknowledged over the HTTP API shows as acknowledged on the page.
            alarms = wait(lambda: api.get("/api/alarms").json()["alarms"], 180, "an alarm")
            first = alarms[-1]
            ack = api.post(f"/api/alarms/{first['id']}/ack", headers={"Authorization": f"Bearer {token}"})
            assert ack.status_code == 200 and ack.json()["acknowledged_at_s"] is not None
            page.get_by_text("Alarms", exact=True).first.click()
            visible(page, "acknowledged by api", exact=False).wait_for(timeout=30_000)

        # the source runs on: a window analysed a moment ago may still be on its way to the database
        st = wait(lambda: (s if (s := api.get("/api/status").json())["pipeline"]["windows_committed"] == s["pipeline"]["windows"]
                           else None), 60, "every analysed window committed")
        assert st["service"]["pipeline_errors"] == 0 and st["sinks"]["dashboard"]["errors"] == 0, st["sinks"]
        assert st["pipeline"]["windows"] > 0
        assert st["model"]["gamma"] == modes
        names = st["model"]["state_names"]
        if mast:  # no φ, no gyro bias at D; the residual mode (mode 4) and its rate; four gyro biases
            assert st["model"]["support"] == "clamped" and "phi" not in names and {"r1", "vr1"} <= set(names)
            assert st["model"]["unit_modes"] == [[1], [2], [3]] and len(names) == 4 + modes + 2 + 4
        else:
            assert len(names) == 5 + modes + max(4, modes) + 1
    finally:
        stack.close()
        stop_process(proc)
    text = log.read_text()
    assert proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]
