"""The dashboard of a beam that bends in two planes, in headless Chromium against the real
``shm serve``: a biaxial steel tube mast (clamped, standing) on the virtual rig, the wind veering
so it sways in ζ and ξ. The Orbit tab draws the tip's ζ deflection against its ξ deflection; the
Loads tab says where around the section each hot spot sits (a weld at 45°, a girth weld all
around, at the worst point the service found); ``/api/structures/{id}/live`` carries each
station's angle and the root moment per plane with its resultant."""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from browser_helpers import ROOT, assert_chart_drawn, browser_page, close_webgl_notice, serve_urls, stop_process, visible, wait

from shm_service.service import start_serve

# A picture of the Orbit tab for the docs: SHM_ORBIT_SCREENSHOT=docs/orbit-tab.png (else a temporary file).
SCREENSHOT = Path(os.environ.get("SHM_ORBIT_SCREENSHOT", Path(tempfile.gettempdir()) / "shm-orbit-tab.png"))
LENGTH, HALF = 3.0, 1.5
TUBE = {"shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}
RIG = {
    "beam": {"length": LENGTH, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": "biaxial",
             "sections": [{"position": 0.0, **TUBE}, {"position": LENGTH, **TUBE}]},
    "gravity": 9.81, "support": "clamped", "orientation": "standing",
    "sensors": [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "m", "kind": "imu", "position": HALF},
                {"name": "tip", "kind": "imu", "position": LENGTH},
                {"name": "g0", "kind": "strain", "position": 1.0}, {"name": "g90", "kind": "strain", "position": 1.0, "angle_deg": 90},
                {"name": "h0", "kind": "strain", "position": 2.0}, {"name": "h90", "kind": "strain", "position": 2.0, "angle_deg": 90}],
    "truth_stations": [HALF, LENGTH],
    "hot_spots": [{"name": "weld45", "position": 1.0, "curve": "EN1993-1-9:71", "angle_deg": 45},
                  {"name": "girth", "position": 0.5, "curve": "EN1993-1-9:71", "angle_deg": "all"}],
}


def _config(tmp):
    return {
        "data_dir": str(tmp / "var"),
        "source": {"spec": "sim", "speed": "4", "keep_running": True, "rig": str(tmp / "rig.json")},
        "sim": {"rig": str(tmp / "rig.json"), "excitation": "ambient", "duration_s": 900.0, "damage": []},
        "estimator": {"peripheral": "gyro", "modes": 2, "imus": 2, "tofs": 0, "gauges": 4, "calibration_s": 20.0, "warmup_s": 5.0},
        "analytics": {"window_s": 30.0, "baseline_s": 120.0},
        "archive": {"enabled": False},
        "dashboard": {"enabled": True, "port": 0},
        "server": {"port": 0},
    }


@pytest.mark.timeout(600)
def test_the_orbit_and_the_hot_spots_angles_of_a_biaxial_mast(chromium, tmp_path):
    import httpx
    import tomli_w

    (tmp_path / "rig.json").write_text(json.dumps(RIG))
    (tmp_path / "serve.toml").write_text(tomli_w.dumps(_config(tmp_path)))
    out, log = tmp_path / "serve.out", tmp_path / "serve.log"
    with open(out, "w") as stdout, open(log, "w") as stderr:
        serve = start_serve(["--config", str(tmp_path / "serve.toml")], cwd=tmp_path, stdout=stdout, stderr=stderr,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=None, ready_file=tmp_path / "ready.json")
    try:
        api_url, dash_url = wait(lambda: serve_urls(serve, log), 240, "shm serve to say where its API and dashboard are")
        with httpx.Client(base_url=api_url, timeout=10) as api:
            (summary,) = wait(lambda: api.get("/api/structures").json()["structures"], 60, "the structure")
            sid = summary["id"]
            with browser_page(chromium, tmp_path) as page:
                page.goto(dash_url)
                page.wait_for_selector("canvas", timeout=60_000)
                visible(page, "Pause live view").wait_for(timeout=60_000)
                close_webgl_notice(page)
                page.get_by_text("Orbit", exact=True).first.click()
                visible(page, "Tip orbit: Δζ (mm) against Δξ (mm)", exact=False).wait_for(timeout=60_000)

                def live():  # the estimates the dashboard reads, once the filter runs
                    doc = api.get(f"/api/structures/{sid}/live").json()
                    return doc if len(doc["x"]) >= 20 and doc["loads_angles_deg"] else None

                doc = wait(live, 240, "live estimates with their loads")
                assert doc["loads_station_names"][:2] == ["weld45", "girth"]
                assert doc["loads_worst_around"][:2] == [False, True] and doc["loads_angles_deg"][0] == 45.0
                root = np.array(doc["root_moment_resultant_nm"])
                np.testing.assert_allclose(root, np.hypot(doc["root_moment_nm"], doc["root_moment_xi_nm"]), rtol=1e-12)
                assert np.abs(doc["root_moment_xi_nm"]).max() > 0.0  # the veering wind bends it in ξ too
                time.sleep(3.0)  # the orbit's points: a few redraws
                assert_chart_drawn(page, "Tip orbit")
                SCREENSHOT.write_bytes(page.screenshot())
                page.get_by_text("Loads", exact=True).first.click()
                visible(page, "at 45°", exact=False).wait_for(timeout=30_000)
                worst = page.get_by_text("all around the section: worst at ", exact=False).first
                worst.wait_for(timeout=30_000)
                wait(lambda: "…" not in worst.inner_text(), 60, "the girth weld's worst angle")
                angle = float(worst.inner_text().split("worst at ")[1].split("°")[0])
                assert 0.0 <= angle < 360.0
                print({"girth worst angle": angle, "root resultant max N·m": float(root.max())})
    finally:
        stop_process(serve.process)
    text = log.read_text()
    assert serve.process.returncode == 0, text[-3000:]
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]
