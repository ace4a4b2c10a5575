import json

import numpy as np
import pytest

from analytics import (
    AnalysisConfig,
    Baseline,
    EwmaChart,
    ModalMonitor,
    chart_level,
    analyze,
    beam_third,
    curvature_change,
    curvature_field,
    curvature_shape,
    fit_temperature_model,
)

FS = 50.0
ETA = np.linspace(0.5, 4.0, 8)
# curvature shapes of three "unit deformations" (hand-made, smooth, distinct)
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])


def test_curvature_field_is_linear_combination():
    b = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, -1.0]])
    k = curvature_field(b, S2)
    assert k.shape == (2, 8)
    np.testing.assert_allclose(k[1], 2 * S2[:, 1] - S2[:, 2])


def test_curvature_index_points_at_planted_change():
    base = np.array([curvature_shape(np.eye(3)[i] + 0j, i, S2) for i in range(3)])
    changed = base.copy()
    changed[1, 1] *= 1.5  # a local change at η = 1.0 m (station 1) in mode 2's shape
    changed[1] /= np.sqrt(np.mean(changed[1] ** 2))
    ch = curvature_change(changed, base, ETA, 4.0)
    assert ch.eta_m == pytest.approx(1.0)
    assert ch.third == "upper"
    assert curvature_change(base, base, ETA, 4.0).total == 0.0
    # the sign of a shape is irrelevant
    assert curvature_change(-base, base, ETA, 4.0).total == pytest.approx(0.0, abs=1e-12)
    assert [beam_third(e, 4.0) for e in (0.2, 2.0, 3.9)] == ["upper", "middle", "lower"]


def test_control_chart_is_the_ewma_statistic_and_its_level():
    ch = EwmaChart(lam=0.5, warning=3, alarm=5)
    assert [ch.update(0.0)[1] for _ in range(4)] == ["ok"] * 4
    # E = 5, σ = √(0.5/1.5·(1 − 0.5^10)) → the score by hand
    score, level = ch.update(10.0)
    assert score == pytest.approx(5.0 / np.sqrt(1 / 3 * (1 - 0.5**10))) and level == "alarm"
    assert chart_level(4.0, 3, 5) == "warning" and chart_level(-5.0, 3, 5) == "alarm" and chart_level(None, 3, 5) == "ok"
    ch2 = EwmaChart.from_state_dict(json.loads(json.dumps(ch.state_dict())))
    assert ch2.state == ch.state and ch2.sigma() == ch.sigma()


def test_temperature_model_prior_and_fit():
    rng = np.random.default_rng(3)
    T = np.linspace(15, 25, 40)
    rel = -1e-4 * (T - 20) + 1e-5 * rng.standard_normal(T.size)
    a, c, tm, s = fit_temperature_model(rel, T, -7.5e-5, 7.5e-5)
    assert c == pytest.approx(-1e-4, rel=0.05) and tm == pytest.approx(20.0)
    # a flat temperature: the prior decides the slope
    _, c2, _, _ = fit_temperature_model(rel[:3] * 0 + 1e-5 * rng.standard_normal(3), np.full(3, 20.0) + [0, 1e-3, 2e-3], -7.5e-5, 7.5e-5)
    assert c2 == pytest.approx(-7.5e-5, rel=0.2)


def synthetic(duration=1800.0, temp_slope=-1.2e-4, drop_at=None, drop=0.0, seed=0):
    """Three 'units', one mode each, ambient-like narrow-band noise; frequencies follow T."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * FS)) / FS
    T = 20 + 10 * np.sin(2 * np.pi * t / duration)
    f0 = np.array([1.0, 2.5, 4.0])
    b = np.zeros((t.size, 3))
    for i, f in enumerate(f0):
        fi = f * (1 + temp_slope * (T - 20))
        if drop_at is not None:
            fi = fi * np.where(t >= drop_at, 1 - drop, 1.0)
        phase = 2 * np.pi * np.cumsum(fi) / FS
        amp = 1 + 0.2 * np.sin(2 * np.pi * t / (37 + 11 * i) + i)
        b[:, i] = 1e-3 * amp * np.sin(phase) + 1e-5 * rng.standard_normal(t.size)
    return t, b, (t[:: int(FS)], T[:: int(FS)]), ((1.0,), (2.5,), (4.0,))


def test_temperature_only_drift_raises_nothing_and_result_is_json_safe():
    t, b, temp, exp = synthetic()
    res = analyze(t, b, S2, ETA, fs=FS, temperature=temp, expected_hz=exp)
    assert res.flags == ()
    d = res.as_dict()
    text = json.dumps(d, allow_nan=False)
    assert {"modes", "windows", "flags"} <= set(d)
    assert [m["unit"] for m in d["modes"]] == [1, 2, 3]
    assert d["modes"][1]["frequency_hz"] == pytest.approx(2.5, rel=1e-3)
    assert "NaN" not in text
    assert res.baseline is not None
    assert Baseline.from_dict(json.loads(json.dumps(res.baseline.to_dict()))).modes == res.baseline.modes


def test_frequency_drop_flagged_and_monitor_restart():
    t, b, temp, exp = synthetic(drop_at=900.0, drop=0.01)
    res = analyze(t, b, S2, ETA, fs=FS, temperature=temp, expected_hz=exp)
    modes = {f["mode"] for f in res.flags if f["kind"] == "frequency"}
    assert modes == {1, 2, 3}
    for f in res.flags:
        if f["kind"] == "frequency":
            assert 880 <= f["since_s"] <= 1500 and f["percent"] < -0.5 and f["sigma"] < -5
    # incremental form with a restart in the middle gives the same flags
    cfg = AnalysisConfig()
    n, step = int(cfg.window_s * FS), int(cfg.window_s * FS * (1 - cfg.overlap))
    mon = ModalMonitor(exp, S2, ETA, fs=FS)
    raised = []
    for k, s in enumerate(range(0, t.size - n + 1, step)):
        if k == 20:
            mon = ModalMonitor.from_state_dict(json.loads(json.dumps(mon.state_dict())))
        w = mon.process_window(t[s : s + n], b[s : s + n], float(np.interp(t[s], *temp)))
        raised += [f["mode"] for f in w.flags]
        json.dumps(w.as_dict(), allow_nan=False)
    assert {1, 2, 3} <= set(raised)


def test_modes_with_too_few_cycles_per_window_are_tracked_but_not_charted():
    # 60 s windows hold 60 cycles of the 1 Hz mode, 150 and 240 of the others
    t, b, temp, exp = synthetic(drop_at=900.0, drop=0.01)
    res = analyze(t, b, S2, ETA, fs=FS, temperature=temp, expected_hz=exp, config=AnalysisConfig(chart_min_cycles=61.0))
    assert {f["mode"] for f in res.flags if f["kind"] == "frequency"} == {2, 3}
    assert all(w.frequency_scores[0] is None for w in res.windows)
    assert res.modes[0].frequency_hz == pytest.approx(1.0, rel=0.02)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: curvature_field(np.ones((5, 2)), S2), "columns"),
        (lambda: curvature_shape(np.ones(3), 5, S2), "reference=5"),
        (lambda: curvature_change(np.ones((2, 8)), np.ones((2, 7)), ETA, 4.0), "disagree"),
        (lambda: beam_third(1.0, 0.0), "length=0.0"),
        (lambda: EwmaChart(lam=0.2, warning=3, alarm=2), "warning <= alarm"),
        (lambda: fit_temperature_model(np.ones(3), np.ones(4), 0.0, 1.0), "equal length"),
        (lambda: AnalysisConfig(window_s=-1), "window_s"),
        (lambda: AnalysisConfig(bogus=1), "bogus"),
        (lambda: ModalMonitor(((1.0,),), S2, ETA[:5]), "stations_eta"),
        (lambda: ModalMonitor(((1.0,),), S2, ETA).process_window(np.arange(100.0), np.ones((100, 2))), "columns"),
        (lambda: analyze(np.arange(100.0), np.ones((100, 3)), S2, ETA, fs=1.0, config=AnalysisConfig(window_s=500)), "window_s=500"),
        (lambda: analyze(np.arange(100.0), np.ones((100, 3)), S2, ETA, temperature=[1, 2, 3]), "temperature"),
        (lambda: analyze(np.arange(100.0), np.ones((100, 3)), S2, ETA, bearing=np.ones(5)), "bearing"),
        (lambda: analyze(np.arange(100.0)[::-1], np.ones((100, 3)), S2, ETA), "increasing"),
        (lambda: Baseline.from_dict({"modes": []}), "malformed"),
        (lambda: ModalMonitor.from_state_dict({}), "lacks"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()
