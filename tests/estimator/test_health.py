"""The filter's health check (pure functions): physical bounds, innovations, refusals, and the
state a restarted filter begins from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator import (
    HealthConfig,
    Measurements,
    SensorSeries,
    aiding_window,
    assess_health,
    physical_bounds,
    restart_state,
)

CHANNELS = ["/tof/s1", "/tof/s2", "/strain/g1", "/bearing/displacement", "pseudo:h", "pseudo:h_rate"]


def _window(accepted, rejected, nis):
    zero = (np.zeros(6), np.zeros(6), np.zeros(6))
    return aiding_window(CHANNELS, zero, (np.array(accepted, float), np.array(rejected, float), np.array(nis, float)))


def test_bounds_follow_the_beam_length():
    b = physical_bounds(4.0)
    assert (b.d_max_m, b.phi_max_rad, b.tip_max_m) == (12.0, math.pi / 2, 4.0)
    with pytest.raises(ValueError, match="beam_length_m"):
        physical_bounds(0.0)


def test_the_signs_of_divergence():
    bounds = physical_bounds(4.0)
    z = np.zeros(3)
    ok = _window([50, 50, 200, 50, 200, 200], [0, 1, 0, 0, 0, 0], [25, 30, 100, 20, 0, 0])
    assert ok.channels == tuple(CHANNELS[:4]) and ok.mean_nis == pytest.approx(175 / 350)  # pseudo-measurements left out
    assert not assess_health(ok, z, z, z, bounds).diverged
    v = assess_health(ok, np.array([0.0, 12.5, 0.0]), z, z, bounds)
    assert v.diverged and v.kind == "bounds" and "d = 12.5 m" in v.reason
    assert assess_health(ok, z, np.array([0.0, -1.6, 0.0]), z, bounds).kind == "bounds"
    assert assess_health(ok, z, z, np.array([4.5, 0, 0]), bounds).kind == "bounds"
    assert assess_health(ok, np.array([np.nan, 0, 0]), z, z, bounds).kind == "nonfinite"
    grown = _window([50, 50, 200, 50, 0, 0], [0, 0, 0, 0, 0, 0], [500, 500, 2000, 500, 0, 0])  # mean NIS 10
    assert assess_health(grown, z, z, z, bounds).kind == "nis"
    # the gate refuses every ToF and the bearing (d ran away) while the gauges still agree
    refused = _window([0, 0, 200, 0, 0, 0], [60, 60, 0, 60, 0, 0], [0, 0, 40, 0, 0, 0])
    v = assess_health(refused, z, z, z, bounds)
    assert v.diverged and v.kind == "rejections" and "/tof/s1, /tof/s2, /bearing/displacement" in v.reason
    # one sensor refused for good is a broken sensor, not a diverged filter
    one = _window([0, 60, 200, 60, 0, 0], [60, 0, 0, 0, 0, 0], [0, 30, 40, 30, 0, 0])
    assert not assess_health(one, z, z, z, bounds).diverged
    few = _window([0, 0, 0, 0, 0, 0], [5, 5, 0, 5, 0, 0], [0] * 6)  # too few updates to judge
    assert not assess_health(few, z, z, z, bounds).diverged
    assert not assess_health(None, z, z, z, bounds).diverged


def test_aiding_window_refuses_mismatched_or_backward_counters():
    with pytest.raises(ValueError, match="shape"):
        aiding_window(CHANNELS, (np.zeros(6),) * 3, (np.zeros(5),) * 3)
    with pytest.raises(ValueError, match="backwards"):
        aiding_window(CHANNELS, (np.ones(6),) * 3, (np.zeros(6),) * 3)
    with pytest.raises(ValueError):
        HealthConfig(reject_fraction=1.5)


def test_a_restart_begins_from_the_current_measurements():
    from estimator import RestCalibration, build_model
    from shm_service.rig_layouts import default_rig

    model = build_model(default_rig("benchmark"), peripheral="gyro", modes=4, imus=4, tofs=4, gauges=4)
    g = model.rig.gravity
    nu, ntof, ng = len(model.selection.imus), len(model.selection.tofs), len(model.selection.gauges)
    cal = RestCalibration(rest_end=0.0, rested=True, bias_D=np.array([0.01, -0.02, 0.0]), bias_imu=np.zeros((nu, 3)),
                          noise_D=np.full(3, 0.01), noise_imu=np.full((nu, 3), 0.01), tof_offset=np.zeros(ntof),
                          tof_std=np.full(ntof, 0.002), strain_offset=np.full(ng, 1e-6), strain_std=np.full(ng, 5e-7),
                          bearing_std=1e-4)
    t = np.arange(200) / 200.0
    phi, d = 0.02, 0.3
    b = np.array([0.01, -0.004, 0.002, 0.001])
    eps = model.strain_matrix() @ b + 1e-6
    f = np.column_stack([np.full(200, -g * math.cos(phi) + 0.01), np.full(200, g * math.sin(phi) - 0.02), np.zeros(200)])
    meas = Measurements(imu={"D": SensorSeries(t, f)},
                        strain={name: SensorSeries(t, np.full(200, eps[k])) for k, name in enumerate(model.selection.gauges)},
                        bearing=SensorSeries(t[::6], np.full(len(t[::6]), d)))
    x = restart_state(meas, model, cal)
    ix = model.state_layout.index
    assert x[ix.d] == pytest.approx(d) and x[ix.phi] == pytest.approx(phi, abs=1e-12)
    np.testing.assert_allclose(x[ix.b:ix.b + 4], b, rtol=1e-9, atol=1e-12)
    rest = np.delete(x, [ix.d, ix.phi, *range(ix.b, ix.b + 4)])
    assert np.all(rest == 0)
    # without the sensors, the states they would give stay 0
    assert np.all(restart_state(Measurements(imu={}), model, cal) == 0)


def test_the_gauges_that_disagree_on_their_own():
    from estimator import gauge_disagreement, gauges_beyond_basis

    # g1's own NIS is 12 (its updates accepted), the ToFs agree; the aggregate would still pass
    w = _window([50, 50, 200, 50, 0, 0], [0, 0, 0, 0, 0, 0], [50, 50, 2400, 50, 0, 0])
    assert gauges_beyond_basis(w) == ("/strain/g1",)
    assert gauge_disagreement(w, ("/strain/g1",), 30.0) == pytest.approx(12.0)
    # refused at least a tenth of the time: the gate's value (the refused NIS lies above it)
    w = _window([50, 50, 150, 50, 0, 0], [0, 0, 50, 0, 0, 0], [50, 50, 300, 50, 0, 0])
    assert gauge_disagreement(w, ("/strain/g1",), 30.0) == 30.0
    assert gauges_beyond_basis(w) == ()  # 25 % refused, a mean NIS of 2: not on its own
    # a ToF that disagrees is not a gauge; too few updates are not judged
    assert gauges_beyond_basis(_window([50, 50, 200, 50, 0, 0], [0, 0, 0, 0, 0, 0], [900, 50, 200, 50, 0, 0])) == ()
    assert gauges_beyond_basis(_window([0, 0, 10, 0, 0, 0], [0, 0, 0, 0, 0, 0], [0, 0, 1000, 0, 0, 0])) == ()
    assert gauges_beyond_basis(None) == ()
    # a channel of the window that is not asked about leaves the figure at 1
    assert gauge_disagreement(w, ("/strain/g9",), 30.0) == 1.0
    with pytest.raises(ValueError):
        HealthConfig(gauge_error_growth=1.0)
