"""The dashboard in a real browser: headless Chromium (Debian's package, software WebGL).

Starts the dashboard on a free port, feeds it the virtual rig (truth as estimates, spectra,
windows, an alarm), opens the page with Playwright driving /usr/bin/chromium, and checks that
the beam and the plots are drawn, that it updates live at >= 10 frames/s without growing memory,
that a raised alarm shows up, and that acknowledging needs the token. The README's screenshot
``docs/dashboard.png`` is this test's: ``SHM_DASHBOARD_SCREENSHOT=docs/dashboard.png make test``.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from contract import ModeDocument, WindowDocument
from shm_service.service import ServeProcess, read_ready, start_serve
from dashboard_feeder import TOKEN, DemoFeeder, FakeService, alarm, history_rows, simulated_estimates

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
# The README's screenshot is refreshed on request (SHM_DASHBOARD_SCREENSHOT=docs/dashboard.png);
# by default the test writes to a temporary file, so running the tests leaves the tree clean.
SCREENSHOT = Path(os.environ.get("SHM_DASHBOARD_SCREENSHOT", Path(tempfile.gettempdir()) / "shm-dashboard.png"))
VIEWPORT = {"width": 1600, "height": 1000}


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's chromium, installed with apt-get when missing (CI runs as root on a fresh machine)."""
    if not os.path.exists(CHROMIUM):
        problem = "apt-get is not available"
        if shutil.which("apt-get") and hasattr(os, "geteuid") and os.geteuid() == 0:
            env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
            problem = ""
            # test files on other xdist workers may install at the same moment: wait for dpkg's lock
            wait = ["-o", "DPkg::Lock::Timeout=600"]
            for cmd in (["apt-get", *wait, "update"], ["apt-get", *wait, "install", "-y", "--no-install-recommends", "chromium"]):
                result = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
                if result.returncode != 0:
                    problem = f"{' '.join(cmd)} failed: {result.stderr.strip()[-500:]}"
                    break
        elif shutil.which("apt-get"):
            problem = "installing needs root"
        if not os.path.exists(CHROMIUM):
            pytest.skip(f"cannot install Debian's chromium ({problem}); the browser test needs {CHROMIUM}")
    return CHROMIUM


@pytest.fixture(scope="module")
def live_dashboard():
    from web import Dashboard

    rig, units, layout, stations, times, states, truth = simulated_estimates(20.0)
    sensor_states = {s.topic: "ok" for s in rig.sensors}
    sensor_states["/tof/s3"] = "degraded"
    sensor_states["/strain/g2"] = "rejected"
    service = FakeService(history=history_rows(40, units, t0=-40 * 30.0), sensors=sensor_states)
    dash = Dashboard(host="127.0.0.1", port=0, rig=rig, units=units, layout=layout, stations=stations, service=service)
    feeder = DemoFeeder(dash, times, states, truth, sensor_states, rate_hz=20.0)
    feeder.push_spectra(len(times) - 1)
    dash.push_window(WindowDocument(
        source="virtual-rig", start_s=0.0, end_s=30.0, kind="ambient", trusted=True, temperature_c=20.5,
        modes=[ModeDocument(mode=m, unit=u, frequency_hz=f, damping_ratio=0.004, confidence=0.9, score_sigma=z, level=lvl)
               for m, u, f, z, lvl in zip(range(1, 6), (1, 1, 2, 3, 4), (0.301, 0.861, 1.885, 3.507, 5.645),
                                          (0.2, -6.2, 0.1, -0.3, 0.5), ("ok", "alarm", "ok", "ok", "ok"))],
        curvature={"index": np.linspace(0.02, 0.35, stations.size).tolist(), "total": 0.2, "eta_m": float(stations[-1]),
                   "third": "lower"},
    ))
    feeder.start()
    yield dash, service, feeder
    feeder.stop()
    dash.stop()


def _visible(page, text: str, **kwargs):
    """The first visible element with ``text`` (notifications and tabs keep hidden copies)."""
    return page.get_by_text(text, **kwargs).filter(visible=True).first


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _image(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


@pytest.mark.timeout(180)
def test_dashboard_in_headless_chromium(chromium, live_dashboard, tmp_path):
    from playwright.sync_api import sync_playwright

    dash, service, feeder = live_dashboard
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"),  # a fresh --user-data-dir
            executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
        )
        try:
            page = context.pages[0] if context.pages else context.new_page()
            t_start = time.monotonic()
            page.goto(dash.url)
            page.wait_for_selector("canvas", timeout=30_000)
            _visible(page, "Pause live view").wait_for(timeout=30_000)
            _visible(page, "b1 · mode 1+2", exact=False).wait_for(timeout=15_000)

            print(f"page ready after {time.monotonic() - t_start:.1f} s")
            # Live: frames keep coming at >= 10 per second and memory stays flat.
            time.sleep(2.0)
            rss0, frames0, pushed0, t0 = _rss_bytes(), dash.frames, feeder.pushed, time.monotonic()
            time.sleep(3.0)
            dt = time.monotonic() - t0
            assert (dash.frames - frames0) / dt >= 10.0
            assert (feeder.pushed - pushed0) / dt >= 10.0
            assert dash.client_count == 1
            assert _rss_bytes() - rss0 < 30 * 2**20

            # An alarm raised by the service shows up as a notification and in the header.
            service.add_alarm(alarm(42))
            dash.push_alarm(alarm(42))
            _visible(page, "ALARM #42 raised").wait_for(timeout=10_000)
            _visible(page, "1 ALARM").wait_for(timeout=10_000)
            try:  # the browser's own notice about software WebGL only hides the picture
                page.locator(".mantine-Notification-root", has_text="Software WebGL").locator("button").first.click(timeout=2_000)
            except Exception:
                pass
            time.sleep(1.0)

            png = page.screenshot()
            SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
            SCREENSHOT.write_bytes(png)

            # The beam: blue pixels in a tall vertical strip of the 3D canvas (left of the panel).
            box = page.evaluate(
                "() => { const c = [...document.querySelectorAll('canvas')]"
                ".sort((a, b) => b.width * b.height - a.width * a.height)[0];"
                " const r = c.getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }"
            )
            img = _image(png)
            x0, y0, w, h = (int(round(v)) for v in box)
            scene = img[y0 : y0 + h, x0 : x0 + int(0.62 * w)]
            r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
            blue = (b > 120) & (b - r > 70) & (b - g > 30)
            rows = np.flatnonzero(blue.any(axis=1))
            assert blue.sum() > 400, f"beam not drawn: {blue.sum()} blue pixels"
            assert rows[-1] - rows[0] > 0.3 * h, "the beam should hang as a tall vertical ribbon"
            background = np.all(np.abs(scene - scene[5, 5]) < 8, axis=-1)
            assert background.mean() < 0.97, "the scene looks blank"

            # The plots: uPlot charts in the DOM, the first spectrum visible and drawn.
            assert page.locator(".uplot").count() >= dash.gamma
            assert page.locator(".uplot canvas").first.is_visible()
            # viser re-creates a uPlot canvas when its data changes, so an element screenshot can
            # race a live update ("not attached"); a page screenshot clipped to where the first
            # canvas is cannot.
            chart_box = page.evaluate(
                "() => { const r = document.querySelector('.uplot canvas').getBoundingClientRect();"
                " return [r.x, r.y, r.width, r.height]; }"
            )
            assert chart_box[2] > 50 and chart_box[3] > 50, f"spectrum canvas too small: {chart_box}"
            chart = _image(page.screenshot(clip=dict(zip(("x", "y", "width", "height"), chart_box))))
            assert (np.abs(chart - 255).sum(axis=-1) > 60).sum() > 300, "the spectrum canvas is blank"

            # The beam moves: two pictures of the scene differ.
            shot_a = _image(page.screenshot(clip={"x": x0, "y": y0, "width": int(0.62 * w), "height": h}))
            time.sleep(0.6)
            shot_b = _image(page.screenshot(clip={"x": x0, "y": y0, "width": int(0.62 * w), "height": h}))
            assert np.any(np.abs(shot_a - shot_b) > 30), "the beam did not move between frames"

            # Acknowledge needs the token: wrong token refused, right token accepted.
            page.get_by_text("Alarms", exact=True).first.click()
            _visible(page, "mode 2 frequency 1.1 % below baseline").wait_for(timeout=10_000)
            token = (
                page.locator(".mantine-Flex-root", has=page.get_by_text("Operator token", exact=True))
                .locator("input").filter(visible=True).first
            )
            (view,) = dash._views.values()

            def type_token(value: str) -> None:
                token.fill(value)
                deadline = time.monotonic() + 10
                while view.token.value != value and time.monotonic() < deadline:
                    time.sleep(0.05)
                assert view.token.value == value

            type_token("wrong")
            page.get_by_role("button", name="Acknowledge").click()
            _visible(page, "Not acknowledged").wait_for(timeout=10_000)
            assert not service.alarms()[0].acknowledged
            type_token(TOKEN)
            page.get_by_role("button", name="Acknowledge").click()
            _visible(page, "Alarm #42 acknowledged").wait_for(timeout=10_000)
            assert service.alarms()[0].acknowledged
            _visible(page, "active, acknowledged by dashboard", exact=False).wait_for(timeout=10_000)

            # Pause freezes this browser's view and, with no live browser left, the pushes.
            page.get_by_text("Spectra", exact=True).first.click()
            page.get_by_text("Pause live view").first.click()
            deadline = time.monotonic() + 10
            while service.paused is not True and time.monotonic() < deadline:
                time.sleep(0.1)
            assert service.paused is True
            _visible(page, "PAUSED").wait_for(timeout=10_000)
        except BaseException:
            page.screenshot(path=str(tmp_path / "failure.png"))
            print("failure screenshot:", tmp_path / "failure.png")
            raise
        finally:
            context.close()
    deadline = time.monotonic() + 10
    while dash.client_count and time.monotonic() < deadline:
        time.sleep(0.1)
    assert dash.client_count == 0
    assert service.paused is False  # no browser left: pushes resume


def _service_test_helpers():
    """The service tests' fast analytics settings (small windows, sensitive charts)."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "shm_service" / "service" / "svc_helpers.py"
    spec = importlib.util.spec_from_file_location("svc_helpers_for_web", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.timeout(300)
def test_alarm_raised_by_the_service_shows_on_the_page(chromium, tmp_path):
    """End to end: shm serve (replay of a damaged recording) with its dashboard on free ports."""

    from playwright.sync_api import sync_playwright

    from shm_service.service._config import load_settings
    from shm_service.service._service import MonitoringService
    from shm_service.virtual_rig import SimulationSettings, simulate

    recording = tmp_path / "damaged.mcap"
    simulate(SimulationSettings(duration=150.0, rest=10.0, excitation="ambient", seed=3,
                                damage=("mass:0.126@4.0",), damage_at=90.0), recording)
    overrides = _service_test_helpers().fast_overrides(tmp_path, **{
        "source.spec": f"replay:{recording}", "source.speed": "2", "source.keep_running": True,
        "dashboard.enabled": True, "dashboard.port": 0,
    })
    service = MonitoringService(load_settings(None, overrides), environ={})
    service.start()
    try:
        assert service.dashboard is not None
        with sync_playwright() as p:
            context = p.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
            )
            try:
                page = context.pages[0] if context.pages else context.new_page()
                page.goto(service.dashboard.url)
                page.wait_for_selector("canvas", timeout=30_000)
                _visible(page, "Pause live view").wait_for(timeout=30_000)
                # The pipeline raises the alarm from the data; the page shows its notification.
                page.get_by_text(re.compile(r"ALARM #\d+ raised")).filter(visible=True).first.wait_for(timeout=150_000)
                assert any(a.level == "alarm" for a in service.alarms())
            finally:
                context.close()
    finally:
        service.stop(drain_s=0)


def _support_offset(scene: np.ndarray) -> float:
    """Where the support is drawn against the beam, as a share of the picture's height: the median
    row of the dark grey pixels (the bearing or clamp and its rail) minus the median row of the
    beam's blue ones. Negative: above the beam (it hangs); positive: below it (it stands)."""
    r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
    blue = (b > 120) & (b - r > 70) & (b - g > 30)
    dark = (scene.max(axis=-1) < 110) & (np.ptp(scene, axis=-1) < 30)
    assert blue.sum() > 400 and dark.sum() > 200, (blue.sum(), dark.sum())
    return float(np.median(np.nonzero(dark)[0]) - np.median(np.nonzero(blue)[0])) / scene.shape[0]


def stop_process(proc: subprocess.Popen) -> None:
    """SIGTERM (``shm serve`` drains and prints its summary), then kill after a minute."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def serve_urls(serve: ServeProcess, log: Path, what: str = "shm serve") -> tuple[str, str] | None:
    """The API and dashboard addresses of ``serve``'s ready document (None: not yet); its log's tail
    when it ended before it was ready."""
    if serve.process.poll() is not None:
        raise AssertionError(f"{what} ended early ({serve.process.returncode}): {log.read_text()[-3000:]}")
    doc = read_ready(serve.ready_file)
    return (doc["api"], doc["dashboard"]) if doc and doc.get("dashboard") else None


def _wait(predicate, timeout: float, what: str, poll: float = 0.25):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


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
    from playwright.sync_api import sync_playwright

    mast = case == "mast"
    modes = SERVICE_CASES[case]["estimator.modes"]
    token = "browser-test-token"
    (tmp_path / "token").write_text(token + "\n")
    config = _service_test_helpers().fast_overrides(tmp_path, **{
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
        api_url, dash_url = _wait(lambda: serve_urls(serve, log), 180, "shm serve to say where its API and dashboard are")
        api = stack.enter_context(httpx.Client(base_url=api_url, timeout=10))
        # The clamped mast: b_k is mode k (no combimode); the pendulum's b1 carries modes 1 and 2.
        gamma_text = "b3 · mode 3" if mast else "b5 · mode 6"
        with sync_playwright() as p:
            context = p.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
            )
            try:
                page = context.pages[0] if context.pages else context.new_page()
                page.goto(dash_url)
                page.wait_for_selector("canvas", timeout=60_000)
                _visible(page, "Pause live view").wait_for(timeout=60_000)
                # One spectrum per unit deformation, labelled by the modes it carries (the last: Γ's).
                _visible(page, gamma_text, exact=False).wait_for(timeout=30_000)
                assert page.get_by_text(f"b{modes + 1} · mode", exact=False).count() == 0
                assert (page.get_by_text("mode 1+2", exact=False).count() == 0) == mast
                if mast:
                    _visible(page, "φ ≡ 0 (clamped)", exact=False).wait_for(timeout=30_000)

                # Spectra before the baseline exists: tracked frequencies drawn, no baseline yet.
                def learning_with_spectra():
                    st = api.get("/api/status").json()
                    return st["pipeline"]["baseline"] == "learning" and api.get("/api/spectra/latest").status_code == 200

                _wait(learning_with_spectra, 120, "a committed window while the baseline is being learnt")
                # b1 carries modes 1 and 2 on the pendulum, mode 1 alone on the mast.
                tracked = re.compile(r"tracked \d+\.\d{3} Hz" if mast else r"tracked \d+\.\d{3} / \d+\.\d{3} Hz")
                page.get_by_text(tracked).filter(visible=True).first.wait_for(timeout=30_000)
                _visible(page, "baseline – Hz").wait_for(timeout=30_000)
                assert api.get("/api/status").json()["baseline"]["modes"] is None, "the baseline came before the check"
                chart_box = page.evaluate(
                    "() => { const r = document.querySelector('.uplot canvas').getBoundingClientRect();"
                    " return [r.x, r.y, r.width, r.height]; }"
                )
                chart = _image(page.screenshot(clip=dict(zip(("x", "y", "width", "height"), chart_box))))
                assert (np.abs(chart - 255).sum(axis=-1) > 60).sum() > 300, "the spectrum canvas is blank"

                # The beam: blue pixels in a tall vertical strip of the 3D canvas.
                try:
                    page.locator(".mantine-Notification-root", has_text="Software WebGL").locator("button").first.click(timeout=2_000)
                except Exception:
                    pass
                box = page.evaluate(
                    "() => { const c = [...document.querySelectorAll('canvas')]"
                    ".sort((a, b) => b.width * b.height - a.width * a.height)[0];"
                    " const r = c.getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }"
                )
                x0, y0, w, h = (int(round(v)) for v in box)
                scene = _image(page.screenshot(clip={"x": x0, "y": y0, "width": int(0.62 * w), "height": h}))
                r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
                blue = (b > 120) & (b - r > 70) & (b - g > 30)
                rows = np.flatnonzero(blue.any(axis=1))
                assert blue.sum() > 400, f"beam not drawn: {blue.sum()} blue pixels"
                assert rows[-1] - rows[0] > 0.3 * h, "the beam should be a tall vertical ribbon"
                # Upright: the mast's clamp and rail below the beam; the pendulum's pin and rail above it.
                offset = _support_offset(scene)
                print(f"{case}: support drawn {offset:+.2f} of the height from the beam")
                assert offset > 0.1 if mast else offset < -0.1, f"support drawn at {offset:+.2f} of the height from the beam"

                # After the baseline: its frequencies are marked too (both of the combimode's modes).
                _wait(lambda: api.get("/api/status").json()["baseline"]["modes"] is not None, 180, "the baseline")
                baseline = re.compile(r"baseline \d+\.\d{3} Hz" if mast else r"baseline \d+\.\d{3} / \d+\.\d{3} Hz")
                page.get_by_text(baseline).filter(visible=True).first.wait_for(timeout=30_000)

                # Trends: labelled per eigenmode like the spectra, with the configured chart levels.
                page.get_by_text("Trends", exact=True).first.click()
                first_mode = "mode 1 (b1) eigenfrequency" if mast else "mode 2 (b1) eigenfrequency"
                last_mode = f"mode {modes} (b{modes}) eigenfrequency" if mast else f"mode {modes + 1} (b{modes}) eigenfrequency"
                _visible(page, first_mode, exact=False).wait_for(timeout=60_000)
                _visible(page, last_mode, exact=False).wait_for(timeout=60_000)
                _visible(page, "alarm +1 σ").wait_for(timeout=60_000)  # frequency charts: alarm_sigma
                _visible(page, "alarm +1.5 σ").wait_for(timeout=120_000)  # the curvature chart's own level

                # An alarm acknowledged over the HTTP API shows as acknowledged on the page.
                alarms = _wait(lambda: api.get("/api/alarms").json()["alarms"], 180, "an alarm")
                first = alarms[-1]
                ack = api.post(f"/api/alarms/{first['id']}/ack", headers={"Authorization": f"Bearer {token}"})
                assert ack.status_code == 200 and ack.json()["acknowledged_at_s"] is not None
                page.get_by_text("Alarms", exact=True).first.click()
                _visible(page, "acknowledged by api", exact=False).wait_for(timeout=30_000)
            except BaseException:
                page.screenshot(path=str(tmp_path / "failure.png"))
                print("failure screenshot:", tmp_path / "failure.png")
                raise
            finally:
                context.close()
        st = api.get("/api/status").json()
        assert st["service"]["pipeline_errors"] == 0 and st["sinks"]["dashboard"]["errors"] == 0, st["sinks"]
        assert st["pipeline"]["windows_committed"] == st["pipeline"]["windows"] > 0
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
