"""A fleet's dashboard in headless Chromium, against the real ``shm serve`` of three simulated
structures on two worker processes (the dashboard in the front process): the overview lists every
structure with its state; the selector switches the 3-D view, its labels, the spectra and the live
estimates to the chosen structure (a pinned pendulum hanging from its pin, a clamped 1.5 m mast
standing on its clamp); only the structures shown are read live. ``/metrics`` of the same fleet
over real HTTP: every structure's samples labelled ``structure``."""

from __future__ import annotations

import os
import re
import tempfile
import time
from pathlib import Path

import httpx
import pytest

from shm_service.service import start_serve
from browser_helpers import (
    ROOT, browser_page, close_webgl_notice, scene_picture, serve_urls, stop_process, support_offset, visible, wait,
)
# The README's picture of a fleet's dashboard: SHM_FLEET_SCREENSHOT=docs/fleet-dashboard.png (else a temporary file).
SCREENSHOT = Path(os.environ.get("SHM_FLEET_SCREENSHOT", Path(tempfile.gettempdir()) / "shm-fleet-dashboard.png"))
TOKEN = "fleet-dashboard-token"
IDS = ("mast-01", "pendulum-02", "pendulum-03")

FLEET_TOML = """
workers = 2
[sim]
block_s = 2.0
duration_s = 3600.0
[estimator]
calibration_s = 10.0
warmup_s = 5.0
chunk_s = 1.0
[analytics]
window_s = 20.0
overlap = 0.5
baseline_s = 40.0
baseline_min_windows = 3
[archive]
enabled = false
[dashboard]
enabled = true
port = 0
[[structures]]
id = "mast-01"
source = "sim"
[structures.sim]
seed = 1
layout = "benchmark"
support = "clamped"
orientation = "standing"
length_m = 1.5
damage = ["mass:0.05@1.5"]
[structures.estimator]
modes = 3
imus = 4
[[structures]]
id = "pendulum-02"
source = "sim"
[structures.sim]
seed = 2
[[structures]]
id = "pendulum-03"
source = "sim"
[structures.sim]
seed = 3
"""


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """``shm serve --config fleet.toml`` (workers = 2) as a subprocess: (API url, dashboard url)."""
    tmp = tmp_path_factory.mktemp("fleet-dashboard")
    (tmp / "fleet.toml").write_text(FLEET_TOML, encoding="utf-8")
    (tmp / "token").write_text(TOKEN + "\n")
    out, log = tmp / "serve.out", tmp / "serve.log"
    # speed 6: the simulation's 60 s rest (the estimator's calibration) passes in 10 s; 2 s blocks
    args = ["--config", str(tmp / "fleet.toml"), "--port", "0", "--speed", "6", "--db", str(tmp / "shm.sqlite"),
            "--token-file", str(tmp / "token")]
    with open(out, "w") as stdout, open(log, "w") as stderr:
        serve = start_serve(args, cwd=tmp, stdout=stdout, stderr=stderr, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            timeout=None, ready_file=tmp / "ready.json")
    proc = serve.process
    try:
        yield wait(lambda: serve_urls(serve, log), 120, "shm serve to say where its API and dashboard are")
    finally:
        stop_process(proc)
    text = log.read_text()
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]


def _scene(page):
    """The left part of the 3-D canvas as an image (the GUI panel on the right left out)."""
    return scene_picture(page)[0]


def _choose(page, structure_id: str) -> None:
    page.locator(".mantine-Flex-root", has=page.get_by_text("Structure", exact=True)).locator("input").filter(
        visible=True).first.click()
    page.get_by_role("option", name=structure_id, exact=True).click()


@pytest.mark.timeout(240)
def test_the_fleets_dashboard_switches_structure_in_chromium(chromium, fleet, tmp_path):
    api_url, dash_url = fleet
    with browser_page(chromium, tmp_path) as page:
        t0 = time.monotonic()
        page.goto(dash_url)
        page.wait_for_selector("canvas", timeout=60_000)
        # The overview: every structure with its state; the first one shown.
        visible(page, "3 structures", exact=False).wait_for(timeout=60_000)
        for sid in IDS:
            row = page.locator("tr", has=page.get_by_text(sid, exact=False)).filter(visible=True).first
            row.wait_for(timeout=30_000)
            assert re.search(r"(starting|running)", row.inner_text()), row.inner_text()
        visible(page, "Structure mast-01").wait_for(timeout=30_000)
        visible(page, "b1 · mode 1 (", exact=False).wait_for(timeout=30_000)  # the clamp: no combimode
        assert page.get_by_text("mode 1+2", exact=False).filter(visible=True).count() == 0
        assert page.get_by_text("b4 · mode", exact=False).filter(visible=True).count() == 0  # Γ = 3
        print(f"first structure shown after {time.monotonic() - t0:.1f} s")
        close_webgl_notice(page)
        time.sleep(0.5)
        offset = support_offset(_scene(page))  # drawn at rest until its first estimates
        assert offset > 0.1, f"the mast should stand above its clamp: support at {offset:+.2f}"

        # Switch: the pendulum's rig, labels, spectra and live estimates (from its worker, through the front).
        _choose(page, "pendulum-02")
        visible(page, "Structure pendulum-02").wait_for(timeout=30_000)
        visible(page, "b1 · mode 1+2", exact=False).wait_for(timeout=30_000)  # the pin's combimode
        visible(page, "b4 · mode 5", exact=False).wait_for(timeout=30_000)  # Γ = 4
        page.get_by_text(re.compile(r"φ = [+-]\d+\.\d+ mrad")).filter(visible=True).first.wait_for(timeout=90_000)
        print(f"the pendulum's live estimates after {time.monotonic() - t0:.1f} s")
        shot_a = _scene(page)
        offset = support_offset(shot_a)
        assert offset < -0.1, f"the pendulum should hang below its pin: support at {offset:+.2f}"
        time.sleep(1.0)
        assert (abs(shot_a - _scene(page)) > 30).any(), "the pendulum does not move"
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        SCREENSHOT.write_bytes(page.screenshot())

        # Only the structures shown were read live: the third kept nothing.
        with httpx.Client(base_url=api_url, timeout=30) as c:
            untouched = c.get("/api/structures/pendulum-03/live").json()
            shown = c.get("/api/structures/pendulum-02/live").json()
        assert untouched["seq"] == 0 and untouched["t_s"] == []
        assert shown["seq"] > 0 and shown["state_names"][:5] == ["d", "h", "d_rate", "h_rate", "phi"]


@pytest.mark.timeout(120)
def test_metrics_of_a_fleet_on_worker_processes(fleet):
    """``/metrics`` of the front: each structure's samples labelled ``structure``, from both workers."""
    api_url, _ = fleet
    with httpx.Client(base_url=api_url, timeout=30) as c:
        wait(lambda: all(s["data_time_s"] for s in c.get("/api/structures").json()["structures"]), 90, "data of all")
        r = c.get("/metrics")
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
        text = r.text
        status = {sid: c.get(f"/api/structures/{sid}/status").json() for sid in IDS}
    families = [line.split()[2] for line in text.splitlines() if line.startswith("# TYPE ")]
    assert len(families) == len(set(families)), "a family is listed twice"
    for sid in IDS:
        assert f'shm_source_messages_total{{structure="{sid}",source="{sid}",kind="sim"}}' in text
        assert f'shm_structure_state{{structure="{sid}",state="running"}} 1' in text
        assert re.search(rf'shm_estimates_total{{structure="{sid}"}} \d', text)
        # a counter read after the exposition is at least what it said
        said = float(re.search(rf'shm_estimates_total{{structure="{sid}"}} (\S+)', text).group(1))
        assert status[sid]["pipeline"]["estimates"] >= said
    assert 'shm_structures{state="running"} 3' in text
    assert 'shm_sensor_degraded{structure="mast-01",topic="/imu/D"}' in text
    # the service's samples once, without a structure
    assert len(re.findall(r"^shm_trend_rows ", text, re.M)) == 1
    assert len(re.findall(r'^shm_notifications_total\{outcome="sent"\} ', text, re.M)) == 1
