"""The IMMS kinematics, aiding equations and filter behaviour against the virtual rig's truth."""

import numpy as np
import pytest
from simdata import NO_ERRORS, simulate

from estimator import FilterConfig, Measurements, RestCalibration, SensorSeries, build_model, calibrate_at_rest, estimate
from estimator._filter import model_arrays
from estimator._imms import least_squares_map, propagate, tof_measurement
from shm_service.rig_layouts import default_rig
from shm_service.virtual_rig import SensorErrors, SimulationSettings, VirtualRig
from shm_service.virtual_rig._kinematics import point_motion

DT = 1 / 200.0


def second_difference(x):
    """(x[k+1] − 2x[k] + x[k−1]) / dt²: error (ω dt)²/12 relative, 0.2 % at 5 Hz."""
    out = np.zeros_like(x)
    out[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / DT**2
    return out


def central_difference(x):
    out = np.zeros_like(x)
    out[1:-1] = (x[2:] - x[:-2]) / (2 * DT)
    return out


@pytest.fixture(scope="module")
def plant_run():
    """States and noise-free sensor outputs of the ideal plant during the paper's excitation."""
    vr = VirtualRig(SimulationSettings(duration=60, rest=2, ideal=True, seed=3, errors=NO_ERRORS))
    n = int(60 * 200)
    y, yd, ydd = vr._integrate_range(0, n)
    t = np.arange(n) * DT
    d, _, d_acc = vr.excitation.bearing(t)
    motions = {eta: point_motion(vr.basis, eta, y, yd, ydd, d, d_acc, 9.81) for eta in (0.0, 1.2, 2.2, 2.8, 3.8)}
    return vr, t, y, d, motions


def _zero_calibration(model):
    """No biases, offsets or noise: the propagation's mean is what these tests check."""
    nu, n_tof, n_gauge = len(model.selection.imus), len(model.selection.tofs), len(model.selection.gauges)
    return RestCalibration(rest_end=0.0, rested=False, bias_D=np.zeros(3), bias_imu=np.zeros((nu, 3)), noise_D=np.zeros(3),
                           noise_imu=np.zeros((nu, 3)), tof_offset=np.zeros(n_tof), tof_std=np.zeros(n_tof),
                           strain_offset=np.zeros(n_gauge), strain_std=np.zeros(n_gauge), bearing_std=float("nan"))


def _rates(model, x, fD, wD, fj, wj):
    """State derivative the model's propagation implies (tiny step)."""
    arrays = model_arrays(model, _zero_calibration(model), FilterConfig(max_step_s=1.0))
    active = np.ones(len(model.imu_eta), dtype=np.bool_)
    h = 1e-7
    xn, _, _ = propagate(arrays, x, h, fD, wD, fj, wj, active, least_squares_map(arrays, active))
    return (xn - x) / h


def test_rigid_kinematics_match_finite_differences_of_truth(plant_run):
    vr, t, y, d, motions = plant_run
    model = build_model(vr.nominal_rig, peripheral="gyro")
    layout = model.state_layout
    D = motions[0.0]
    acc_d_fd = second_difference(d)
    phi_rate_fd = central_difference(y[:, 0])
    errors_acc, errors_rate = [], []
    for k in range(500, t.size - 500, 97):
        x = np.zeros(layout.size)
        x[layout.phi] = y[k, 0]
        rates = _rates(model, x, np.array([D.specific_force_x[k], D.specific_force_y[k]]), D.rate[k],
                       np.zeros((4, 2)), np.zeros(4))
        # ḋ⁺ − ḋ over the tiny step is d̈ · h; the state rate of ḋ is d̈ = sin φ f_x + cos φ f_y.
        errors_acc.append(rates[layout.d_rate] - acc_d_fd[k])
        errors_rate.append(rates[layout.phi] - phi_rate_fd[k])
    scale_acc = np.abs(acc_d_fd[500:-500]).max()
    assert scale_acc > 0.1
    assert np.abs(errors_acc).max() < 2e-3 * scale_acc
    assert np.abs(errors_rate).max() < 2e-3 * np.abs(phi_rate_fd).max()


def test_gyro_relation_matches_slope_rates_of_truth(plant_run):
    # Eq. (9): ω_j − ω_D = Σ ḃ s'_j. With ν = Γ the least squares reproduces each sensor's rate.
    vr, t, y, d, motions = plant_run
    model = build_model(vr.nominal_rig, peripheral="gyro")
    D = motions[0.0]
    worst, scale = 0.0, 0.0
    for k in range(500, t.size - 500, 131):
        wj = np.array([motions[eta].rate[k] for eta in model.imu_eta])
        x = np.zeros(model.state_size)
        rates = _rates(model, x, np.zeros(2), D.rate[k], np.zeros((4, 2)), wj)
        bdot = rates[model.state_layout.b]
        slope_rate_fd = np.array([central_difference(motions[eta].slope_angle)[k] for eta in model.imu_eta])
        worst = max(worst, np.abs(model.units.slope(model.imu_eta) @ bdot - slope_rate_fd).max())
        scale = max(scale, np.abs(slope_rate_fd).max())
    assert scale > 1e-3
    assert worst < 5e-3 * scale


def test_accelerometer_relation_matches_deflection_accelerations(plant_run):
    # Eq. (8) per sensor: Δ̈_j = f_jζ − f_Dζ − ω̇ η_j + ω² Δ_j, with f_jζ = sin α_j f_jx + cos α_j f_jy.
    vr, t, y, d, motions = plant_run
    model = build_model(vr.nominal_rig, peripheral="acc")
    layout = model.state_layout
    S = model.units.shape(model.imu_eta)
    D = motions[0.0]
    omega_dot = central_difference(D.rate)
    fd = {eta: second_difference(motions[eta].lateral) for eta in model.imu_eta}
    err_tilt, err_no_tilt, reference = [], [], []
    for k in range(500, t.size - 500, 37):
        lateral = np.array([motions[eta].lateral[k] for eta in model.imu_eta])
        fj = np.array([[motions[eta].specific_force_x[k], motions[eta].specific_force_y[k]] for eta in model.imu_eta])
        fD = np.array([D.specific_force_x[k], D.specific_force_y[k]])
        ddelta_fd = np.array([fd[eta][k] for eta in model.imu_eta])
        x = np.zeros(layout.size)
        x[layout.b] = np.linalg.solve(S, lateral)
        rates = _rates(model, x, fD, D.rate[k], fj, np.zeros(4))
        err_tilt.append(S @ rates[layout.v] - omega_dot[k] * model.imu_eta - ddelta_fd)
        # The same with the sensors taken as aligned with the body frame (α_j = 0): the tilt term is lost.
        x[layout.b] = 0.0
        rates = _rates(model, x, fD, D.rate[k], fj, np.zeros(4))
        err_no_tilt.append(S @ rates[layout.v] - omega_dot[k] * model.imu_eta + D.rate[k] ** 2 * lateral - ddelta_fd)
        reference.append(ddelta_fd)
    rms = lambda a: np.sqrt(np.mean(np.square(a)))  # noqa: E731
    assert rms(reference) > 0.05
    assert rms(err_tilt) < 0.03 * rms(reference)
    # g·α_j is as large as the elastic accelerations themselves: dropping it is a gross error.
    assert rms(err_no_tilt) > 5 * rms(err_tilt)


def test_tof_model_and_jacobian(plant_run):
    vr, t, y, d, motions = plant_run
    model = build_model(vr.nominal_rig)
    layout = model.state_layout
    ix = layout.index
    rig = vr.nominal_rig
    S = model.units.shape(model.tof_eta)
    S1 = model.units.slope(model.tof_eta)
    worst = 0.0
    for k in range(500, t.size - 500, 173):
        x = np.zeros(layout.size)
        x[layout.d], x[layout.phi] = d[k], y[k, 0]
        x[layout.b] = np.linalg.solve(S, [motions[eta].lateral[k] for eta in model.tof_eta])
        for j, eta in enumerate(model.tof_eta):
            m = motions[eta]
            exact = (rig.reflector_distance - m.inertial_zeta[k]) / np.cos(y[k, 0] + m.slope_angle[k])
            rho, H = tof_measurement(ix, x, eta, S[j], S1[j], rig.reflector_distance)
            worst = max(worst, abs(rho - exact))
            numeric = np.zeros_like(H)
            for i in range(x.size):
                step = np.zeros_like(x)
                step[i] = 1e-6
                numeric[i] = (tof_measurement(ix, x + step, eta, S[j], S1[j], rig.reflector_distance)[0]
                              - tof_measurement(ix, x - step, eta, S[j], S1[j], rig.reflector_distance)[0]) / 2e-6
            np.testing.assert_allclose(H, numeric, rtol=1e-6, atol=1e-9)
    # The remaining difference is the slope of modes beyond Γ and the foreshortening: sub-millimetre.
    assert worst < 5e-4


def test_strain_model_matches_simulated_gauges(plant_run):
    # Eq. (19): ε = −(h*/2) Σ s''_χ b_χ, with b from the deflection along the beam.
    vr, t, y, d, motions = plant_run
    model = build_model(vr.nominal_rig)
    grid = np.linspace(0.05, 4.0, 80)
    q = y[:, 1:]
    w = q @ vr.basis.evaluate(grid, 0).T
    b = np.linalg.lstsq(model.units.shape(grid), w.T, rcond=None)[0].T
    predicted = b @ model.strain_matrix().T
    exact = np.column_stack([-0.001 * point_motion(vr.basis, eta, y, y, y, d, d, 9.81).curvature for eta in model.gauge_eta])
    corr = [np.corrcoef(predicted[:, i], exact[:, i])[0, 1] for i in range(exact.shape[1])]
    assert min(corr) > 0.95


def _score(result, truth, after):
    i = np.searchsorted(truth["t"], result.t)
    m = result.t >= after
    return (np.degrees(np.sqrt(np.mean((result.phi - truth["phi"][i])[m] ** 2))),
            np.sqrt(np.mean((result.e - truth["e"][i])[m] ** 2)))


@pytest.fixture(scope="module")
def realistic_run():
    return simulate(duration=120.0, rest=20.0, seed=7, ideal=False)


def test_filter_tracks_the_realistic_rig(realistic_run):
    meas, truth, vr = realistic_run
    for peripheral, e_bar in (("gyro", 2e-3), ("acc", 3e-3)):
        result = estimate(meas, build_model(vr.nominal_rig, peripheral=peripheral))
        phi_rmse, e_rmse = _score(result, truth, 20.0)
        assert phi_rmse < 0.02 and e_rmse < e_bar, (peripheral, phi_rmse, e_rmse)
        assert np.all(np.isfinite(result.x))


def test_rest_phase_calibrates_biases():
    errors = SensorErrors(gyro_bias=0.02, accel_bias=0.1, gyro_bias_instability=0.0, accel_bias_instability=0.0)
    meas, truth, vr = simulate(duration=45.0, rest=15.0, seed=2, ideal=True, errors=errors)
    first_motion = vr.excitation.bearing.components[0].start
    model = build_model(vr.nominal_rig)
    cal = calibrate_at_rest(meas, model)
    assert cal.rested and 10.0 <= cal.rest_end <= first_motion
    np.testing.assert_allclose(cal.bias_D[2], vr._gyro_bias[0, 2], atol=1e-4)
    np.testing.assert_allclose(cal.bias_D[:2], vr._accel_bias[0, :2], atol=2e-3)
    np.testing.assert_allclose(cal.bias_imu[:, 2], vr._gyro_bias[1:, 2], atol=1e-4)


def test_without_rest_the_gyro_bias_at_d_is_estimated():
    errors = SensorErrors(gyro_bias=0.0, gyro_bias_instability=0.0)
    meas, truth, vr = simulate(duration=90.0, rest=0.0, seed=5, ideal=True, errors=errors)
    # Give D alone a bias the calibration cannot see.
    D = meas.imu["D"]
    biased = SensorSeries(D.times, D.values + np.array([0.0, 0.0, 2e-3]))
    meas = Measurements(imu={**meas.imu, "D": biased}, tof=meas.tof, strain=meas.strain, bearing=meas.bearing)
    model = build_model(vr.nominal_rig)
    # A rest phase is required to be longer than the recording: nothing is calibrated.
    result = estimate(meas, model, FilterConfig(q_beta=1e-9, rest_min_s=1e3))
    assert not result.calibration.rested
    estimated_bias = result.x[-1, model.state_layout.bias_d]
    assert estimated_bias == pytest.approx(2e-3, rel=0.3)


def _drop_after(meas, name, t_cut):
    s = meas.imu[name]
    keep = s.times < t_cut
    return Measurements(imu={**meas.imu, name: SensorSeries(s.times[keep], s.values[keep])}, tof=meas.tof,
                        strain=meas.strain, bearing=meas.bearing)


def test_silent_imu_degrades_without_divergence(realistic_run):
    meas, truth, vr = realistic_run
    model = build_model(vr.nominal_rig)
    result = estimate(_drop_after(meas, "s2", 60.0), model)
    degraded = result.diagnostics["degraded_imus"]
    assert [d["sensor"] for d in degraded] == ["/imu/s2"] and not degraded[0]["active"]
    phi_rmse, e_rmse = _score(result, truth, 20.0)
    assert np.all(np.isfinite(result.x))
    assert phi_rmse < 0.05 and e_rmse < 0.01


def test_nan_and_outlier_samples_are_rejected(realistic_run):
    meas, truth, vr = realistic_run
    model = build_model(vr.nominal_rig)
    clean = estimate(meas, model)
    rng = np.random.default_rng(0)
    tof = meas.tof["s3"]
    spikes = rng.choice(np.nonzero(tof.times > 30)[0], 25, replace=False)
    tof_values = tof.values.copy()
    tof_values[spikes] += 0.3  # a reflection off something else
    D = meas.imu["D"]
    D_values = D.values.copy()
    D_values[rng.choice(np.nonzero(D.times > 30)[0], 40, replace=False), 1] = np.nan
    dirty = Measurements(imu={**meas.imu, "D": SensorSeries(D.times, D_values)},
                         tof={**meas.tof, "s3": SensorSeries(tof.times, tof_values)}, strain=meas.strain, bearing=meas.bearing)
    result = estimate(dirty, model)
    assert result.diagnostics["aiding"]["/tof/s3"]["rejected"] >= 25
    assert np.all(np.isfinite(result.x))
    _, e_clean = _score(clean, truth, 20.0)
    _, e_dirty = _score(result, truth, 20.0)
    assert e_dirty < 1.2 * e_clean + 1e-4


def test_tof_samples_off_the_imu_grid_are_applied_at_their_own_time():
    errors = NO_ERRORS.model_copy(update={"tof_time_offset": 0.003, "tof_noise": 1e-4, "gyro_noise": 2e-4, "accel_noise": 0.003})
    meas, truth, vr = simulate(duration=90.0, rest=10.0, seed=3, ideal=True, errors=errors)
    model = build_model(vr.nominal_rig, gauges=0)  # without gauges the ToFs carry the deformation
    on_time = estimate(meas, model)
    snapped = Measurements(
        imu=meas.imu, strain=meas.strain,
        tof={k: SensorSeries(np.round(v.times * 200) / 200, v.values) for k, v in meas.tof.items()},
        bearing=SensorSeries(np.round(meas.bearing.times * 200) / 200, meas.bearing.values),
    )
    snapped_result = estimate(snapped, model)
    assert not np.allclose(meas.tof["s1"].times * 200, np.round(meas.tof["s1"].times * 200))
    phi_own, e_own = _score(on_time, truth, 10.0)
    phi_snap, e_snap = _score(snapped_result, truth, 10.0)
    assert phi_own < phi_snap


def test_model_refuses_bad_configurations():
    rig = default_rig()
    with pytest.raises(ValueError, match="Γ=5 unit deformations need at least 5 peripheral IMUs"):
        build_model(rig, modes=5)
    with pytest.raises(ValueError, match="unknown sensor names"):
        build_model(rig, imus=("s1", "s2", "s3", "x9"))
    with pytest.raises(ValueError, match="peripheral='laser'"):
        build_model(rig, peripheral="laser")
    with pytest.raises(ValueError, match="aided unit deformations \\[7\\]"):
        build_model(rig, gauges=2, aided=(7,))
    no_d = rig.model_dump(mode="json")
    no_d["sensors"] = [s for s in no_d["sensors"] if s["name"] != "D"]
    from estimator import parse_rig

    with pytest.raises(ValueError, match="no IMU named 'D'"):
        build_model(parse_rig(no_d))


@pytest.mark.parametrize("peripheral", ["gyro", "acc"])
def test_kernels_read_every_offset_from_the_layout(peripheral):
    """The same model run through a layout without φ and β_D (a support that fixes φ ≡ 0) gives,
    at φ = 0, ω_D = 0 and β_D = 0, exactly the propagation and ToF Jacobian of the full layout on
    the states both have: no offset is hard-wired in the compiled kernels."""
    from contract import StateLayout

    model = build_model(default_rig(), peripheral=peripheral)
    full = model.state_layout
    fixed = StateLayout(full.peripheral, full.gamma, full.nu, attitude=False, imu_names=full.imu_names)
    common = [full.position(name) for name in fixed.names]
    assert len(common) == full.size - 2
    arrays = model_arrays(model, _zero_calibration(model), FilterConfig())
    rng = np.random.default_rng(5)
    x_full = np.zeros(full.size)
    x_full[common] = rng.normal(scale=1e-2, size=fixed.size)
    x_fixed = x_full[common].copy()
    nu = full.nu
    active = np.ones(nu, dtype=np.bool_)
    inputs = (np.array([-9.7, 0.3]), 0.0, rng.normal(scale=0.1, size=(nu, 2)) + [-9.81, 0.0], rng.normal(scale=1e-2, size=nu))
    results = []
    for layout, x in ((full, x_full), (fixed, x_fixed)):
        m = arrays._replace(index=layout.index)
        xn, F, Q = propagate(m, x, 0.005, *inputs, active, least_squares_map(m, active))
        rho, H = tof_measurement(layout.index, x, model.tof_eta[1], arrays.tof_S[1], arrays.tof_S1[1],
                                 model.rig.reflector_distance)
        results.append((xn, F, Q, rho, H))
    (xn_a, F_a, Q_a, rho_a, H_a), (xn_b, F_b, Q_b, rho_b, H_b) = results
    assert np.abs(xn_a[full.b] - x_full[full.b]).max() > 1e-6  # b moved: not a trivial comparison
    np.testing.assert_array_equal(xn_a[common], xn_b)
    np.testing.assert_array_equal(F_a[np.ix_(common, common)], F_b)
    np.testing.assert_allclose(Q_a[np.ix_(common, common)], Q_b, rtol=1e-12, atol=1e-30)
    assert rho_a == rho_b
    np.testing.assert_array_equal(H_a[common], H_b)
