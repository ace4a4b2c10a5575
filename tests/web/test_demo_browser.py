"""``shm demo`` itself in a real browser: the demo's scenario shortened (20 s windows, a two-minute
baseline, the damage at 260 s, 6 simulated minutes at max speed), its dashboard in headless
Chromium. The page draws the beam, populated spectra and trends, and shows the alarm the damage
raises; Ctrl-C ends the demo with exit status 0 and its log holds no traceback."""

from __future__ import annotations

import re

import pytest

from browser_helpers import (
    assert_chart_drawn, assert_tall_beam, browser_page, close_webgl_notice, interrupt_group, scene_picture, serve_urls,
    start_demo, visible, wait,
)
from shm_service.virtual_rig import SimulationSettings

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
def test_the_shortened_demo_in_headless_chromium(chromium, tmp_path):
    import httpx

    (tmp_path / "short.toml").write_text(SHORT)
    out = tmp_path / "demo.out"
    args = ["--dir", str(tmp_path / "demo"), "--config", str(tmp_path / "short.toml"), "--duration", f"{DURATION_S:g}",
            "--damage-at", f"{DAMAGE_AT_S:g}", "--speed", "max", "--port", "0", "--dashboard-port", "0", "--keep-running"]
    demo = start_demo(args, tmp_path, out)
    proc = demo.process
    try:
        api_url, dash_url = wait(lambda: serve_urls(demo, out, "shm demo"), 240, "shm demo to say where its API and dashboard are")
        banner = out.read_text()
        # the banner's timeline is this configuration's: baseline, damage, when its alarm is expected
        assert re.search(r"\n\s+190 s\s+the baseline is learnt from 120 s", banner), banner
        assert re.search(r"\n\s+260 s\s+the damage appears: mass:0\.126@4\.0", banner), banner
        assert re.search(r"\n\s+300 s\s+a shift large against the baseline's scatter is raised", banner), banner
        with httpx.Client(base_url=api_url, timeout=10) as api, browser_page(chromium, tmp_path) as page:
            page.goto(dash_url)
            page.wait_for_selector("canvas", timeout=60_000)
            visible(page, "Pause live view").wait_for(timeout=60_000)
            visible(page, "b1 · mode 1+2", exact=False).wait_for(timeout=60_000)

            # The damage raises the demo's alarm: the page says so (a raised alarm's notification, or
            # the header's count when the page came after it).
            wait(lambda: api.get("/api/status").json()["service"]["done"], 420, "the scenario to end")
            alarms = api.get("/api/alarms").json()["alarms"]
            assert any(a["level"] == "alarm" for a in alarms), alarms
            # raised by the damage, not before it (data time since the simulation's start)
            first = min(alarms, key=lambda a: a["raised_at_s"])
            assert first["raised_at_s"] - SimulationSettings().start_time_ns / 1e9 > DAMAGE_AT_S, first
            st = api.get("/api/status").json()
            n_alarm = sum(a["level"] == "alarm" and a["state"] == "active" for a in alarms)
            visible(page, f"{n_alarm} ALARM").wait_for(timeout=30_000)
            close_webgl_notice(page)
            assert_tall_beam(*scene_picture(page))

            # Spectra: the latest window's, with the baseline's frequencies marked, drawn.
            visible(page, re.compile(r"baseline \d+\.\d{3} / \d+\.\d{3} Hz")).wait_for(timeout=30_000)
            assert_chart_drawn(page)

            # Trends: every committed window, per eigenmode, with the chart levels in force (defaults).
            page.get_by_text("Trends", exact=True).first.click()
            visible(page, "mode 3 (b2) eigenfrequency", exact=False).wait_for(timeout=30_000)
            visible(page, "alarm +5 σ").wait_for(timeout=30_000)
            visible(page, f"{st['pipeline']['windows_committed']} windows stored", exact=False).wait_for(timeout=30_000)

            # The alarm list: the demo's alarm by its chart and message.
            page.get_by_text("Alarms", exact=True).first.click()
            alarm = next(a for a in alarms if a["level"] == "alarm")
            visible(page, alarm["message"]).wait_for(timeout=30_000)
        assert st["service"]["pipeline_errors"] == 0 and st["sinks"]["dashboard"]["errors"] == 0, st["sinks"]
        assert st["pipeline"]["windows_committed"] == st["pipeline"]["windows"] > 0
        assert st["sources"][0]["lag_s"] is None  # max speed: no schedule to lag behind
    finally:
        interrupt_group(proc)  # Ctrl-C
    text = out.read_text()
    assert proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]
    assert "shm demo: done (exit 0)" in text and re.search(r"\d+ alarms? raised", text), text[-3000:]
