"""Why no analysis window is usable: each window's rejection reason counted, the reason said and
what to change, through analyze's JSON document."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import WINDOW_REJECTIONS, AnalysisConfig, ModeEstimate, analyze, usability_document, window_rejection

FS = 20.0
S2 = np.array([[1.0, 0.5], [0.5, -1.0], [0.2, 0.3]])  # (stations, Γ) curvature shapes, 1/m²
ETA = np.array([0.5, 1.5, 2.5])
EXPECTED = ((1.0,), (3.0,))


def test_the_document_counts_each_reason_and_says_why_by_count():
    d = usability_document(0, {"quiet": 2, "forced": 5, "warmup": 0})
    assert d["usable"] == 0 and d["rejected"] == {"quiet": 2, "forced": 5}
    assert d["why_none"] == (f"no usable window: 5 forced ({WINDOW_REJECTIONS['forced'][0]}); "
                             f"2 quiet ({WINDOW_REJECTIONS['quiet'][0]})")
    assert d["change"] == [f"forced: {WINDOW_REJECTIONS['forced'][1]}", f"quiet: {WINDOW_REJECTIONS['quiet'][1]}"]
    # a usable window: counts, no verdict
    assert usability_document(1, {"quiet": 2}) == {"usable": 1, "rejected": {"quiet": 2}, "why_none": None, "change": []}
    # nothing at all: the record holds no complete window
    assert "no complete analysis window" in usability_document(0, {})["why_none"]


@pytest.mark.parametrize("call, message", [
    (lambda: usability_document(-1, {}), "usable=-1"),
    (lambda: usability_document(0, {"late": 1}), "'late'"),
    (lambda: usability_document(0, {"quiet": 1.5}), "rejected['quiet']=1.5"),
    (lambda: window_rejection(object(), None), "config must be an AnalysisConfig"),
])
def test_bad_inputs_are_named(call, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        call()


def test_a_trusted_window_without_a_confident_mode_is_not_usable():
    cfg = AnalysisConfig()

    class Window:
        kind, trusted = "ambient", True
        estimates = (ModeEstimate(1, 1, 1.0, 1.0, cfg.min_confidence - 0.01, method="ssi"),
                     ModeEstimate(2, 2, 3.0, 1.0, 0.9, method="spectrum"))

    assert window_rejection(Window(), cfg) == "no_mode_identified"
    Window.estimates = Window.estimates + (ModeEstimate(2, 2, 3.0, 1.0, cfg.min_confidence, method="ssi"),)
    assert window_rejection(Window(), cfg) is None


def test_a_record_that_does_not_move_has_no_usable_window_and_says_so():
    t = np.arange(int(300 * FS)) / FS
    res = analyze(t, np.zeros((t.size, 2)), S2, ETA, fs=FS, expected_hz=EXPECTED)
    # 300 s, 60 s windows every 30 s: 9 windows, every one quiet
    doc = res.as_dict()["usability"]
    assert doc["usable"] == 0 and doc["rejected"] == {"quiet": 9}
    assert doc["why_none"].startswith("no usable window: 9 quiet") and doc["change"][0].startswith("quiet: ")


def test_a_support_shaken_at_a_mode_gives_forced_windows_and_the_warm_up_is_counted():
    t = np.arange(int(300 * FS)) / FS
    rng = np.random.default_rng(7)
    drive = np.sin(2 * np.pi * 1.0 * t)
    b = np.column_stack([1e-3 * drive, 1e-4 * np.sin(2 * np.pi * 3.0 * t)]) + 1e-7 * rng.standard_normal((t.size, 2))
    res = analyze(t, b, S2, ETA, fs=FS, expected_hz=EXPECTED, bearing=1e-3 * drive, not_before_s=60.0)
    doc = res.as_dict()["usability"]
    # the windows starting at 0 and 30 s are the warm-up; the other 7 are the forced response
    assert doc["usable"] == 0 and doc["rejected"] == {"warmup": 2, "forced": 7}
    assert doc["why_none"].startswith("no usable window: 7 forced")
