"""The estimator's clamped configurations (the paper's fixed bearing, a standing mast) against the
virtual rig's truth and against closed forms."""

import numpy as np
import pytest
from simdata import NO_ERRORS, simulate

from contract import parse_rig
from estimator import build_model, calibrate_at_rest, estimate
from shm_service.processing.estimation import TruthSeries, score_against_truth


def _truth_series(truth) -> TruthSeries:
    return TruthSeries(truth["t"], truth["d"], truth["h"], truth["phi"], truth["e"], truth["deflection"], truth["curvature"])


def _e_rmse(result, truth) -> float:
    return score_against_truth(result, _truth_series(truth), after=result.calibration.rest_end)["rmse"]["e_m"]


def _bare_clamped_rig(**overrides):
    """A uniform clamped sheet without attached masses (gravity 0): closed forms hold."""
    description = {
        "beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": 2.1e11, "density": 7850.0},
        "gravity": 0.0,
        "reflector_distance": 0.5,
        "support": "clamped",
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]
        + [{"name": f"s{j}", "kind": "imu", "position": p} for j, p in enumerate((1.2, 2.2, 2.8, 3.8), start=1)],
    }
    description.update(overrides)
    return parse_rig(description)


def test_clamped_layout_has_no_attitude_and_carries_the_next_mode():
    model = build_model(_bare_clamped_rig(), tofs=0, gauges=0, check_observable=False)
    layout = model.state_layout
    assert layout.phi is None and layout.bias_d is None
    assert layout.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "b3", "b4", "r1", "vr1",
                            "gyro_bias_s1", "gyro_bias_s2", "gyro_bias_s3", "gyro_bias_s4")
    assert model.mode_map.unit_modes == ((1,), (2,), (3,), (4,))  # no combimode: labels b1 · mode 1 ...
    assert model.mode_map.unit_label(1) == "b1 · mode 1"
    assert model.modal.modes[-1] == (5,)
    acc = build_model(_bare_clamped_rig(), peripheral="acc", tofs=0, gauges=0, check_observable=False).state_layout
    assert acc.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "b3", "b4", "r1", "v1", "v2", "v3", "v4", "vr1")
    assert build_model(_bare_clamped_rig(), tofs=0, gauges=0, residual_modes=0, check_observable=False).state_layout.size == 12


def test_residual_mode_frequency_and_participation_match_the_cantilever_closed_form():
    # Uniform clamped–free beam, mode 5: λL = 14.137165; the support's acceleration a loads the
    # mode with p = ∫s dη / ∫s² dη (s scaled to max |s| = 1, tip positive).
    rig = _bare_clamped_rig()
    model = build_model(rig, tofs=0, gauges=0, check_observable=False)
    beam = rig.beam
    L, EI, mu = beam.length, beam.youngs_modulus * beam.width * beam.thickness**3 / 12, beam.density * beam.width * beam.thickness
    lam = 14.137165491257464 / L
    f5 = lam**2 * np.sqrt(EI / mu) / (2 * np.pi)
    assert model.modal.frequencies_hz[4][0] == pytest.approx(f5, rel=1e-4)
    x = np.linspace(0.0, L, 200_001)
    sigma = (np.cosh(lam * L) + np.cos(lam * L)) / (np.sinh(lam * L) + np.sin(lam * L))
    phi = np.cosh(lam * x) - np.cos(lam * x) - sigma * (np.sinh(lam * x) - np.sin(lam * x))
    s = phi / np.abs(phi).max() * np.sign(phi[-1])
    p_exact = np.trapezoid(s, x) / np.trapezoid(s * s, x)
    assert model.residual_participation[0] == pytest.approx(p_exact, rel=1e-3)


def test_residual_modes_are_refused_for_a_pinned_support():
    rig = _bare_clamped_rig(support="pinned")
    with pytest.raises(ValueError, match="residual modes are modelled for a clamped support"):
        build_model(rig, tofs=0, gauges=0, residual_modes=1, check_observable=False)
    with pytest.raises(ValueError, match=r"residual_modes=4 must be an integer in \[0, 3\]"):
        build_model(_bare_clamped_rig(), tofs=0, gauges=0, residual_modes=4, check_observable=False)


@pytest.fixture(scope="module")
def clamped_run():
    """50 s of the fixed bearing (paper excitation, realistic rig); seed 2 drives mode 5 (6.1 Hz)."""
    return simulate(duration=50.0, rest=10.0, seed=2, ideal=False, support="clamped")


@pytest.mark.parametrize("peripheral", ["gyro", "acc"])
def test_fixed_bearing_estimate_phi_exactly_zero_e_within_a_millimetre(clamped_run, peripheral):
    meas, truth, vr = clamped_run
    assert np.all(truth["phi"] == 0.0)
    result = estimate(meas, build_model(vr.nominal_rig, peripheral=peripheral))
    scores = score_against_truth(result, _truth_series(truth), after=result.calibration.rest_end)
    assert np.all(result.phi == 0.0) and scores["rmse"]["phi_deg"] == 0.0  # 0, not None
    assert scores["nees"]["phi"] is None
    # Measured: gyro 0.25 mm, acc 0.63 mm (the tip swings by 25 mm RMS).
    assert scores["rmse"]["e_m"] < (0.5e-3 if peripheral == "gyro" else 1e-3)
    assert result.diagnostics["rejected"] == 0


def test_without_the_residual_mode_the_driven_fifth_mode_aliases_into_b(clamped_run):
    """The clamp passes the 6.1 Hz drive to mode 5, which the least squares of four gyros reads
    as b1..b4 (−7.7× its tip deflection for this layout): carried as a state it is told apart."""
    meas, truth, vr = clamped_run
    with_residual = _e_rmse(estimate(meas, build_model(vr.nominal_rig)), truth)
    without = _e_rmse(estimate(meas, build_model(vr.nominal_rig, residual_modes=0)), truth)
    assert without > 10 * with_residual  # measured 8.7 mm against 0.25 mm


def test_standing_mast_rest_calibration_expects_plus_g_and_estimates_within_a_millimetre():
    meas, truth, vr = simulate(duration=50.0, rest=10.0, seed=2, ideal=False, support="clamped",
                               orientation="standing", length=1.5)
    model = build_model(vr.nominal_rig)
    assert model.gravity_eta == pytest.approx(-9.81)
    calibration = calibrate_at_rest(meas, model)
    assert meas.imu["D"].values[: 400, 0].mean() == pytest.approx(9.81, abs=0.2)  # accel x reads +g at rest
    # Offsets of a few 0.01 m/s² (bias, 1 % scale factor on g, misalignment), not 2 g: the rest
    # phase expects +g along x.
    assert np.abs(calibration.bias_D[0]) < 0.5 and np.all(np.abs(calibration.bias_imu[:, 0]) < 0.5)
    for peripheral, bar in (("gyro", 0.5e-3), ("acc", 1e-3)):  # measured 0.09 mm and 0.33 mm
        result = estimate(meas, build_model(vr.nominal_rig, peripheral=peripheral))
        assert np.all(result.phi == 0.0)
        assert _e_rmse(result, truth) < bar


def test_standing_mast_rest_biases_vanish_without_sensor_errors():
    meas, truth, vr = simulate(duration=14.0, rest=12.0, seed=1, ideal=True, errors=NO_ERRORS, support="clamped",
                               orientation="standing", length=1.5)
    calibration = calibrate_at_rest(meas, build_model(vr.nominal_rig, peripheral="acc"))
    assert calibration.rested
    np.testing.assert_allclose(calibration.bias_D[:2], 0.0, atol=1e-6)
    np.testing.assert_allclose(calibration.bias_imu[:, :2], 0.0, atol=1e-6)
