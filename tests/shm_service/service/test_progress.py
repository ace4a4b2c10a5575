"""service.progress: the phases' words and their times, from a structure's state. The
real service's progress is checked end to end by tests/web/test_first_run_browser.py; these pin
each phase's text and arithmetic on hand-computable states."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest

from shm_service.service import ServiceSettings
from shm_service.service.runtime._progress import COMPILING, describe_progress

NS = 1_000_000_000


def _structure(*, epoch=None, calibration=None, state="calibrating", span=None, speed=4.0, done=False):
    est = SimpleNamespace(epoch_ns=epoch, calibration=calibration, state=state, buffer_span=span)
    return SimpleNamespace(pipeline=SimpleNamespace(estimator=est), settings=ServiceSettings(), speed=speed, done=done)


def _status(estimates=0, windows=0, processed=None, baseline="learning"):
    return SimpleNamespace(estimates=estimates, windows=windows, processed_data_s=processed, baseline=baseline)


def test_compiling_comes_first():
    text = describe_progress(_structure(), _status(), compiling_since=time.monotonic() - 12.0)
    assert text.startswith(COMPILING) and "12 s so far" in text


def test_waiting_for_data_then_calibrating_with_the_wall_time_left():
    assert describe_progress(_structure(), _status()) == "waiting for data from the source"
    # 60 s of rest calibration (the default), 18 s gathered, at 4x: 42 s of data are 10.5 s of wall time
    text = describe_progress(_structure(epoch=0, span=(0, 18 * NS)), _status())
    assert text == "calibrating at rest: 10 s left"
    text = describe_progress(_structure(epoch=0, span=(0, 18 * NS), speed=None), _status())
    assert text == "calibrating at rest: 42 s of data left"


def test_the_first_window_is_on_the_analysis_grid():
    # rest ends at 60 s, warm-up 120 s: the first window starts at ceil(180 / 30) * 30 = 180 s, ends at 240 s
    s = _structure(epoch=0, calibration=SimpleNamespace(rest_end=60.0), state="running")
    assert describe_progress(s, _status()) == "calibrated; the filter starts"
    text = describe_progress(s, _status(estimates=10, processed=100.0))
    assert text == "estimating; waiting for the first analysis window at t = 240 s (35 s left)"
    # a rest that ends off the grid: 61 s + 120 s -> the window starting at 210 s, ending at 270 s
    s = _structure(epoch=0, calibration=SimpleNamespace(rest_end=61.0), state="running", speed=None)
    assert describe_progress(s, _status(estimates=10, processed=200.0)).endswith("at t = 270 s (70 s of data left)")


def test_learning_the_baseline_then_monitoring_then_finished():
    s = _structure(epoch=0, calibration=SimpleNamespace(rest_end=60.0), state="running")
    # the baseline: 480 s from the first window's start (180 s)
    assert describe_progress(s, _status(estimates=1, windows=1)) == \
        "monitoring; learning the baseline until about t = 660 s (1 window so far)"
    assert describe_progress(s, _status(estimates=1, windows=20, baseline="active")) == "monitoring: 20 windows analysed"
    s.done = True
    assert describe_progress(s, _status(estimates=1, windows=20)) == "finished: 20 windows analysed"


def test_the_kernels_stamp_follows_their_sources(tmp_path, monkeypatch):
    import shm_service.warmup as warmup

    monkeypatch.setattr(warmup, "stamp_path", lambda: tmp_path / "stamp")
    assert not warmup.kernels_ready()
    (tmp_path / "stamp").write_text(warmup._key() + "\n")
    assert warmup.kernels_ready()
    (tmp_path / "stamp").write_text("0" * 64 + "\n")  # compiled from other sources, numba or CPU
    assert not warmup.kernels_ready()


@pytest.mark.parametrize("args", [["--bogus"]])
def test_the_warmup_command_refuses_unknown_arguments(args):
    import shm_service.warmup as warmup

    with pytest.raises(SystemExit) as exc:
        warmup.main(args)
    assert exc.value.code == 2


def test_no_usable_window_is_said_with_its_reasons_while_learning_and_when_finished():
    from shm_service.service.stages._pipeline import _no_usable

    doc = {"usable": 0, "rejected": {"quiet": 3}, "why_none": "no usable window: 3 quiet (b barely moves)", "change": ["quiet: excite it"]}
    why = _no_usable(doc)
    assert why == "no usable window: 3 quiet (b barely moves); change: quiet: excite it"
    # some usable, or only the warm-up skipped so far (the normal start): nothing to say
    assert _no_usable({**doc, "usable": 1}) is None
    assert _no_usable({**doc, "rejected": {"warmup": 2}}) is None
    s = _structure(epoch=0, calibration=SimpleNamespace(rest_end=60.0), state="running")
    status = SimpleNamespace(estimates=1, windows=3, processed_data_s=None, baseline="learning", no_usable_window=why)
    assert describe_progress(s, status) == f"monitoring, but {why}"
    # every window skipped for gaps (the filter restarting): said, not "waiting for the first window"
    status.windows = 0
    assert describe_progress(s, status) == f"monitoring, but {why}"
    s.done = True
    assert describe_progress(s, status) == f"finished: 0 windows analysed; {why}"
