"""The first run shows itself: ``shm demo`` as ``make demo`` runs it (the defaults: the
virtual rig at 4× real time, its dashboard on), in headless Chromium from the moment its dashboard's
port opens. The panel's header, its tabs and a status line saying what the service is doing appear
at once, and ``/api/status`` counts estimates within 30 s of the port opening: the rest phase's
60 simulated seconds take 15 s at 4×, and the filter's kernels were compiled at install time
(``make`` runs ``python -m shm_service.warmup``; the test makes sure they are, as ``make`` would).
"""

from __future__ import annotations

import os
import re
import time

import pytest

from browser_helpers import CHROMIUM_ARGS, VIEWPORT, interrupt_group, save_failure, serve_urls, start_demo, visible, wait
#: the issue's bound on this 2-core machine when quiet: live estimates this soon after the dashboard's
#: port opens. Other processes' load stretches every wall-clock time, so the bound is stretched by the
#: machine's load per core when that is above 1 (the test still fails when the kernels compile at the
#: first run: that is asserted on its own, below, without a clock).
FIRST_ESTIMATES_S = 30.0


def _load_factor() -> float:
    return max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))
#: the phrases of service.progress (shm_service/service/runtime/_progress.py) before monitoring starts
PHASES = ("compiling the filter", "waiting for data", "calibrating at rest", "calibrated; the filter starts",
          "waiting for the first analysis window", "learning the baseline")


@pytest.mark.timeout(900)
def test_the_first_demo_shows_its_header_and_counts_estimates_within_30_s(chromium, tmp_path):
    import httpx
    from playwright.sync_api import sync_playwright

    from shm_service.warmup import compile_kernels, kernels_ready

    compile_kernels()  # what make did at install (at once when the stamp is current)
    assert kernels_ready()
    out = tmp_path / "demo.out"
    args = ["--dir", str(tmp_path / "demo"), "--duration", "600", "--no-damage", "--port", "0", "--dashboard-port", "0"]
    with sync_playwright() as p:
        # the browser is up before the service starts: the times below are the service's, not Chromium's start
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport=VIEWPORT)
        demo = start_demo(args, tmp_path, out)
        proc = demo.process
        try:
            api_url, dash_url = wait(lambda: serve_urls(demo, out, "shm demo"), 240,
                                     "shm demo to say where its API and dashboard are", poll=0.05)
            port_open = time.monotonic()
            load = _load_factor()
            with httpx.Client(base_url=api_url, timeout=10) as api:
                page.goto(dash_url)
                # the panel: its header (the label and the live badge), its tabs, and what the service does now
                visible(page, "IMMS structural health monitor").wait_for(timeout=30_000)
                visible(page, "LIVE", exact=False).wait_for(timeout=30_000)
                for tab in ("Spectra", "Trends", "Alarms", "Status"):
                    visible(page, tab, exact=True).wait_for(timeout=30_000)
                header_s = time.monotonic() - port_open
                phase = page.get_by_text(re.compile("|".join(re.escape(x) for x in PHASES))).filter(visible=True).first
                phase.wait_for(timeout=30_000)

                def estimating():
                    st = api.get("/api/status").json()
                    return st if st["pipeline"]["estimates"] > 0 else None

                st = wait(estimating, 120, "/api/status to count estimates", poll=0.25)
                first_estimates_s = time.monotonic() - port_open
                print(f"header after {header_s:.1f} s, first estimates after {first_estimates_s:.1f} s "
                      f"of the dashboard's port opening (load per core {load:.2f}); progress: {st['service']['progress']!r}")
                assert st["service"]["progress"] and not st["service"]["progress"].startswith("compiling"), st["service"]
                assert first_estimates_s <= FIRST_ESTIMATES_S * load, (
                    f"the first estimates came {first_estimates_s:.1f} s after the dashboard's port opened "
                    f"(bound {FIRST_ESTIMATES_S:g} s × the load per core {load:.2f})")
                # the page follows: the header shows the live state (t = …) once estimates flow
                visible(page, "t = ", exact=False).wait_for(timeout=30_000)
        except BaseException:
            save_failure(page, tmp_path)
            raise
        finally:
            browser.close()
            interrupt_group(proc)  # Ctrl-C
    text = out.read_text()
    assert proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text, text[-3000:]
    # nothing compiled at this first run: make's warm-up cached the kernels
    assert "compiling the filter" not in text, text[-3000:]
    # the console says the same as the page: each phase once, as it begins
    assert re.search(r"shm\.serve: calibrating at rest: \d+ s left", text), text[-3000:]
    assert re.search(r"shm\.serve: estimating; waiting for the first analysis window at t = \d+ s", text), text[-3000:]
