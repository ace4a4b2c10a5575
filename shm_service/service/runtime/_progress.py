"""What a structure's monitoring is doing now, in one line an operator reads: in ``/api/status``
(``service.progress``), the dashboard's header and ``shm serve``'s console.

The phases, in order: compiling the filter's kernels (the first run of a fresh install only),
waiting for data, calibrating at rest (the estimator gathers ``estimator.calibration_s`` of data to
learn the sensors' biases and noise), the filter's warm-up until the first analysis window ends,
learning the baseline, monitoring. Times are data seconds since the start of the data (the
simulator's time for ``--source sim``); the wall-clock time left is given where the source keeps a
pace (sim and replay at a speed factor).
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from typing import Any

__all__ = ["COMPILING", "ProgressLog", "compile_first", "describe_progress"]

_NS = 1_000_000_000
log = logging.getLogger("shm.serve")
COMPILING = "compiling the filter — first run only"


def _left(data_s: float, speed: float | None) -> str:
    data_s = max(0.0, data_s)
    if speed is None:
        return f"{data_s:.0f} s of data left"
    return f"{data_s / speed:.0f} s left"


def describe_progress(structure: Any, pipeline_status: Any, compiling_since: float | None = None) -> str:
    """The phase of ``structure`` (a ``runtime._service.Structure``) from its pipeline's state.

    ``pipeline_status`` is its ``PipelineStatusDocument``; ``compiling_since`` the monotonic time
    the kernels' compilation began (None: not compiling).
    """
    if compiling_since is not None:
        return f"{COMPILING} ({time.monotonic() - compiling_since:.0f} s so far; cached for every later run)"
    pipeline = structure.pipeline
    settings = structure.settings
    speed = getattr(structure, "speed", None)
    est = pipeline.estimator
    if structure.done:
        none_usable = getattr(pipeline_status, "no_usable_window", None)
        why = f"; {none_usable}" if none_usable else ""
        return f"finished: {pipeline_status.windows} windows analysed{why}"
    if est.epoch_ns is None:
        return "waiting for data from the source"
    if est.calibration is None:
        if est.state != "calibrating":
            return f"calibrating at rest: {est.state}"
        span = est.buffer_span
        gathered = 0.0 if span is None else (span[1] - span[0]) / _NS
        return f"calibrating at rest: {_left(settings.estimator.calibration_s - gathered, speed)}"
    if pipeline_status.estimates == 0:
        return "calibrated; the filter starts"
    a = settings.engine_config()
    step = a.window_s * (1.0 - a.overlap)
    first_start = math.ceil((float(est.calibration.rest_end) + settings.estimator.warmup_s) / step) * step
    first_end = first_start + a.window_s
    none_usable = getattr(pipeline_status, "no_usable_window", None)  # why no window so far is usable
    if pipeline_status.baseline == "learning" and none_usable:
        return f"monitoring, but {none_usable}"
    if pipeline_status.windows == 0:
        now = 0.0 if pipeline_status.processed_data_s is None else float(pipeline_status.processed_data_s)
        return (f"estimating; waiting for the first analysis window at t = {first_end:.0f} s "
                f"({_left(first_end - now, speed)})")
    if pipeline_status.baseline == "learning":
        return (f"monitoring; learning the baseline until about t = {first_start + a.baseline_s:.0f} s "
                f"({pipeline_status.windows} window{'' if pipeline_status.windows == 1 else 's'} so far)")
    return f"monitoring: {pipeline_status.windows} windows analysed"


def compile_first(service: Any, stop: threading.Event) -> bool:
    """Compile the kernels before ``service`` starts when they are not cached yet (a fresh install
    that skipped ``make``), saying so on the console, in ``/api/status`` and on the dashboard,
    whose port is already open. False when ``stop`` was set meanwhile (the caller stops)."""
    import os

    from ...warmup import CHILD_ENV, Cancelled, compile_kernels, kernels_ready

    if os.environ.get(CHILD_ENV) or kernels_ready():
        return True
    log.info("%s: about a minute on 2 cores, cached for every later run (make does it at install)", COMPILING)
    service.compiling_since = time.monotonic()
    result: dict[str, Any] = {}

    def run() -> None:
        try:
            result["took"] = compile_kernels(cancel=stop)
        except Cancelled:
            pass
        except Exception as exc:  # the service compiles on its first call instead
            result["error"] = exc

    thread = threading.Thread(target=run, name="shm-compile", daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(0.5)
    service.compiling_since = None
    if stop.is_set():
        return False
    if "error" in result:
        log.warning("compiling the kernels ahead failed (the filter compiles on its first call instead): %s", result["error"])
    else:
        log.info("the filter's kernels are compiled and cached (%.0f s)", result.get("took", 0.0))
    return True


class ProgressLog:
    """Logs a structure's progress when its phase changes (the text before its first number)."""

    def __init__(self, service: Any, every_s: float = 1.0) -> None:
        self.service = service
        self.every_s = every_s
        self.last_phase: str | None = None
        self.next_at = 0.0

    def poll(self) -> None:
        now = time.monotonic()
        if now < self.next_at or getattr(self.service, "fleet", False):
            return
        self.next_at = now + self.every_s
        try:
            text = self.service.status().service.progress
        except Exception:  # the console line must never stop the service
            return
        if not text:
            return
        phase = re.split(r"\d", text, maxsplit=1)[0]
        if phase != self.last_phase:
            self.last_phase = phase
            log.info("%s", text)
