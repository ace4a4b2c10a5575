"""Model-assisted damage location, the calibrated curvature chart (mode-shape curvature), damping paths of analyze()."""

import json

import numpy as np
import pytest
from scipy import signal

from analytics import AnalysisConfig, DamageLocation, analyze, locate_damage, mode_shape_curvature
from contract import CURVATURE_CHART

FS = 50.0
ETA = np.linspace(0.5, 4.0, 8)
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])

# three hand-made candidates along a 4 m beam: frequency-shift patterns of 3 modes (relative)
SIG = {
    "eta": np.array([0.5, 2.0, 3.5]),
    "kind": ("stiffness", "stiffness", "mass"),
    "frequency_shift": np.array([[-1e-3, -2e-3, 0.0], [0.0, -1e-3, -3e-3], [-2e-3, -1e-3, -1e-3]]),
    "length": 4.0,
}


def test_locate_damage_dlac_by_hand():
    # observed = 2 × candidate 1 exactly: match 1, severity 2, middle third
    loc = locate_damage(2 * SIG["frequency_shift"][1], np.full(3, 1e-4), SIG)
    assert isinstance(loc, DamageLocation)
    assert loc.eta_m == 2.0 and loc.third == "middle" and loc.kind_best == "stiffness"
    assert loc.best_match == pytest.approx(1.0) and loc.severity == pytest.approx(2.0)
    # DLAC of candidate 0 by hand: (y·s)² / (|y|²|s|²)
    y, s0 = SIG["frequency_shift"][1], SIG["frequency_shift"][0]
    assert loc.match[0] == pytest.approx((y @ s0) ** 2 / ((y @ y) * (s0 @ s0)))
    # a rise of every frequency matches no loss: all matches 0 (the sign is kept)
    assert np.all(locate_damage(-y, np.full(3, 1e-4), SIG).match == 0.0)
    # an unusable mode (std inf) is left out: only modes 1 and 3 count
    loc2 = locate_damage(np.array([-2e-3, 5e-3, -1e-3]), np.array([1e-4, np.inf, 1e-4]), SIG)
    assert loc2.eta_m == 3.5 and loc2.kind_best == "mass" and loc2.third == "lower"
    assert loc2.profile_eta.tolist() == [0.5, 2.0, 3.5] and json.dumps(loc2.as_dict())


def test_locate_damage_with_curvature_changes():
    sig = dict(SIG, frequency_shift=np.zeros((3, 3)), curvature_change=np.zeros((3, 3, 8)))
    sig["curvature_change"][0, 1, 1] = 0.05  # candidate 0 changes mode 2's shape at η = 1 m
    sig["curvature_change"][2, 0, 6] = -0.05
    dk = np.zeros((3, 8))
    dk[1, 1] = 0.04
    loc = locate_damage(np.zeros(3), np.full(3, 1e-4), sig, shape_change=dk, shape_std=np.full(3, 0.01))
    assert loc.eta_m == 0.5 and loc.third == "upper" and loc.best_match == pytest.approx(1.0)


def synthetic(duration=1500.0, mix_at=None, mix=0.0, seed=0, noise=1e-6):
    """Three units, one narrow-band mode each, white noise of RMS ``noise`` on each; from mix_at
    mode 1 also moves unit 2 (shape change)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * FS)) / FS
    b = noise * rng.standard_normal((t.size, 3))
    for i, f in enumerate((1.0, 2.5, 4.0)):
        # a lightly damped mode under white noise (resonator), so every window is 'ambient'
        bb, aa = signal.iirpeak(f, Q=40.0, fs=FS)
        x = signal.lfilter(bb, aa, rng.standard_normal(t.size)) * 1e-3
        b[:, i] += x
        if i == 0 and mix_at is not None:
            b[:, 1] += np.where(t >= mix_at, mix, 0.0) * x
    return t, b, ((1.0,), (2.5,), (4.0,))


@pytest.fixture(scope="module")
def healthy():
    t, b, exp = synthetic(seed=1)
    return analyze(t, b, S2, ETA, fs=FS, expected_hz=exp)


def test_healthy_curvature_chart_is_calibrated(healthy):
    assert healthy.flags == ()
    scores = [w.curvature_score for w in healthy.windows if w.curvature_score is not None]
    assert len(scores) > 20 and max(abs(s) for s in scores) < AnalysisConfig().curvature_alarm_sigma / 2
    bl = healthy.baseline
    assert len(bl.curvature_shape_std) == 3 and bl.curvature_windows >= 10 and min(bl.curvature_mode_windows) >= 10
    # the baseline's curvatures are the modes' (one unit deformation each): s''_χ at unit RMS
    np.testing.assert_allclose(bl.curvature_shapes, (S2 / np.sqrt(np.mean(S2**2, axis=0))).T, atol=0.02)
    # Q pools 3 modes × 8 stations: its std lies between that of χ²_24/24 (independent terms, the
    # tolerance's) and χ²_3/3 (each mode's stations fully correlated)
    assert bl.curvature_index_mean == 1.0 and np.sqrt(2 / 24) - 1e-9 <= bl.curvature_index_std <= np.sqrt(2 / 3) + 1e-9


def test_baseline_from_another_record_charts_calmly():
    """A baseline learnt from one healthy record, charted on another whose modes stand barely above
    the noise (their shapes scatter far more than the tolerance): no flag."""
    base = analyze(*synthetic(seed=1, noise=3e-4)[:2], S2, ETA, fs=FS, expected_hz=((1.0,), (2.5,), (4.0,))).baseline
    t, b, exp = synthetic(duration=900.0, seed=3, noise=3e-4)
    res = analyze(t, b, S2, ETA, fs=FS, expected_hz=exp, baseline=base)
    scores = [w.curvature_score for w in res.windows if w.curvature_score is not None]
    assert res.flags == () and len(scores) > 10
    assert max(scores) < AnalysisConfig().curvature_alarm_sigma, scores


def test_shape_change_is_flagged_and_located_by_signatures():
    t, b, exp = synthetic(mix_at=800.0, mix=0.15, seed=2)
    # mode 1's identified shape turns from (1, 0, 0) to (1, 0.15, 0): its mode-shape curvature changes by
    base, changed = mode_shape_curvature(np.array([[1.0, 0.0, 0.0], [1.0, 0.15, 0.0]]), S2, np.array([0, 0]))
    sig = dict(SIG, frequency_shift=np.zeros((3, 3)), curvature_change=np.zeros((3, 3, 8)))
    sig["curvature_change"][1, 0] = changed - base  # the candidate at 2.0 m predicts this change
    sig["curvature_change"][0, 0] = -(changed - base)
    sig["curvature_change"][2, 2, 3] = 0.1
    res = analyze(t, b, S2, ETA, fs=FS, expected_hz=exp, signatures=sig)
    cur = [f for f in res.flags if f["kind"] == "curvature"]
    assert cur, res.flags
    first = next(w for w in res.windows if any(f["kind"] == "curvature" for f in w.flags))
    assert 800 < first.end_s < 800 + 600
    assert cur[0]["located_by"] == "signatures" and cur[0]["eta_m"] == 2.0 and cur[0]["third"] == "middle"
    assert json.dumps(res.as_dict(), allow_nan=False)


def test_ambient_damping_by_the_subspace_pole_and_random_decrement():
    """Ambient record with a bearing channel that never moves: no free decay, so the record's
    subspace pole (preferred) and random decrement, each with its method and 1σ."""
    rng = np.random.default_rng(5)
    f, zeta = 2.0, 0.01
    wn = 2 * np.pi * f
    A = np.array([[0.0, 1.0], [-(wn**2), -2 * zeta * wn]])
    Ad, Bd, *_ = signal.cont2discrete((A, np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))), 1 / FS)
    u = rng.standard_normal(int(1200 * FS))
    y = signal.lfilter([0.0, Bd[0, 0], Bd[1, 0] * Ad[0, 1] - Bd[0, 0] * Ad[1, 1]], [1.0, -np.trace(Ad), np.linalg.det(Ad)], u)
    t = np.arange(y.size) / FS
    res = analyze(t, y[:, None], S2[:, :1], ETA, fs=FS, expected_hz=((f,),), bearing=np.zeros(y.size))
    m = res.modes[0]
    assert m.damping_method == "ssi" and m.method == "ssi"
    by = {d.method: d for d in m.damping}
    assert set(by) == {"ssi", "random_decrement"}
    for d in by.values():
        assert d.damping_ratio == pytest.approx(zeta, rel=0.25) and 0 < d.damping_std < 0.5 * zeta
    assert m.damping_ratio == by["ssi"].damping_ratio


def test_decay_fit_stops_at_the_noise_floor():
    """Decays of a fast mode (5 Hz, ζ = 0.7 %, τ = 4.5 s) kicked every 60 s by the bearing: each
    still span lasts ~13 τ, far into the noise floor; the fit must stop before it."""
    rng = np.random.default_rng(9)
    f, zeta = 5.0, 0.007
    wn = 2 * np.pi * f
    t = np.arange(int(1200 * FS)) / FS
    b = 1e-6 * rng.standard_normal(t.size)
    bearing = np.zeros(t.size)
    for k0 in range(0, t.size, int(60 * FS)):
        kick = slice(k0, k0 + int(0.5 * FS))
        bearing[kick] = 5e-3
        tt = t[k0 + int(0.5 * FS) :] - t[k0 + int(0.5 * FS)]
        b[k0 + int(0.5 * FS) :] += 1e-3 * np.exp(-zeta * wn * tt) * np.cos(wn * np.sqrt(1 - zeta**2) * tt)
    res = analyze(t, b[:, None], S2[:, :1], ETA, fs=FS, expected_hz=((f,),), bearing=bearing)
    m = res.modes[0]
    assert m.damping_method == "free_decay" and "free_decay" in {d.method for d in m.damping}
    assert m.damping_ratio == pytest.approx(zeta, rel=0.1)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: locate_damage(np.zeros(3), np.zeros(3), SIG), "frequency_std"),
        (lambda: locate_damage(np.zeros(3), np.ones(2), SIG), "frequency_std"),
        (lambda: locate_damage(np.zeros(3), np.ones(3), {"eta": [1.0]}), "need eta"),
        (lambda: locate_damage(np.zeros(4), np.ones(4), SIG), "disagree"),
        (lambda: locate_damage(np.zeros(3), np.ones(3), SIG, shape_change=np.zeros((3, 8))), "curvature_change"),
        (lambda: locate_damage(np.zeros(3), np.ones(3), dict(SIG, curvature_change=np.zeros((3, 3, 7))), shape_change=np.zeros((3, 8))), "does not fit"),
        (lambda: analyze(np.arange(100.0), np.ones((100, 3)), S2, ETA, fs=1.0, config=AnalysisConfig(window_s=50),
                         signatures=dict(SIG, curvature_change=np.zeros((3, 3, 5)))), "stations"),
        (lambda: AnalysisConfig(curvature_min_std=0.0), "curvature_min_std"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_against_another_records_baseline_the_curvature_chart_warns_but_never_alarms():
    """The same shape change as above, charted against a baseline learnt by a separate analysis (as
    of another record): the statistic still rises beyond the alarm level, the chart stays at
    "warning" and raises no curvature flag."""
    t, b, exp = synthetic(mix_at=800.0, mix=0.15, seed=2)
    own = analyze(t, b, S2, ETA, fs=FS, expected_hz=exp)
    assert any(f["kind"] == "curvature" for f in own.flags)
    res = analyze(t, b, S2, ETA, fs=FS, expected_hz=exp, baseline=own.baseline)
    scores = [w.curvature_score for w in res.windows if w.curvature_score is not None]
    assert max(scores) > AnalysisConfig().curvature_alarm_sigma
    levels = {w.levels.get(CURVATURE_CHART) for w in res.windows}
    assert levels <= {None, "ok", "warning"} and "warning" in levels
    assert not [f for f in res.flags if f["kind"] == "curvature"]
