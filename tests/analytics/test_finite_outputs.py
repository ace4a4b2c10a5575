"""Every number the analytics write is finite or null: degenerate signals (constant, one spike, very
short, clipped, random) through the public output paths (spectra and their peaks, shm oma --json,
analyze's JSON document with the hot spots' loads, a whole signal's loads). A degenerate input may
be refused with a ValueError naming it; it never yields NaN or an infinity where a number is
promised."""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analytics import (
    AnalysisConfig, FatigueDetail, HotSpotSpec, LoadsMonitor, amplitude_spectrum, analyze, averaged_spectrum, cross_spectra,
    find_peaks, signal_loads, sn_curve,
)

FS = 20.0
ETA = np.array([0.5, 1.5, 2.5, 3.5])
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])
EXPECTED = ((1.0,), (2.5,), (4.0,))
KINDS = ("constant", "spike", "short", "clipped", "random", "sines", "modal", "modal_clipped", "modal_step")


def _signal(kind: str, seed: int, seconds: float, channels: int = 3) -> np.ndarray:
    """(N, channels) a degenerate signal of ``kind`` (finite, NaN-free)."""
    rng = np.random.default_rng(seed)
    n = 5 + seed % 20 if kind == "short" else int(seconds * FS)
    t = np.arange(n) / FS
    if kind == "constant":
        return np.full((n, channels), 0.01 * (seed % 3))
    if kind == "spike":
        x = np.zeros((n, channels))
        x[seed % n, seed % channels] = 1.0
        return x
    if kind == "sines":
        return 0.01 * np.column_stack([np.sin(2 * np.pi * f * t) for f in (1.0, 2.5, 4.0)[:channels]])
    if kind.startswith("modal"):
        x = _modal(rng, n, channels)
        if kind == "modal_clipped":
            x = np.clip(x, -0.5 * np.std(x), 0.5 * np.std(x))
        elif kind == "modal_step":  # the second half's modes 3 % lower: a change for the charts
            x[n // 2 :] = _modal(rng, n - n // 2, channels, shift=0.97)
        return x
    x = rng.standard_normal((n, channels)) * 0.01
    if kind == "clipped":
        x = np.clip(x * 10, -0.01, 0.01)  # most samples at the rails
    return x


def _modal(rng: np.random.Generator, n: int, channels: int, shift: float = 1.0) -> np.ndarray:
    """(n, channels) white noise through the modes of EXPECTED (ζ = 2 %), mixed onto the channels."""
    from scipy.signal import lfilter

    modes = []
    for f in (g[0] * shift for g in EXPECTED):
        w, z = 2 * np.pi * f / FS, 0.02
        r = np.exp(-z * w)
        modes.append(lfilter([1.0], [1.0, -2 * r * np.cos(w * np.sqrt(1 - z * z)), r * r], rng.standard_normal(n)))
    mix = np.eye(3)[:channels] + 0.2
    return 1e-3 * np.column_stack(modes) @ mix.T


def _numbers(doc: object, path: str = "$"):
    """Every (path, number) of a JSON-like document."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(doc, (list, tuple)):
        for i, v in enumerate(doc):
            yield from _numbers(v, f"{path}[{i}]")
    elif isinstance(doc, (float, int, np.floating, np.integer)) and not isinstance(doc, bool):
        yield path, float(doc)


def _assert_finite(doc: object) -> None:
    bad = [(p, v) for p, v in _numbers(doc) if not math.isfinite(v)]
    assert not bad, f"non-finite numbers: {bad[:5]}"
    json.dumps(doc, allow_nan=False)  # what the JSON writers refuse


signals = dict(kind=st.sampled_from(KINDS), seed=st.integers(0, 2**16))
scales = st.sampled_from([1e-12, 1.0, 1e4])
#: damage signatures at ETA for the flags' location: two candidates of each kind (dimensionless shifts)
SIGNATURES = {"eta": [1.0, 3.0, 2.0, 4.0], "kind": ["stiffness", "stiffness", "mass", "mass"],
              "frequency_shift": [[-0.01, -0.02, -0.005], [-0.002, -0.01, -0.03], [-0.001, -0.004, -0.01], [-0.01, -0.01, -0.01]],
              "curvature_change": np.linspace(-0.05, 0.05, 4 * 3 * 4).reshape(4, 3, 4).tolist(), "length": 4.0}


@settings(max_examples=25, deadline=None, derandomize=True)
@given(**signals)
def test_spectra_and_their_peaks_are_finite(kind, seed):
    x = _signal(kind, seed, 30.0)
    try:
        spec = amplitude_spectrum(x, FS)
        avg = averaged_spectrum(x, FS, segment_s=min(10.0, x.shape[0] / FS))
        cross = cross_spectra(x, FS, [1.0, 2.5])
    except ValueError:
        return  # refused with its reason (too short)
    for s in (spec, avg):
        assert np.all(np.isfinite(s.frequencies)) and np.all(np.isfinite(s.amplitude))
        _assert_finite([s.resolution_hz, s.bin_spacing_hz, s.coherent_gain, s.enbw_bins, s.enbw_hz])
        for p in find_peaks(s, column=0):
            _assert_finite([p.frequency_hz, p.amplitude, p.prominence, p.snr])
    assert np.all(np.isfinite(cross))


@settings(max_examples=20, deadline=None, derandomize=True)
@given(**signals, scale=scales, windowed=st.booleans())
def test_shm_oma_json_is_finite(kind, seed, scale, windowed):
    from shm_service.cli import main

    y = scale * _signal(kind, seed, 60.0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "y.npy"
        np.save(path, y)
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["oma", str(path), "--fs", str(FS), "--fmax", "6", "--json", *(["--window", "20"] if windowed else [])])
    if code != 0:
        assert err.getvalue().strip(), "a refusal says why"
        return
    _assert_finite(json.loads(out.getvalue()))


def _loads() -> LoadsMonitor:
    spots = [HotSpotSpec("weld", 1.0, FatigueDetail(sn_curve("EN1993-1-9:71")), np.array([1.0, 0.5, -0.2]), 0.005)]
    return LoadsMonitor(spots, youngs_modulus=2.1e11, design_life_years=20.0)


@settings(max_examples=20, deadline=None, derandomize=True)
@given(**signals, scale=scales, with_support=st.booleans(), with_temperature=st.booleans())
def test_analyze_json_with_loads_is_finite(kind, seed, scale, with_support, with_temperature):
    b = scale * _signal(kind, seed, 120.0)
    t = np.arange(b.shape[0]) / FS
    config = AnalysisConfig(window_s=20.0, baseline_s=40.0, baseline_min_windows=3)
    kw = {}
    if with_support:
        kw["bearing"] = scale * _signal(kind, seed + 1, 120.0, channels=1)[: b.shape[0], 0]
    if with_temperature:
        kw["temperature"] = (t[:: max(1, t.size // 4)], np.full(t[:: max(1, t.size // 4)].size, 20.0 + seed % 5))
    try:
        res = analyze(t, b, S2, ETA, fs=FS, expected_hz=EXPECTED, config=config, loads=_loads(),
                      signatures=SIGNATURES, **kw)
    except ValueError:
        return  # refused with its reason (shorter than a window)
    _assert_finite(res.as_dict())


@settings(max_examples=25, deadline=None, derandomize=True)
@given(**signals)
def test_a_whole_signals_loads_are_finite(kind, seed):
    x = 1e-4 * _signal(kind, seed, 30.0, channels=1)[:, 0]
    detail = FatigueDetail(sn_curve("EN1993-1-9:71"))
    loads = signal_loads(x, n_eq=1e7, detail=detail, to_stress=2.1e11)
    _assert_finite([loads.rms, loads.range_max, [list(d) for d in loads.dels], loads.damage, loads.cycles.ranges.tolist(),
                    loads.cycles.counts.tolist()])
    edges, _ = loads.cycles_by_range()
    _assert_finite(edges)


def test_the_checker_finds_what_it_looks_for():
    with pytest.raises(AssertionError, match=r"\$\.a\[1\]"):
        _assert_finite({"a": [1.0, float("inf")], "b": None})
    _assert_finite({"a": [1, 2.5, None], "b": "text"})
