"""The one engine: windows aligned in data time whatever the chunking, the support motion as an
input (distrusted only when deterministic at a mode), the baseline from a whole healthy record."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from analytics import AnalysisConfig, BaselineError, ModalMonitor, MonitoringEngine, analyze, learn_baseline

FS = 50.0
ETA = np.linspace(0.5, 4.0, 8)
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])
MODES = (1.0, 2.5, 4.0)
EXPECTED = ((1.0,), (2.5,), (4.0,))
ORIGIN_NS = 1_767_225_600_123_456_789  # a recording's first sample, not on a whole second


def record(seconds: float = 900.0, seed: int = 0, drop_at: float | None = None, drop: float = 0.0, sine: tuple | None = None,
           temperature_slope: float = 0.0):
    """b (N, 3) of three lightly damped modes (ζ = 1 %), each excited by broadband noise and by a
    support motion d(t) with a broadband acceleration; ``sine=(hz, m/s², t0, t1)`` adds a steady line to the
    support's acceleration; the modes may follow a temperature ramp and drop by ``drop`` from ``drop_at``."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    # the support's acceleration broadband (flat over 0.2–20 Hz), its displacement the double integral
    acc = signal.sosfilt(signal.butter(4, [0.2, 20.0], "bandpass", fs=FS, output="sos"), rng.standard_normal(n)) * 0.05
    fr = np.fft.rfftfreq(n, 1 / FS)
    d = np.fft.irfft(np.fft.rfft(acc) * np.where(fr > 0, -1.0 / (2 * np.pi * np.maximum(fr, 1e-9)) ** 2, 0.0), n)
    if sine is not None:
        f, amp, t0, t1 = sine
        on = (t >= t0) & (t < t1)
        acc = acc + np.where(on, amp * np.sin(2 * np.pi * f * t), 0.0)
        d = d + np.where(on, -amp / (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t), 0.0)
    T = 20 + 10 * np.sin(2 * np.pi * t / seconds)
    b = 1e-6 * rng.standard_normal((n, 3))
    h = 1 / FS
    for i, f0 in enumerate(MODES):
        f = f0 * (1 + temperature_slope * (T - 20)) * (np.where(t >= drop_at, 1 - drop, 1.0) if drop_at is not None else 1.0)
        w, z = 2 * np.pi * f, 0.01
        # exact zero-order-hold step of x'' + 2ζω x' + ω² x = force, its ω held per sample
        wd, sg = w * np.sqrt(1 - z**2), z * w
        ex, c, sn = np.exp(-sg * h), np.cos(wd * h), np.sin(wd * h)
        a00, a01 = ex * (c + sg / wd * sn), ex * sn / wd
        a10, a11 = -ex * w**2 / wd * sn, ex * (c - sg / wd * sn)
        b0 = (1 - a11 - 2 * z * w * a01) / w**2
        force = (0.3 * rng.standard_normal(n) - 0.5 * acc).tolist()
        x = v = 0.0
        out = []
        for _k, (p00, p01, p10, p11, q0, q1, fk) in enumerate(zip(a00.tolist(), a01.tolist(), a10.tolist(), a11.tolist(), b0.tolist(),
                                                                 a01.tolist(), force)):
            out.append(x)
            x, v = p00 * x + p01 * v + q0 * fk, p10 * x + p11 * v + q1 * fk
        b[:, i] += 1e-2 * np.asarray(out)
    return t, b, d, (t[:: int(FS)], T[:: int(FS)])


@pytest.fixture(scope="module")
def operational():
    return record(seconds=600.0, seed=1)


def test_windows_are_the_same_whatever_the_chunking_and_aligned_in_data_time(operational):
    t, b, d, temp = operational
    whole = analyze(t, b, S2, ETA, fs=FS, bearing=d, temperature=temp, expected_hz=EXPECTED, time_origin_ns=ORIGIN_NS)
    assert len(whole.windows) >= 17
    step = AnalysisConfig().window_s * (1 - AnalysisConfig().overlap)
    for w in whole.windows:  # aligned to multiples of the step in data time, reported from the first sample
        k = (ORIGIN_NS / 1e9 + w.start_s) / step
        assert abs(k - round(k)) < 1e-6
    mon = ModalMonitor(EXPECTED, S2, ETA, fs=FS)
    engine = MonitoringEngine(mon, origin_ns=ORIGIN_NS, time_zero_ns=ORIGIN_NS)
    rng = np.random.default_rng(3)
    got, lo = [], 0
    while lo < t.size:
        hi = min(t.size, lo + int(rng.integers(1, 4000)))
        tt = temp[0][(temp[0] >= t[lo]) & (temp[0] <= t[hi - 1])]
        tv = temp[1][(temp[0] >= t[lo]) & (temp[0] <= t[hi - 1])]
        got += engine.add(t[lo:hi], b[lo:hi], support=d[lo:hi], temperature=(tt, tv) if tt.size else None)
        lo = hi
    assert [g.result.start_s for g in got] == [w.start_s for w in whole.windows]
    for g, w in zip(got, whole.windows):
        assert [e.frequency_hz for e in g.result.estimates] == [e.frequency_hz for e in w.estimates]  # identical, not close
        assert [e.track for e in g.result.estimates] == [e.track for e in w.estimates]  # one tracker, the same ids
        assert g.result.levels == w.levels and g.result.flags == w.flags and g.result.temperature_c == w.temperature_c


def test_a_randomly_moving_support_is_an_input_and_the_modes_come_out(operational):
    t, b, d, temp = operational
    res = analyze(t, b, S2, ETA, fs=FS, bearing=d, temperature=temp, expected_hz=EXPECTED)
    assert all(w.trusted and w.kind == "ambient" for w in res.windows)
    assert all(w.excitation is not None and w.excitation.kind != "deterministic_near_mode" for w in res.windows)
    for m, f in zip(res.modes, MODES):
        # the record-long subspace pole, or the windows' subspace mean where they state the smaller 1σ
        assert m.method in ("ssi", "ssi_windows") and m.frequency_hz == pytest.approx(f, rel=2e-3)
        assert {"ssi", "random_decrement"} <= {e.method for e in m.damping}
        assert m.damping_ratio == pytest.approx(0.01, rel=0.3) and m.damping_std > 0
    window = res.windows[5].estimates[1]
    assert window.method == "ssi" and window.confirmed and window.frequency_std_hz > 0 and 0.9 < window.mpc <= 1.0
    assert res.flags == () and len(res.modes) == 3
    # each eigenmode is one track through the record (the engine's tracker, as shm oma's), listed with its range
    doc = res.as_dict()
    for k, f in enumerate(MODES):
        ids = {w.estimates[k].track for w in res.windows if w.estimates[k].method == "ssi"}
        assert len(ids) == 1 and None not in ids, ids
        (track,) = [tr for tr in doc["tracks"] if tr["track"] in ids]
        assert track["min_hz"] <= f * 1.01 and track["max_hz"] >= f * 0.99
    assert all(m["track"] is not None for w in doc["windows"] for m in w["identified_modes"])


def test_a_sine_at_a_mode_in_the_support_motion_distrusts_only_its_windows():
    t, b, d, temp = record(seconds=600.0, seed=2, sine=(2.5, 0.2, 300.0, 600.0))
    res = analyze(t, b, S2, ETA, fs=FS, bearing=d, expected_hz=EXPECTED)
    before = [w for w in res.windows if w.end_s <= 300.0]
    during = [w for w in res.windows if w.start_s >= 300.0]
    assert before and during
    assert all(w.kind == "ambient" for w in before)
    assert all(w.kind == "forced" and not w.trusted for w in during)
    assert all(w.excitation.kind == "deterministic_near_mode" and w.excitation.nearest_mode_hz == pytest.approx(2.5, rel=0.01)
               for w in during)


#: the model's temperature sensitivity of each mode (as ``estimator.damage_signatures`` gives it) and
#: three hand-made candidates for the location
SIGNATURES = {"eta": np.array([0.5, 2.0, 3.5]), "kind": ("stiffness", "stiffness", "mass"),
              "frequency_shift": np.array([[-1e-3, -2e-3, 0.0], [0.0, -1e-3, -3e-3], [-2e-3, -1e-3, -1e-3]]),
              "temperature_slope": np.full(3, -1.5e-4), "length": 4.0}


@pytest.fixture(scope="module")
def swing_baseline():
    t, b, d, temp = record(seconds=1200.0, seed=4, temperature_slope=-1.5e-4)
    return learn_baseline(t, b, S2, ETA, fs=FS, bearing=d, temperature=temp, expected_hz=EXPECTED, signatures=SIGNATURES)


def test_a_baseline_from_a_whole_record_with_a_temperature_swing(swing_baseline):
    bl = swing_baseline
    assert bl.trusted_windows >= 35 and all(m.windows >= 30 for m in bl.modes)
    for m, f in zip(bl.modes, MODES):
        # the frequency at the reference temperature to a per-window scatter over √windows, the slope near the model's
        assert m.f_ref_hz * (1 + m.slope_per_k * (20.0 - m.temperature_ref_c)) == pytest.approx(f, rel=3e-3)
        assert m.slope_per_k == pytest.approx(-1.5e-4, abs=0.6e-4)
        assert len(m.shape) == 3 and abs(m.shape[m.unit]) > 0.9
    assert bl.problems(AnalysisConfig()) == {}
    # a second record of the same structure (another realisation, the swing too) raises nothing …
    t, b, d, temp = record(seconds=700.0, seed=5, temperature_slope=-1.5e-4)
    kw = dict(fs=FS, bearing=d, expected_hz=EXPECTED, baseline=bl, signatures=SIGNATURES)
    assert analyze(t, b, S2, ETA, temperature=temp, **kw).flags == ()
    # … a 2 % drop from 300 s is flagged within the next 10 minutes, and not before it
    t, b, d, temp = record(seconds=700.0, seed=6, temperature_slope=-1.5e-4, drop_at=300.0, drop=0.02)
    res = analyze(t, b, S2, ETA, temperature=temp, **dict(kw, bearing=d))
    first = next(w for w in res.windows if w.flags)
    assert 300.0 < first.end_s <= 900.0 and all(f["since_s"] > 300.0 for f in res.flags)
    assert {f["mode"] for f in res.flags if f["kind"] == "frequency"} >= {2, 3}
    assert json.dumps(res.as_dict(), allow_nan=False)


def test_when_no_baseline_can_be_learnt_the_error_names_the_modes_and_what_they_lacked():
    t, b, d, _ = record(seconds=150.0, seed=7)
    slow = ((0.4,), (2.5,), (4.0,))  # 24 cycles of mode 1 in a 60 s window
    with pytest.raises(BaselineError, match=r"mode 1: .*windows with a subspace estimate.*minutes of trusted data.*8 needed; "
                                            r"24 cycles per 60 s window, 30 needed to chart it; mode 2: .*8 needed"):
        learn_baseline(t, b, S2, ETA, fs=FS, bearing=d, expected_hz=slow)
    # … and the least a record must hold: 8 windows of 60 s every 30 s = 60 + 7 · 30 s
    with pytest.raises(BaselineError, match=r"a baseline needs at least 8 trusted windows .*: 270 s of ambient data"):
        learn_baseline(t, b, S2, ETA, fs=FS, bearing=d, expected_hz=slow)
    with pytest.raises(BaselineError, match=r"no baseline can be learnt: 0 windows .*; a baseline needs at least 3 trusted "
                                            r"windows .*: 40 s of ambient data"):
        learn_baseline(t, b, S2, ETA, fs=FS, bearing=d, expected_hz=EXPECTED,
                       config=AnalysisConfig(window_s=20.0, baseline_min_windows=3), not_before_s=149.0)


@pytest.mark.parametrize("call, match", [
    (lambda: MonitoringEngine("monitor"), "ModalMonitor"),
    (lambda: MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS), min_coverage=0.0), "min_coverage"),
    (lambda: MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS)).add([0.0, 0.0], np.zeros((2, 3))), "increasing"),
    (lambda: MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS)).add([0.0, 1.0], np.zeros((3, 3))), "b has 3"),
    (lambda: MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS)).add([0.0], np.zeros((1, 3)), support=[0.0, 1.0]), "support"),
    (lambda: analyze(np.arange(100.0), np.ones((100, 3)), S2, ETA, fs=1.0, time_origin_ns=1.5), "time_origin_ns"),
    (lambda: ModalMonitor(EXPECTED, S2, ETA, learn="always"), "learn='always'"),
])
def test_bad_input_names_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_a_gap_of_years_is_skipped_in_one_step_with_the_same_windows_and_counts(operational, monkeypatch):
    """A clock that jumped decades ahead (a wall-clock stamp in a 1970 backfill) costs
    one step, not one per window of the years between; a gap of minutes gives the same windows
    and counts as the window-by-window loop."""
    import time

    t, b, d, _ = operational
    half = t.size // 2

    def run(gap_s: float, skip: bool, not_before_s: float = 100.0):
        engine = MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS), origin_ns=ORIGIN_NS, time_zero_ns=ORIGIN_NS,
                                  not_before_ns=ORIGIN_NS + int(not_before_s * 1e9))
        if not skip:
            monkeypatch.setattr(engine, "_skip_gap", lambda *a: False)
        got = engine.add(t[:half], b[:half], support=d[:half])
        got += engine.add(t[half:] + gap_s, b[half:], support=d[half:])
        return [g.result.start_s for g in got], engine.windows, engine.skipped_incomplete, engine.skipped_warmup

    assert run(1234.5, True) == run(1234.5, False)
    assert run(1234.5, True, not_before_s=900.0) == run(1234.5, False, not_before_s=900.0)
    began = time.process_time()
    starts, windows, incomplete, warmup = run(56 * 365.25 * 86400.0, True)
    assert time.process_time() - began < 60.0  # the loop would take hours
    assert windows == len(starts) >= 10 and incomplete > 56 * 365 * 86400 / 30 - 10
