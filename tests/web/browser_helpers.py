"""What the browser tests share: Debian's chromium and its arguments, waiting for page texts, the
picture of the beam, starting and ending ``shm serve`` / ``shm demo`` and reading their addresses."""

from __future__ import annotations

import contextlib
import functools
import io
import os
import signal
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from shm_service.service import ServeProcess, read_ready

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORT = {"width": 1600, "height": 1000}
ROOT = Path(__file__).resolve().parents[2]


def visible(page: Any, text: Any, **kwargs: Any) -> Any:
    """The first visible element with ``text`` (notifications and tabs keep hidden copies)."""
    return page.get_by_text(text, **kwargs).filter(visible=True).first


def wait(predicate: Callable[[], Any], timeout: float, what: str, poll: float = 0.25) -> Any:
    """The first truthy value of ``predicate`` within ``timeout`` s (AssertionError naming ``what``):
    the service tests' ``wait_for``."""
    return service_test_helpers().wait_for(predicate, timeout, what, poll)


def image(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def close_webgl_notice(page: Any) -> None:
    """The browser's own notice about software WebGL only hides the picture."""
    try:
        page.locator(".mantine-Notification-root", has_text="Software WebGL").locator("button").first.click(timeout=2_000)
    except Exception:
        pass


def scene_picture(page: Any) -> tuple[np.ndarray, int]:
    """(the picture of the 3-D canvas left of the panel, the canvas height in pixels)."""
    box = page.evaluate(
        "() => { const c = [...document.querySelectorAll('canvas')]"
        ".sort((a, b) => b.width * b.height - a.width * a.height)[0];"
        " const r = c.getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }"
    )
    x0, y0, w, h = (int(round(v)) for v in box)
    return image(page.screenshot(clip={"x": x0, "y": y0, "width": int(0.62 * w), "height": h})), h


def assert_tall_beam(scene: np.ndarray, height: int) -> None:
    """The beam: blue pixels in a tall vertical strip of the scene."""
    r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
    blue = (b > 120) & (b - r > 70) & (b - g > 30)
    rows = np.flatnonzero(blue.any(axis=1))
    assert blue.sum() > 400, f"beam not drawn: {blue.sum()} blue pixels"
    assert rows[-1] - rows[0] > 0.3 * height, "the beam should be a tall vertical ribbon"


def assert_chart_drawn(page: Any, title: str | None = None) -> None:
    """The first uPlot canvas (or that of the chart whose title starts with ``title``) is visible,
    large enough and not blank.

    viser re-creates a uPlot canvas when its data changes, so an element screenshot can race a live
    update ("not attached"); a page screenshot clipped to where the canvas is cannot."""
    box = page.evaluate(
        "(title) => { const plots = [...document.querySelectorAll('.uplot')].filter(p => title === null ||"
        " (p.querySelector('.u-title') || {}).textContent?.startsWith(title));"
        " const r = plots[0].querySelector('canvas').getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }",
        title,
    )
    assert box[2] > 50 and box[3] > 50, f"chart canvas too small: {box}"
    chart = image(page.screenshot(clip=dict(zip(("x", "y", "width", "height"), box))))
    assert (np.abs(chart - 255).sum(axis=-1) > 60).sum() > 300, "the chart canvas is blank"


def support_offset(scene: np.ndarray) -> float:
    """Where the support is drawn against the beam, as a share of the picture's height: the median
    row of the dark grey pixels (the bearing or clamp and its rail) minus the median row of the
    beam's blue ones. Negative: above the beam (it hangs); positive: below it (it stands)."""
    r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
    blue = (b > 120) & (b - r > 70) & (b - g > 30)
    dark = (scene.max(axis=-1) < 110) & (np.ptp(scene, axis=-1) < 30)
    assert blue.sum() > 400 and dark.sum() > 200, (blue.sum(), dark.sum())
    return float(np.median(np.nonzero(dark)[0]) - np.median(np.nonzero(blue)[0])) / scene.shape[0]


@contextlib.contextmanager
def browser_page(chromium: str, tmp_path: Path) -> Iterator[Any]:
    """A page of a fresh headless Chromium (its own profile in ``tmp_path``); a screenshot of it
    is left in ``tmp_path/failure.png`` when the block fails."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"), executable_path=chromium, headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
        )
        page = context.pages[0] if context.pages else context.new_page()
        try:
            yield page
        except BaseException:
            save_failure(page, tmp_path)
            raise
        finally:
            context.close()


def save_failure(page: Any, tmp_path: Path) -> None:
    """A screenshot of ``page`` in ``tmp_path/failure.png`` (said in the test's output)."""
    page.screenshot(path=str(tmp_path / "failure.png"))
    print("failure screenshot:", tmp_path / "failure.png")


def serve_urls(serve: ServeProcess, log: Path, what: str = "shm serve") -> tuple[str, str] | None:
    """The API and dashboard addresses of ``serve``'s ready document (None: not yet); its log's tail
    when it ended before it was ready."""
    if serve.process.poll() is not None:
        raise AssertionError(f"{what} ended early ({serve.process.returncode}): {log.read_text()[-3000:]}")
    doc = read_ready(serve.ready_file)
    return (doc["api"], doc["dashboard"]) if doc and doc.get("dashboard") else None


def stop_process(proc: subprocess.Popen) -> None:
    """SIGTERM (``shm serve`` drains and prints its summary), then kill after a minute."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def interrupt_group(proc: subprocess.Popen) -> None:
    """Ctrl-C to the process group of ``proc`` (started with ``start_new_session``), then kill after 90 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(90)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)


@functools.cache
def service_test_helpers() -> Any:
    """The service tests' fast analytics settings (small windows, sensitive charts)."""
    import importlib.util

    path = ROOT / "tests" / "shm_service" / "service" / "svc_helpers.py"
    spec = importlib.util.spec_from_file_location("svc_helpers_for_web", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def start_demo(args: list[str], tmp_path: Path, out: Path) -> ServeProcess:
    """``shm demo ARGS`` in ``tmp_path`` (its output in ``out``), in a process group of its own (Ctrl-C
    in a terminal goes to the whole foreground group: ``interrupt_group`` sends it so)."""
    from shm_service.service import start_serve

    with open(out, "w") as stdout:
        return start_serve(args, command="demo", cwd=tmp_path, stdout=stdout, stderr=subprocess.STDOUT,
                           start_new_session=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=None,
                           ready_file=tmp_path / "ready.json")
