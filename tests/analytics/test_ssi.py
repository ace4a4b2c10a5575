"""SSI-cov, the stabilisation diagram and the clustering on systems with known poles."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import (
    OmaConfig, OperationalModalAnalysis, PoleSet, block_toeplitz, cluster_poles, damping_estimates, identify_modes, identify_windows,
    modal_assurance, modal_phase_collinearity, output_correlations, ssi_cov, ssi_poles, stabilisation_diagram,
    subspace_damping, toeplitz_from_data, tracked_frequency,
)

from oma_systems import ambient_response, exact_correlations, three_dof

FS = 50.0


def test_output_correlations_and_toeplitz_by_hand():
    y = np.array([1.0, -1.0, 2.0, 0.0])  # mean 0.5 → [0.5, -1.5, 1.5, -0.5]
    R = output_correlations(y, 2)
    assert R.shape == (3, 1, 1)
    assert R[0, 0, 0] == pytest.approx((0.25 + 2.25 + 2.25 + 0.25) / 4)
    assert R[1, 0, 0] == pytest.approx((-0.75 - 2.25 - 0.75) / 3)
    assert R[2, 0, 0] == pytest.approx((0.75 + 0.75) / 2)
    lags = np.arange(4, dtype=float)[:, None, None] * np.ones((1, 1, 1))
    T = block_toeplitz(lags, 2)  # block (a, b) holds lag 2 + a - b
    np.testing.assert_array_equal(T, [[2.0, 1.0], [3.0, 2.0]])


def test_exact_poles_of_a_three_dof_system():
    """Without noise (exact correlations) the poles come back to 1e-4 (here ~1e-9)."""
    s = three_dof()
    R = exact_correlations(s, FS, 60)
    model = ssi_poles(block_toeplitz(R, 30), 3, FS, [6])
    order = np.argsort(model.poles.frequency_hz)
    f, z = model.poles.frequency_hz[order], model.poles.damping_ratio[order]
    np.testing.assert_allclose(f, s.frequencies_hz, rtol=1e-4)
    np.testing.assert_allclose(z, s.damping, rtol=1e-4)
    mac = np.diag(modal_assurance(model.poles.shapes[order], s.shapes))
    assert np.all(mac > 1 - 1e-8)
    assert np.all(model.poles.mpc > 1 - 1e-8)


def test_ssi_cov_and_data_toeplitz_agree_on_a_long_record():
    s = three_dof()
    y = ambient_response(s, FS, 60_000, seed=3)
    m1 = ssi_cov(y, FS, block_rows=20, orders=[6])
    T, Ts = toeplitz_from_data(y, 20, segments=4)
    np.testing.assert_allclose(T, Ts.mean(axis=0), rtol=1e-3, atol=1e-9 * np.abs(T).max())
    m2 = ssi_poles(T, 3, FS, [6])
    np.testing.assert_allclose(np.sort(m1.poles.frequency_hz), np.sort(m2.poles.frequency_hz), rtol=2e-3)
    np.testing.assert_allclose(np.sort(m1.poles.frequency_hz), s.frequencies_hz, rtol=5e-3)


def test_identify_modes_lists_the_three_modes_and_nothing_else():
    s = three_dof()
    y = ambient_response(s, FS, 30_000, seed=1, noise_rel=0.05)
    ident = identify_modes(y, FS, config=OmaConfig(fmin_hz=1.0, fmax_hz=15.0), reference_shapes=s.shapes)
    f = np.array([m.frequency_hz for m in ident.modes])
    assert f.size == 3
    np.testing.assert_allclose(f, s.frequencies_hz, rtol=0.01)
    for k, m in enumerate(ident.modes):
        assert m.reference == k and m.mac > 0.99
        assert m.mpc > 0.95
        assert abs(m.damping_ratio - s.damping[k]) < 4 * m.damping_std + 1e-3
        d = subspace_damping(m)
        assert d.method == "ssi" and d.damping_ratio == m.damping_ratio and d.damping_std == m.damping_std
    assert 0.95 < sum(m.contribution for m in ident.modes) <= 1.0 + 1e-12  # the rest: the noise clusters rejected


@pytest.mark.slow
@pytest.mark.parametrize("uncertainty", ["jackknife", "batch", "delete-one"])
def test_standard_deviations_cover_the_errors_at_their_stated_rate(uncertainty):
    """Over seeded runs, |error| ≤ 1σ about 68 % of the time and ≤ 2σ about 95 %: the segment
    jackknife of a window, the batch means and the delete-one jackknife of a record (each part
    identified anew)."""
    s = three_dof()
    cfg = OmaConfig(fmin_hz=1.0, fmax_hz=15.0, uncertainty=uncertainty)
    zf, zz = [], []
    for seed in range(40):
        y = ambient_response(s, FS, 6_000, seed=100 + seed, noise_rel=0.2)
        ident = identify_modes(y, FS, config=cfg)
        for m in ident.modes:
            k = int(np.argmin(np.abs(s.frequencies_hz - m.frequency_hz)))
            if abs(m.frequency_hz / s.frequencies_hz[k] - 1) < 0.05:
                zf.append((m.frequency_hz - s.frequencies_hz[k]) / m.frequency_std_hz)
                zz.append((m.damping_ratio - s.damping[k]) / m.damping_std)
    zf, zz = np.abs(zf), np.abs(zz)
    assert zf.size >= 100  # the modes are found in nearly every run
    for z in (zf, zz):
        assert 0.55 <= np.mean(z <= 1) <= 0.85, np.mean(z <= 1)
        assert np.mean(z <= 2) >= 0.85, np.mean(z <= 2)


def test_damping_by_subspace_and_random_decrement_each_with_method_and_uncertainty():
    s = three_dof()
    y = ambient_response(s, FS, 60_000, seed=8, noise_rel=0.05)
    ident = identify_modes(y, FS, config=OmaConfig(fmin_hz=1.0, fmax_hz=15.0))
    m = ident.modes[0]
    est = {e.method: e for e in damping_estimates(y, FS, m)}
    assert set(est) == {"ssi", "random_decrement"}
    for e in est.values():
        assert e.damping_std > 0
        assert abs(e.damping_ratio - s.damping[0]) < 4 * e.damping_std + 5e-4, (e.method, e.damping_ratio, e.damping_std)
    with pytest.raises(ValueError, match="channels"):
        damping_estimates(y[:, :2], FS, m)


def test_a_harmonic_is_not_listed_as_a_mode():
    s = three_dof()
    n = 60_000
    y = ambient_response(s, FS, n, seed=5, noise_rel=0.05)
    t = np.arange(n) / FS
    y = y + 3 * y.std(axis=0) * np.sin(2 * np.pi * 4.0 * t)[:, None] * np.array([1.0, 0.5, -0.3])
    ident = identify_modes(y, FS, config=OmaConfig(fmin_hz=1.0, fmax_hz=15.0))
    f = np.array([m.frequency_hz for m in ident.modes])
    assert not np.any(np.abs(f - 4.0) < 0.05), f
    assert any(abs(r - 4.0) < 0.05 for r, _ in ident.rejected)
    np.testing.assert_allclose(np.sort(f), s.frequencies_hz, rtol=0.01)


def test_windows_and_algorithm_object():
    s = three_dof()
    y = ambient_response(s, FS, 12_000, seed=2, noise_rel=0.05)
    res = OperationalModalAnalysis(OmaConfig(fmin_hz=1.0, fmax_hz=15.0), window_s=60.0, step_s=60.0).run(y, FS)
    assert len(res.windows) == 4
    assert [w.start_s for w in res.windows] == pytest.approx([0.0, 60.0, 120.0, 180.0], abs=0.1)
    for w in res.windows:
        f1 = tracked_frequency(w.modes, 1.5, 3.0)
        assert f1 == pytest.approx(s.frequencies_hz[0], rel=0.01)
    assert len(res.record.modes) == 3


def test_stabilisation_flags_and_clusters_by_hand():
    # order 2 and 4 poles at 1 Hz (stable), a noise pole at order 4 only
    lam = lambda f, z: -z * 2 * np.pi * f + 1j * 2 * np.pi * f * np.sqrt(1 - z * z)  # noqa: E731
    ev = np.array([lam(1.0, 0.01), lam(1.001, 0.0101), lam(3.0, 0.3), lam(1.0005, 0.0102), lam(2.0, 0.05)])
    shapes = np.ones((5, 2), complex)
    p = PoleSet(np.array([2, 4, 4, 6, 6]), ev, np.abs(ev) / (2 * np.pi), -ev.real / np.abs(ev), shapes, np.ones(5))
    d = stabilisation_diagram(p, freq_rel=0.01, damping_rel=0.05, mac_min=0.9, max_damping=0.2)
    np.testing.assert_array_equal(d.admissible, [True, True, False, True, True])
    np.testing.assert_array_equal(d.stable, [False, True, False, True, False])
    c = cluster_poles(d, min_orders=0.5)
    assert c == ()  # two stable poles are fewer than 3 orders
    assert modal_phase_collinearity(np.array([[1 + 0j, -2 + 0j], [1, 1j]])) == pytest.approx([1.0, 0.0], abs=1e-12)


@pytest.mark.parametrize("call, match", [
    (lambda: identify_modes(np.ones((100, 2)), 50.0), "constant"),
    (lambda: identify_modes(np.r_[np.zeros(50), np.nan, np.zeros(49)], 50.0), "NaN"),
    (lambda: identify_modes(np.random.default_rng(0).standard_normal(200), -1.0), "fs=-1.0"),
    (lambda: identify_modes(np.random.default_rng(0).standard_normal(200), 50.0, config=OmaConfig(fmax_hz=40.0)), "fmax_hz=40.0"),
    (lambda: identify_modes(np.random.default_rng(0).standard_normal((200, 2)), 50.0, reference_shapes=np.ones((1, 3))), "reference_shapes"),
    (lambda: identify_windows(np.random.default_rng(0).standard_normal(200), 50.0, 10.0, 5.0), "window_s=10.0"),
    (lambda: OmaConfig(fmin_hz=5.0, fmax_hz=2.0), "fmax_hz"),
    (lambda: OmaConfig(unknown=1), "unknown"),
    (lambda: OmaConfig(uncertainty="bootstrap"), "uncertainty"),
    (lambda: ssi_poles(np.eye(6), 4, 10.0, [2]), "channels=4"),
    (lambda: ssi_poles(np.eye(6), 2, 10.0, [8]), "orders"),
    (lambda: block_toeplitz(np.zeros((3, 1, 1)), 2), "block_rows=2"),
    (lambda: output_correlations(np.zeros(5), 5), "max_lag=5"),
    (lambda: toeplitz_from_data(np.zeros(10), 3, segments=4), "segments=4"),
    (lambda: stabilisation_diagram("poles"), "PoleSet"),
    (lambda: tracked_frequency((), 3.0, 2.0), "fmin_hz=3.0"),
    (lambda: subspace_damping(0.01), "IdentifiedMode"),
])
def test_bad_input_names_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_noise_free_free_decay_clusters_without_negative_distances():
    # Identical shapes across orders give 1 − MAC a rounding error below zero; clustering must take it.
    fs = 100.0
    t = np.arange(0.0, 20.0, 1 / fs)

    def decay(f, zeta):
        return np.exp(-zeta * 2 * np.pi * f * t) * np.cos(2 * np.pi * f * np.sqrt(1 - zeta**2) * t)

    y = np.column_stack([decay(3.0, 0.01) + 0.5 * decay(7.0, 0.02), 0.6 * decay(3.0, 0.01) - 0.8 * decay(7.0, 0.02)])
    result = identify_modes(y, fs, config=OmaConfig(fmin_hz=1.0, fmax_hz=10.0))
    assert [round(m.frequency_hz, 2) for m in result.modes] == [3.0, 7.0]
