"""The virtual stations' DEL bands from leave-one-gauge-out residuals at the strain gauges:
hand-computable cases (DELs scale with the signal, so a gauge reading k times the virtual strain
gives the factor k exactly) and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import BAND_FLOOR, gauge_bands

MEASURED = np.sin(np.linspace(0.0, 60.0, 3000)) + 0.3 * np.sin(np.linspace(0.0, 222.0, 3000))


def _bands(gauges, stations):
    bands, rows = gauge_bands(gauges, stations, exponents=(3.0, 5.0), n_eq=30.0)
    assert bands is not None
    return [b.high - 1.0 for b in bands], bands, rows


def test_out_of_sample_and_in_sample_factors_by_hand():
    m = MEASURED
    # out of sample (h = 0): virtual = m/1.1, the measured DEL is 1.1 times the virtual's: a = 0.1 at the gauge
    a, bands, rows = _bands([("g1", 1.0, m / 1.1, m, 0.0)], [1.0, 2.0])
    assert a[0] == pytest.approx(0.1, rel=1e-12) and bands[0].low == pytest.approx(1 / 1.1, rel=1e-12)
    assert rows[0]["out_of_sample"] and rows[0]["del_factor"][0]["measured_over_virtual"] == pytest.approx(1.1, rel=1e-12)
    # away from a single gauge the prediction: t(0.9, 1 dof) = 3.077684 × sqrt(2) × 0.1
    assert a[1] == pytest.approx(3.077684 * np.sqrt(2.0) * 0.1, rel=1e-6)
    # an over-estimate counts the same way: virtual = 1.05 m gives a = 0.05
    assert _bands([("g1", 1.0, 1.05 * m, m, 0.0)], [1.0])[0][0] == pytest.approx(0.05, rel=1e-12)
    # in sample with leverage 0.5: r = m − 0.95 m, r/(1 − h) = 0.1 m, v_loo = 0.9 m: a = 1/0.9 − 1
    a, _, rows = _bands([("g1", 1.0, 0.95 * m, m, 0.5)], [1.0])
    assert a[0] == pytest.approx(1 / 0.9 - 1, rel=1e-12) and not rows[0]["out_of_sample"] and rows[0]["leverage"] == 0.5


def test_each_station_by_its_position_between_and_beyond_the_gauges():
    m = MEASURED
    gauges = [("g1", 1.0, m / 1.1, m, 0.0), ("g3", 3.0, m / 1.05, m, 0.0), ("g2", 2.0, 1.03 * m, m, 0.0),
              ("g4", 3.5, m.copy(), m, 0.0)]  # given out of order: sorted by position
    a, bands, _ = _bands(gauges, [0.5, 1.0, 1.5, 2.0, 2.5, 3.25, 3.5, 3.8])
    # the prediction where no gauge measured: t(0.9, 4 dof) = 1.533206, × sqrt(1 + 1/4), × rms(0.10, 0.03, 0.05, 0)
    predicted = 1.533206 * np.sqrt(1.25) * np.sqrt((0.10**2 + 0.03**2 + 0.05**2 + 0.0) / 4)
    assert predicted == pytest.approx(0.09922, abs=1e-5)
    # beyond: the largest and the prediction; at a gauge: its own; between: the larger of the two and the
    # prediction; never below the floor
    assert a == pytest.approx([0.10, 0.10, 0.10, 0.03, predicted, predicted, BAND_FLOOR, 0.10], rel=1e-6)
    assert "at 2.5 m: the larger of the gauges at 2 and 3 m and the prediction 0.0992" in bands[4].method
    assert "beyond the outermost gauges" in bands[0].method and "leave-one-gauge-out" in bands[0].method


def test_a_gauge_without_cycles_gives_no_band():
    flat = np.zeros(100)
    bands, rows = gauge_bands([("g1", 1.0, flat, flat, 0.0)], [1.0], exponents=(3.0,), n_eq=10.0)
    assert bands is None and rows[0]["half_width"] is None
    assert gauge_bands([], [1.0], exponents=(3.0,), n_eq=10.0) == (None, [])


def test_bad_band_input():
    m = MEASURED
    with pytest.raises(ValueError, match="leverage of gauge g1 must be in \\[0, 1\\), got 1.0"):
        gauge_bands([("g1", 1.0, m, m, 1.0)], [1.0], exponents=(3.0,), n_eq=10.0)
    with pytest.raises(ValueError, match="gauge g1: virtual strain has 10 samples, measured 3000"):
        gauge_bands([("g1", 1.0, m[:10], m, 0.0)], [1.0], exponents=(3.0,), n_eq=10.0)
    bad = m.copy()
    bad[7] = np.nan
    with pytest.raises(ValueError, match="strain gauge g1"):
        gauge_bands([("g1", 1.0, m, bad, 0.0)], [1.0], exponents=(3.0,), n_eq=10.0)
    with pytest.raises(ValueError, match="stations"):
        gauge_bands([("g1", 1.0, m, m, 0.0)], [], exponents=(3.0,), n_eq=10.0)
