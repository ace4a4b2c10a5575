"""DEL bands calibrated on the gauges' cross-validated residuals and carried along the beam by the
modes above the basis (``analytics.outside_basis_bands``): hand-computable cases (DELs scale with
the signal, so a gauge reading k times the virtual strain has |ln ρ| = ln k exactly) and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import OutsideBasis, outside_basis_bands

M = np.sin(np.linspace(0.0, 60.0, 3000)) + 0.3 * np.sin(np.linspace(0.0, 222.0, 3000))
RMS = float(np.sqrt(np.mean(M**2)))


def _run(gauges, stations, phi_g, phi_s, rms, **kw):
    bands, rows = outside_basis_bands(gauges, stations, OutsideBasis(np.asarray(phi_g, float), np.asarray(phi_s, float),
                                                                     np.asarray(rms, float)), exponents=(3.0, 5.0), n_eq=30.0, **kw)
    assert bands is not None
    return [b.high - 1.0 for b in bands], bands, rows


def test_floor_only_residual_scales_with_the_station_strain():
    # no mode above the basis: the missing strain is the same floor everywhere; g1 reads 1.1 × virtual
    # (r = 0.1/1.1 m, q = 0.1), g2 1.05 × (q = 0.05): scores ln 1.1/0.1 and ln 1.05/0.05
    gauges = [("g1", 1.0, M / 1.1, M, 0.0), ("g2", 2.0, M / 1.05, M, 0.0)]
    var = np.mean([np.mean((M - M / 1.1) ** 2), np.mean((M - M / 1.05) ** 2)])  # the floor: the NNLS mean of two
    a, bands, rows = _run(gauges, [3.0, 1.0], np.zeros((2, 0)), np.zeros((2, 0)), [RMS / 2, RMS / 1.1])
    kappa = max(np.log(1.1) / 0.1, np.log(1.05) / 0.05)  # 2 gauges, 90 %: the largest
    assert rows[0]["score"] == pytest.approx(np.log(1.1) / 0.1, rel=1e-9)
    assert rows[1]["relative_residual"] == pytest.approx(0.05, rel=1e-9)
    # a station with half the virtual strain has twice the relative missing strain
    assert a[0] == pytest.approx(np.expm1(kappa * np.sqrt(var) / (RMS / 2)), rel=1e-6)
    # at a gauge: at least its own factor
    assert a[1] >= 0.1 - 1e-12
    assert "conformal" in bands[0].method and "kappa" in bands[0].method


def test_a_mode_above_the_basis_puts_the_missing_strain_where_it_bends():
    # the missing strain is one mode's: 0.1 v at g1 (shape 1), 0.05 v at g2 (shape 0.5); a station between
    # them where the shape is 0 has no missing strain (floor 0) but takes the larger gauge's own factor,
    # 1/(1 − 0.1/1.1) = 1.1; where the shape is 2, q doubles against g1's
    v = M / 1.1
    gauges = [("g1", 1.0, M - 0.1 * v, M, 0.0), ("g2", 2.0, M - 0.05 * v, M, 0.0)]
    rms = np.sqrt(np.mean((M - 0.1 * v) ** 2))
    a, _, rows = _run(gauges, [1.5, 3.0], [[1.0], [0.5]], [[0.0], [2.0]], [rms, rms])
    assert a[0] == pytest.approx(0.1, rel=1e-9)
    kappa = max(r["score"] for r in rows)
    assert a[1] == pytest.approx(np.expm1(kappa * 2 * rows[0]["relative_residual"]), rel=1e-6)
    assert a[1] > a[0]


def test_the_conformal_rank_with_many_gauges():
    # 19 gauges reading 1 + k/100 times the virtual: scores ln(1 + k/100)/(k/100); 90 %: rank ⌈20 × 0.9⌉ = 18
    gauges = [(f"g{k}", float(k), M / (1 + k / 100), M, 0.0) for k in range(1, 20)]
    scores = sorted(np.log(1 + k / 100) / (k / 100) for k in range(1, 20))
    rms_s = np.sqrt(np.mean((M / 1.01) ** 2))
    _a, bands, _ = _run(gauges, [0.5], np.zeros((19, 0)), np.zeros((1, 0)), [rms_s])
    assert f"kappa = {scores[17]:.4f}" in bands[0].method


def test_bad_input():
    g = [("g1", 1.0, M, M, 0.0)]
    with pytest.raises(ValueError, match="disagree with 1 gauges and 2 stations"):
        _run(g, [1.0, 2.0], np.zeros((1, 1)), np.zeros((1, 1)), [1.0])
    with pytest.raises(ValueError, match="coverage=1.5 must be in"):
        _run(g, [1.0], np.zeros((1, 0)), np.zeros((1, 0)), [1.0], coverage=1.5)
    with pytest.raises(ValueError, match="leverage of gauge g1"):
        _run([("g1", 1.0, M, M, 1.0)], [1.0], np.zeros((1, 0)), np.zeros((1, 0)), [1.0])
    flat = np.zeros(100)
    bands, rows = outside_basis_bands([("g1", 1.0, flat, flat, 0.0)], [1.0], OutsideBasis(np.zeros((1, 0)), np.zeros((1, 0)),
                                      np.ones(1)), exponents=(3.0,), n_eq=10.0)
    assert bands is None and rows[0]["half_width"] is None
