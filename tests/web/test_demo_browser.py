"""``shm demo`` itself in a real browser: the demo's scenario shortened (20 s windows, a two-minute
baseline, the damage at 260 s, 6 simulated minutes at max speed), its dashboard in headless
Chromium. The page draws the beam, populated spectra and trends, and shows the alarm the damage
raises; Ctrl-C ends the demo with exit status 0 and its log holds no traceback."""

from __future__ import annotations

import os
import re
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from shm_service.service import read_ready, start_serve
from shm_service.virtual_rig import SimulationSettings
from test_dashboard_browser import CHROMIUM_ARGS, VIEWPORT, _image, _visible, _wait, chromium  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[2]

#: make demo's configuration, shortened: the engine's defaults but 20 s windows every 10 s, a baseline
#: of 120 s (11 windows) and a short warm-up. The alarm levels and their hysteresis are the defaults.
SHORT = """
[analytics]
window_s = 20.0
overlap = 0.5
baseline_s = 120.0
[estimator]
warmup_s = 10.0
"""
DURATION_S, DAMAGE_AT_S = 360.0, 260.0


@pytest.mark.timeout(540)
def test_the_shortened_demo_in_headless_chromium(chromium, tmp_path):  # noqa: F811
    import httpx
    from playwright.sync_api import sync_playwright

    (tmp_path / "short.toml").write_text(SHORT)
    out = tmp_path / "demo.out"
    args = ["--dir", str(tmp_path / "demo"), "--config", str(tmp_path / "short.toml"), "--duration", f"{DURATION_S:g}",
            "--damage-at", f"{DAMAGE_AT_S:g}", "--speed", "max", "--port", "0", "--dashboard-port", "0", "--keep-running"]
    with open(out, "w") as stdout:
        # a process group of its own: Ctrl-C in a terminal goes to the whole foreground group
        demo = start_serve(args, command="demo", cwd=tmp_path, stdout=stdout, stderr=subprocess.STDOUT,
                           start_new_session=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=None,
                           ready_file=tmp_path / "ready.json")
    proc = demo.process
    try:
        def urls():
            if proc.poll() is not None:
                raise AssertionError(f"shm demo ended early ({proc.returncode}):\n{out.read_text()[-3000:]}")
            doc = read_ready(demo.ready_file)
            return (doc["api"], doc["dashboard"]) if doc and doc.get("dashboard") else None

        api_url, dash_url = _wait(urls, 240, "shm demo to say where its API and dashboard are")
        banner = out.read_text()
        # the banner's timeline is this configuration's: baseline, damage, when its alarm is expected
        assert re.search(r"\n\s+190 s\s+the baseline is learnt from 120 s", banner), banner
        assert re.search(r"\n\s+260 s\s+the damage appears: mass:0\.126@4\.0", banner), banner
        assert re.search(r"\n\s+300 s\s+a shift large against the baseline's scatter is raised", banner), banner
        with httpx.Client(base_url=api_url, timeout=10) as api, sync_playwright() as p:
            context = p.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
            )
            page = context.pages[0] if context.pages else context.new_page()
            try:
                page.goto(dash_url)
                page.wait_for_selector("canvas", timeout=60_000)
                _visible(page, "Pause live view").wait_for(timeout=60_000)
                _visible(page, "b1 · mode 1+2", exact=False).wait_for(timeout=60_000)

                # The damage raises the demo's alarm: the page says so (a raised alarm's notification, or
                # the header's count when the page came after it).
                _wait(lambda: api.get("/api/status").json()["service"]["done"], 420, "the scenario to end")
                alarms = api.get("/api/alarms").json()["alarms"]
                assert any(a["level"] == "alarm" for a in alarms), alarms
                # raised by the damage, not before it (data time since the simulation's start)
                first = min(alarms, key=lambda a: a["raised_at_s"])
                assert first["raised_at_s"] - SimulationSettings().start_time_ns / 1e9 > DAMAGE_AT_S, first
                st = api.get("/api/status").json()
                n_alarm = sum(a["level"] == "alarm" and a["state"] == "active" for a in alarms)
                _visible(page, f"{n_alarm} ALARM").wait_for(timeout=30_000)
                try:  # the browser's own notice about software WebGL only hides the picture
                    page.locator(".mantine-Notification-root", has_text="Software WebGL").locator("button").first.click(timeout=2_000)
                except Exception:
                    pass

                # The beam: blue pixels in a tall vertical strip of the 3D canvas.
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
                assert rows[-1] - rows[0] > 0.3 * h, "the beam should hang as a tall vertical ribbon"

                # Spectra: the latest window's, with the baseline's frequencies marked, drawn.
                page.get_by_text(re.compile(r"baseline \d+\.\d{3} / \d+\.\d{3} Hz")).filter(visible=True).first.wait_for(timeout=30_000)
                chart_box = page.evaluate(
                    "() => { const r = document.querySelector('.uplot canvas').getBoundingClientRect();"
                    " return [r.x, r.y, r.width, r.height]; }"
                )
                assert chart_box[2] > 50 and chart_box[3] > 50, f"spectrum canvas too small: {chart_box}"
                chart = _image(page.screenshot(clip=dict(zip(("x", "y", "width", "height"), chart_box))))
                assert (np.abs(chart - 255).sum(axis=-1) > 60).sum() > 300, "the spectrum canvas is blank"

                # Trends: every committed window, per eigenmode, with the chart levels in force (defaults).
                page.get_by_text("Trends", exact=True).first.click()
                _visible(page, "mode 3 (b2) eigenfrequency", exact=False).wait_for(timeout=30_000)
                _visible(page, "alarm +5 σ").wait_for(timeout=30_000)
                _visible(page, f"{st['pipeline']['windows_committed']} windows stored", exact=False).wait_for(timeout=30_000)

                # The alarm list: the demo's alarm by its chart and message.
                page.get_by_text("Alarms", exact=True).first.click()
                alarm = next(a for a in alarms if a["level"] == "alarm")
                _visible(page, alarm["message"]).wait_for(timeout=30_000)
            except BaseException:
                page.screenshot(path=str(tmp_path / "failure.png"))
                print("failure screenshot:", tmp_path / "failure.png")
                raise
            finally:
                context.close()
        assert st["service"]["pipeline_errors"] == 0 and st["sinks"]["dashboard"]["errors"] == 0, st["sinks"]
        assert st["pipeline"]["windows_committed"] == st["pipeline"]["windows"] > 0
        assert st["sources"][0]["lag_s"] is None  # max speed: no schedule to lag behind
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C
            try:
                proc.wait(90)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(10)
    text = out.read_text()
    assert proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]
    assert "shm demo: done (exit 0)" in text and re.search(r"\d+ alarms? raised", text), text[-3000:]
