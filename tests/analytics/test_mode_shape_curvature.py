"""The curvature (damage-location) index from identified mode shapes: the shape curvature and the
chart's statistic by hand, a healthy structure under another balance of its excitation, and a
stiffness loss of the 20 m mast raising the curvature chart and located by it."""

import json

import numpy as np
import pytest
from example_mast import planar_mast_data
from scipy import signal

from analytics import AnalysisConfig, analyze, curvature_shape, curvature_statistic, mode_shape_curvature

FS = 50.0
ETA = np.linspace(0.5, 4.0, 8)
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])


def test_mode_shape_curvature_by_hand():
    S = np.array([[1.0, 2.0], [0.0, 1.0], [1.0, -1.0], [0.0, 0.0]])  # 4 stations, Γ = 2
    # φ = (2, 0): κ = 2·s''_1 = (2, 0, 2, 0), RMS √2 → (√2, 0, √2, 0)
    k = mode_shape_curvature([[2.0, 0.0]], S, np.array([0]))
    np.testing.assert_allclose(k, [[np.sqrt(2), 0.0, np.sqrt(2), 0.0]], rtol=1e-12)
    # φ = −(1, 1): κ = −(3, 1, 0, 0), RMS √(10/4); signed by unit 1 (φ_1 > 0): (3, 1, 0, 0)/√2.5
    k = mode_shape_curvature([[-1.0, -1.0]], S, np.array([0]))
    np.testing.assert_allclose(k, [[3 / np.sqrt(2.5), 1 / np.sqrt(2.5), 0.0, 0.0]], rtol=1e-12)
    # scale and sign are the normalisation's: the same as the reference-signed form of any multiple
    ref = mode_shape_curvature([[1.0, 1.0]], S, np.array([1]))
    np.testing.assert_allclose(mode_shape_curvature([[-7.0, -7.0]], S, ref), ref, rtol=1e-12)
    # a real shape's curvature is the operational curvature shape of an in-phase cross spectrum
    np.testing.assert_allclose(mode_shape_curvature([[0.3, 1.0, -0.2]], S2, np.array([1]))[0],
                               curvature_shape(np.array([0.3, 1.0, -0.2]) + 0j, 1, S2), rtol=1e-12)


def test_curvature_statistic_by_hand():
    # two modes, three stations; mode 1's terms independent with variance 1e-4 (σ² = 1e-4 + τ² = 2e-4),
    # mode 2 unused at its last station
    C = np.zeros((2, 3, 3))
    C[0] = 1e-4 * np.eye(3)
    C[1] = 1e-4 * np.ones((3, 3))  # fully correlated stations
    delta = np.array([[0.02, 0.0, 0.0], [0.0, 0.01, 5.0]])
    used = np.array([[True, True, True], [True, True, False]])
    s = curvature_statistic(delta, C, 0.01, used)
    # q = ((0.02²/2e-4) + 0 + 0 + 0 + 0.01²/2e-4)/5 = (2 + 0.5)/5
    assert s.terms == 5 and s.q == pytest.approx(0.5)
    # R of mode 1 = I (tr R² = 3); mode 2's two stations: R = [[1, ½], [½, 1]] (tr R² = 2.5)
    assert s.q_std == pytest.approx(np.sqrt(2 * 5.5) / 5)
    assert s.score == pytest.approx((0.5 - 1) / (np.sqrt(11) / 5))
    assert s.sigma[1, 2] == np.inf and s.sigma[0, 0] == pytest.approx(np.sqrt(2e-4))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: mode_shape_curvature([[1.0, 0.0]], S2, np.array([0])), "columns"),
        (lambda: mode_shape_curvature([[0.0, 0.0, 0.0]], S2, np.array([0])), "zero curvature"),
        (lambda: mode_shape_curvature([[1.0, 0.0, 0.0]], S2, np.array([3])), "reference"),
        (lambda: mode_shape_curvature([[1.0, 0.0, 0.0]], S2, np.ones((1, 5))), "reference"),
        (lambda: curvature_statistic(np.zeros((1, 3)), np.zeros((1, 2, 2)), 0.01), "covariance"),
        (lambda: curvature_statistic(np.zeros((1, 3)), np.zeros((1, 3, 3)), -0.01), "tolerance"),
        (lambda: curvature_statistic(np.zeros((1, 3)), np.zeros((1, 3, 3)), 0.0), "zero σ"),
        (lambda: curvature_statistic(np.zeros((1, 3)), np.zeros((1, 3, 3)), 0.01, np.zeros((1, 3))), "no .* term"),
        (lambda: curvature_statistic(np.zeros((1, 3)), np.zeros((1, 3, 3)), 0.01, np.ones((2, 3))), "used"),
        (lambda: AnalysisConfig(curvature_mac_min=0.0), "curvature_mac_min"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def resonators(t, fs, freqs, phis, amplitudes, seed, q=40.0):
    """b (N, Γ) = Σ_i φ_i·x_i(t): lightly damped modes (frequencies ``freqs``, shapes the rows of
    ``phis``) under white noise, each of RMS ``amplitudes[i]``."""
    rng = np.random.default_rng(seed)
    b = np.zeros((t.size, np.shape(phis)[1]))
    for i, f in enumerate(freqs):
        bb, aa = signal.iirpeak(f, Q=q, fs=fs)
        x = signal.lfilter(bb, aa, rng.standard_normal(t.size))
        b += np.outer(x * amplitudes[i] / np.std(x), phis[i])
    return b


def test_a_healthy_structure_under_another_balance_of_its_excitation_raises_no_curvature_flag():
    """The baseline's record: three modes of similar amplitude and a small broadband error common to
    units 1 and 2 (an estimator's error that follows the wind load, not a mode). The healthy test
    record: mode 2 five times stronger, mode 3 five times weaker and the broadband error ten times
    stronger (a storm). The operational deflection shapes at the modes change with that balance;
    the identified mode shapes do not: no curvature flag, and the chart stays calm."""
    phis = np.array([[1.0, 0.2, 0.0], [0.1, 1.0, 0.1], [0.0, -0.2, 1.0]])
    freqs = (1.0, 2.5, 4.0)
    exp = tuple((f,) for f in freqs)

    def record(duration, amplitudes, error, seed):
        t = np.arange(int(duration * FS)) / FS
        b = 1e-3 * resonators(t, FS, freqs, phis, amplitudes, seed)
        rng = np.random.default_rng(seed + 100)
        wind = signal.lfilter(*signal.butter(2, 6.0, fs=FS), rng.standard_normal(t.size))
        b[:, :2] += 1e-3 * error * (wind / np.std(wind))[:, None]
        return t, b

    base = analyze(*record(1500.0, (1.0, 1.0, 1.0), 0.02, 1), S2, ETA, fs=FS, expected_hz=exp, config=AnalysisConfig(baseline_s=1200.0))
    bl = base.baseline
    assert min(bl.curvature_mode_windows) >= 30 and bl.curvature_covariance.shape == (3, 8, 8)
    t, b = record(1200.0, (1.0, 5.0, 0.2), 0.2, 7)
    res = analyze(t, b, S2, ETA, fs=FS, expected_hz=exp, baseline=bl)
    scores = [w.curvature_score for w in res.windows if w.curvature_score is not None]
    assert len(scores) > 20
    assert not [f for f in res.flags if f["kind"] == "curvature"], res.flags
    assert max(scores) < AnalysisConfig().warning_sigma, scores
    assert json.dumps(res.as_dict(), allow_nan=False)


@pytest.fixture(scope="module")
def mast():
    """The 20 m mast of examples/mast bending in ζ: its healthy FE modes (the unit deformations of a clamped beam:
    each mode is its own, so the healthy shapes are unit vectors) and the modes after a stiffness
    loss of 30 % over 9–11 m, projected onto the healthy unit deformations as the estimator sees them."""
    from contract import parse_rig
    from estimator import assemble_beam, damage_signatures, natural_modes, unit_deformations

    raw = planar_mast_data()  # one plane's modes (a round tube: the other plane's are the same)
    rig = parse_rig(raw)
    damaged = json.loads(json.dumps(raw))
    damaged["beam"]["stiffness_segments"] = [{"start": 9.0, "end": 11.0, "factor": 0.7}]
    healthy_model = assemble_beam(rig, extra_nodes=(9.0, 11.0))
    units = unit_deformations(healthy_model, 4)
    modes_h = natural_modes(healthy_model, 4)
    modes_d = natural_modes(assemble_beam(parse_rig(damaged), extra_nodes=(9.0, 11.0)), 4)
    grid = np.linspace(0.0, 20.0, 401)
    basis = units.shape(grid)
    project = lambda m: np.linalg.lstsq(basis, m.shapes.evaluate(grid, 0), rcond=None)[0].T  # noqa: E731  (modes, Γ)
    stations = np.asarray(rig.truth_stations, dtype=float)
    sig = damage_signatures(rig, stations, gamma=4, segment_length=2.0, step=1.0, stiffness_factor=0.7)
    return dict(units=units, stations=stations, f_h=modes_h.frequencies_hz, f_d=modes_d.frequencies_hz,
                phi_h=project(modes_h), phi_d=project(modes_d), signatures=sig)


def test_the_healthy_mast_modes_are_its_unit_deformations(mast):
    phi = mast["phi_h"] / np.linalg.norm(mast["phi_h"], axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(phi), np.eye(4), atol=1e-6)
    # the loss changes the shapes by a few per cent of curvature, far beyond the tolerance
    k_h = mode_shape_curvature(mast["phi_h"], mast["units"].curvature(mast["stations"]), np.arange(4))
    k_d = mode_shape_curvature(mast["phi_d"], mast["units"].curvature(mast["stations"]), k_h)
    assert np.sqrt(np.mean((k_d - k_h) ** 2)) > 2 * AnalysisConfig().curvature_min_std


def test_a_stiffness_loss_of_the_mast_raises_the_curvature_chart_and_is_located(mast):
    fs, damage_s = 100.0, 900.0
    t = np.arange(int(1500.0 * fs)) / fs
    amplitudes = (1.0, 0.5, 0.3, 0.2)
    b = np.where((t < damage_s)[:, None], resonators(t, fs, mast["f_h"], mast["phi_h"], amplitudes, seed=3),
                 resonators(t, fs, mast["f_d"], mast["phi_d"], amplitudes, seed=4))
    b = 1e-3 * b + 1e-7 * np.random.default_rng(5).standard_normal(b.shape)
    S = mast["units"].curvature(mast["stations"])
    res = analyze(t, b, S, mast["stations"], fs=fs, expected_hz=tuple((f,) for f in mast["f_h"]), signatures=mast["signatures"],
                  beam_length=20.0)
    before = [w.curvature_score for w in res.windows if w.curvature_score is not None and w.end_s <= damage_s]
    assert before and max(before) < AnalysisConfig().warning_sigma
    cur = [f for f in res.flags if f["kind"] == "curvature"]
    assert cur, res.flags
    first = next(w for w in res.windows if any(f["kind"] == "curvature" for f in w.flags))
    assert damage_s < first.end_s <= damage_s + 600
    # located by the FE signatures at the damaged segment (9–11 m), a stiffness loss, in the middle third
    assert cur[0]["located_by"] == "signatures" and 9.0 <= cur[0]["eta_m"] <= 11.0
    assert cur[0]["damage_kind"] == "stiffness" and cur[0]["third"] == "middle"


def test_a_baseline_stored_before_the_mode_shape_index_arms_the_frequency_charts_only():
    phis = np.eye(3)
    exp = ((1.0,), (2.5,), (4.0,))
    t = np.arange(int(900.0 * FS)) / FS
    b = 1e-3 * resonators(t, FS, (1.0, 2.5, 4.0), phis, (1.0, 1.0, 1.0), seed=11)
    cfg = AnalysisConfig(baseline_s=300.0, curvature_memory_windows=2.0)
    new = analyze(t[: int(450 * FS)], b[: int(450 * FS)], S2, ETA, fs=FS, expected_hz=exp, config=cfg).baseline
    old = new.to_dict()
    del old["curvature_index"], old["curvature_covariance"], old["curvature_mode_windows"]
    for baseline, charted in ((new.to_dict(), True), (old, False)):
        res = analyze(t[int(450 * FS):], b[int(450 * FS):], S2, ETA, fs=FS, expected_hz=exp, config=cfg, baseline=baseline,
                      time_origin_ns=int(450e9))
        assert any(w.curvature_score is not None for w in res.windows) is charted
        assert any(s is not None for w in res.windows for s in w.frequency_scores)
        assert res.flags == ()
