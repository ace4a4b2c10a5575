"""Both bending planes in one filter (beam.bending = "biaxial"): the state layout, the kinematics
of gyro y and accel z, gauges around the section, the per-plane observability check, and the
biaxial mast of the virtual rig estimated in both planes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from example_mast import planar_mast_data
from simdata import simulate

from contract import StateLayout, parse_rig
from estimator import FilterConfig, RestCalibration, build_model, estimate
from estimator._filter import model_arrays
from estimator._imms import least_squares_map, propagate

MAST = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"
GAUGE_HEIGHTS = (0.5, 4.0, 9.0, 14.0)


def biaxial_mast(*, xi_gauges: bool = True) -> dict:
    """The example mast bending in both planes, with a gauge pair (0° and 90°) at each of four heights."""
    data = json.loads(MAST.read_text())
    data["beam"]["bending"] = "biaxial"
    sensors = [s for s in data["sensors"] if s["kind"] != "strain"]
    for i, eta in enumerate(GAUGE_HEIGHTS):
        sensors.append({"name": f"g{i + 1}", "kind": "strain", "position": eta})
        sensors.append({"name": f"g{i + 1}x", "kind": "strain", "position": eta, "angle_deg": 90 if xi_gauges else 180})
    data["sensors"] = sensors
    return data


def tube(*, gravity: float = 0.0, sensors=None) -> dict:
    """A 3 m uniform steel tube, clamped and biaxial, IMUs at 1, 2, 3 m and gauges at 0° and 90°."""
    return {
        "beam": {"length": 3.0, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": "biaxial",
                 "sections": [{"position": 0.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004},
                              {"position": 3.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}]},
        "gravity": gravity, "support": "clamped", "orientation": "standing",
        "sensors": sensors or [{"name": "D", "kind": "imu", "position": 0.0},
                               *({"name": f"s{k}", "kind": "imu", "position": float(k)} for k in (1, 2, 3)),
                               {"name": "g1", "kind": "strain", "position": 0.5},
                               {"name": "g1x", "kind": "strain", "position": 0.5, "angle_deg": 90},
                               {"name": "g2", "kind": "strain", "position": 1.5},
                               {"name": "g2x", "kind": "strain", "position": 1.5, "angle_deg": 90},
                               {"name": "g3", "kind": "strain", "position": 2.2, "angle_deg": 45}],
        "truth_stations": [1.5, 3.0],
    }


# -- the state layout ----------------------------------------------------------------------------


def test_a_planar_layout_is_unchanged_and_the_xi_block_follows_the_zeta_block():
    planar = StateLayout("gyro", 2, 2, attitude=False, residual=1)
    assert planar == StateLayout("gyro", 2, 2, attitude=False, residual=1, gamma_xi=0)
    assert planar.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "r1", "vr1", "gyro_bias_1", "gyro_bias_2")
    assert planar.b_xi == slice(0, 0) and planar.modal_xi == slice(0, 0) and planar.peripheral_bias_xi is None
    gyro = StateLayout("gyro", 2, 2, attitude=False, residual=1, gamma_xi=3, residual_xi=1)
    assert gyro.names == ("d", "h", "d_rate", "h_rate", "b1", "b2", "r1", "bxi1", "bxi2", "bxi3", "rxi1", "vr1", "vrxi1",
                          "gyro_bias_1", "gyro_bias_2", "gyro_y_bias_1", "gyro_y_bias_2")
    assert (gyro.b_xi, gyro.modal_xi, gyro.residual_rates_xi) == (slice(7, 10), slice(7, 11), slice(12, 13))
    assert gyro.peripheral_bias_xi == slice(15, 17) and gyro.size == 17
    acc = StateLayout("acc", 1, 1, attitude=False, gamma_xi=2)
    assert acc.names == ("d", "h", "d_rate", "h_rate", "b1", "bxi1", "bxi2", "v1", "vxi1", "vxi2")
    assert acc.v_xi == slice(8, 10)
    x = np.arange(acc.size, dtype=float)
    np.testing.assert_array_equal(acc.b_xi_of(x), [5.0, 6.0])


def test_bad_xi_layouts_are_refused():
    with pytest.raises(ValueError, match="residual_xi=1 needs gamma_xi"):
        StateLayout("gyro", 2, 2, attitude=False, residual_xi=1)
    with pytest.raises(ValueError, match="gamma_xi=2 with an attitude state"):
        StateLayout("gyro", 2, 2, gamma_xi=2)
    with pytest.raises(ValueError, match="gamma_xi=-1"):
        StateLayout("gyro", 2, 2, attitude=False, gamma_xi=-1)


# -- the kinematics of the xi plane --------------------------------------------------------------


def _one_step(peripheral: str, bxi_rate: float, bxi_accel: float):
    """One propagation step of a Γ = Γξ = 1 tube model from rest with ξ readings made for the
    given ḃξ1 (gyro y) or b̈ξ1 (accel z); returns (model, x before, x after, dt)."""
    rig = parse_rig(tube())
    model = build_model(rig, peripheral=peripheral, modes=1, imus=3, gauges=None, residual_modes=0)
    nu = len(model.selection.imus)
    zeros = np.zeros((nu, 5))
    cal = RestCalibration(0.0, True, np.zeros(5), zeros, np.full(5, 1e-3), np.full((nu, 5), 1e-3), np.zeros(0), np.zeros(0),
                          np.zeros(len(model.selection.gauges)), np.full(len(model.selection.gauges), 1e-6), float("nan"))
    m = model_arrays(model, cal, FilterConfig())
    s_xi, s1_xi = model.units_xi.shape(model.imu_eta)[:, 0], model.units_xi.slope(model.imu_eta)[:, 0]
    fj = np.zeros((nu, 4))
    fj[:, 3] = -s1_xi * bxi_rate  # gyro y is minus the ξ tangent's rate
    fj[:, 2] = s_xi * bxi_accel  # accel z: the ξ acceleration (no gravity, no tilt at rest)
    active = np.ones(nu, dtype=np.bool_)
    x = np.zeros(model.state_size)
    dt = 0.005
    xn, _, _ = propagate(m, x, dt, np.zeros(3), 0.0, fj, np.zeros(nu), active, least_squares_map(m, active))
    return model, x, xn, dt


def test_gyro_y_turns_the_xi_unit_deformation_with_the_contracts_minus_sign():
    model, _, xn, dt = _one_step("gyro", 0.2, 0.0)
    layout = model.state_layout
    assert xn[layout.b_xi][0] == pytest.approx(0.2 * dt, rel=1e-12)
    np.testing.assert_array_equal(xn[layout.b], 0.0)  # ζ sees nothing of it


def test_accel_z_accelerates_the_xi_unit_deformation_as_accel_y_does_zeta():
    model, _, xn, dt = _one_step("acc", 0.0, 3.0)
    layout = model.state_layout
    assert xn[layout.v_xi][0] == pytest.approx(3.0 * dt, rel=1e-12)
    assert xn[layout.b_xi][0] == pytest.approx(0.5 * 3.0 * dt**2, rel=1e-12)
    np.testing.assert_array_equal(xn[layout.b], 0.0)


def test_a_gauge_at_an_angle_sees_both_planes():
    rig = parse_rig(tube())
    model = build_model(rig, modes=2, gauges=None)
    K = model.strain_matrix()
    n_zeta, n_xi = model.modal.count, model.modal_xi.count
    assert K.shape == (5, n_zeta + n_xi)
    radius = 0.05
    at = {name: i for i, name in enumerate(model.selection.gauges)}
    for name, angle in (("g1", 0.0), ("g1x", 90.0), ("g3", 45.0)):
        eta = next(s.position for s in rig.sensors if s.kind == "strain" and s.name == name)
        theta = math.radians(angle)
        expected_zeta = -radius * math.cos(theta) * model.modal.curvature(np.array([eta]))[0]
        expected_xi = -radius * math.sin(theta) * model.modal_xi.curvature(np.array([eta]))[0]
        np.testing.assert_allclose(K[at[name], :n_zeta], expected_zeta, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(K[at[name], n_zeta:], expected_xi, rtol=1e-12, atol=1e-15)


# -- the per-plane observability check -------------------------------------------------------------


def test_a_biaxial_rig_whose_xi_plane_no_gauge_holds_is_refused_naming_the_plane():
    rig = parse_rig(biaxial_mast(xi_gauges=False))  # the pairs at 0° and 180°: ζ faces only
    with pytest.raises(ValueError, match=r"the xi plane is not observed: .*no strain gauge sits at an angle off 0/180"):
        build_model(rig, modes=4, gauges=None)


def test_too_few_xi_aiding_rows_are_refused_naming_the_xi_plane_and_its_unit_deformations():
    data = biaxial_mast()
    data["sensors"] = [s for s in data["sensors"] if s["name"] not in ("g3x", "g4x")]  # two ξ gauges for Γξ = 4
    with pytest.raises(ValueError, match=r"the xi plane: the sensors cannot observe bxi"):
        build_model(parse_rig(data), modes=4, gauges=None)
    model = build_model(parse_rig(data), modes=4, modes_xi=2, gauges=None)  # Γξ = 2 is held by the two
    assert model.gamma_xi == 2 and model.selection.aided_xi == (1, 2)


def test_modes_xi_on_a_planar_beam_is_refused():
    data = planar_mast_data()
    with pytest.raises(ValueError, match="modes_xi=2: unit deformations in ξ need a beam that bends in both planes"):
        build_model(parse_rig(data), modes=4, modes_xi=2)


# -- the biaxial mast of the virtual rig -------------------------------------------------------------


def _tip_errors(wind: dict, duration: float = 90.0):
    rig = parse_rig(biaxial_mast())
    meas, truth, _ = simulate(duration, rest=10.0, ideal=False, rig=rig, seed=3, excitation="ambient", support="clamped",
                              orientation="standing", length=20.0, wind_direction=wind)
    model = build_model(rig, peripheral="gyro", modes=4, gauges=None)
    res = estimate(meas, model)
    idx = np.clip(np.searchsorted(truth["t"], res.t), 0, truth["t"].size - 1)
    ok = (np.abs(truth["t"][idx] - res.t) < 1e-6) & (res.t > res.calibration.rest_end + 5.0)
    i = idx[ok]

    def rms(a):
        return float(np.sqrt(np.mean(np.square(a))))

    return {key: (rms(est[ok] - truth[key][i]), rms(truth[key][i])) for key, est in (("e", res.e), ("e_xi", res.e_xi))}


def test_the_biaxial_mast_in_a_veering_wind_is_estimated_in_both_planes_within_5_percent():
    errors = _tip_errors({"mean_deg": 25.0, "veer_deg": 30.0, "period_s": 60.0})
    for key, (err, ref) in errors.items():
        assert ref > 1e-3, key  # both planes move
        assert err <= 0.05 * ref, (key, err, ref)


def test_wind_across_zeta_is_estimated_in_xi_and_leaves_zeta_at_noise():
    errors = _tip_errors({"mean_deg": 90.0, "veer_deg": 0.0}, duration=60.0)
    err_xi, ref_xi = errors["e_xi"]
    err_zeta, ref_zeta = errors["e"]
    assert ref_zeta < 1e-12 and ref_xi > 1e-3  # the truth: ξ only
    assert err_xi <= 0.05 * ref_xi
    assert err_zeta <= 0.01 * ref_xi  # the estimate of ζ: noise, far below the ξ motion
