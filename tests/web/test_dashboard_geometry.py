"""The dashboard's geometry and input checks, without a browser."""

from __future__ import annotations

import math

import numpy as np
import pytest

import estimator
from shm_service.rig_layouts import default_rig
from web import BeamState, Dashboard, centreline, parse_state, ribbon, ribbon_faces, tangent_angle, tof_rays, to_world
from web._data import normalise_alarm, normalise_window, spectrum_plot, windows_from_trend_rows
from web._view import _nice

from dashboard_feeder import FakeService


class Parabola:
    """One unit deformation s(η) = (η/4)², s'(η) = η/8 (a known shape for exact coordinates)."""

    count = 1

    def shape(self, eta):
        eta = np.atleast_1d(np.asarray(eta, dtype=float))
        return ((eta / 4.0) ** 2)[:, None]

    def slope(self, eta):
        eta = np.atleast_1d(np.asarray(eta, dtype=float))
        return (eta / 8.0)[:, None]


PHI = math.atan2(0.6, 0.8)  # cos φ = 0.8, sin φ = 0.6


def test_ribbon_vertices_for_known_b_and_phi_are_exact():
    # x = [d, h, d_rate, h_rate, phi, b1, gyro_bias]
    state = parse_state([0.2, 0.1, 9.0, 9.0, PHI, 0.5, 7.0], 1)
    line = centreline(state, Parabola(), np.array([0.0, 2.0, 4.0]))
    # η_I = h + cos φ η − sin φ Δ, ζ_I = d + sin φ η + cos φ Δ with Δ = 0.5 (η/4)²
    np.testing.assert_allclose(line, [[0.1, 0.2], [1.625, 1.5], [3.0, 3.0]], atol=1e-12)
    verts = ribbon(line, 0.2)
    expected = [
        [0.2, -0.1, -0.1], [0.2, 0.1, -0.1],
        [1.5, -0.1, -1.625], [1.5, 0.1, -1.625],
        [3.0, -0.1, -3.0], [3.0, 0.1, -3.0],
    ]
    np.testing.assert_allclose(verts, expected, atol=1e-6)
    faces = ribbon_faces(3)
    assert faces.shape == (4, 3) and faces.dtype == np.uint32 and faces.max() == 5
    # Every face uses vertices of two neighbouring stations only.
    assert np.all(faces.max(axis=1) - faces.min(axis=1) <= 3)


def test_overscale_multiplies_only_the_chosen_part():
    state = BeamState(d=0.2, h=0.1, phi=PHI, b=np.array([0.5]))
    units = Parabola()
    base = centreline(state, units, [4.0])[0]
    scaled = centreline(state, units, [4.0], elastic_scale=10.0)[0]
    # Δ(4) = 0.5 → 5.0: η_I = 0.1 + 3.2 − 0.6·5 = 0.3, ζ_I = 0.2 + 2.4 + 0.8·5 = 6.6
    np.testing.assert_allclose(scaled, [0.3, 6.6], atol=1e-12)
    rigid = centreline(state, units, [0.0], rigid_scale=3.0)[0]
    np.testing.assert_allclose(rigid, [0.3, 0.6], atol=1e-12)  # D scaled, s(0) = 0
    assert not np.allclose(base, scaled)
    # tangent angle: φ + scale · s'(η) b
    np.testing.assert_allclose(tangent_angle(state, units, [4.0], elastic_scale=2.0), [PHI + 2 * 0.5 * 0.5])


def test_real_unit_deformations_start_at_the_bearing_and_hang_straight_at_rest():
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), 4)
    eta = np.linspace(0, rig.beam.length, 9)
    rest = centreline(BeamState(0.0, 0.0, 0.0, np.zeros(4)), units, eta)
    np.testing.assert_allclose(rest, np.column_stack([eta, np.zeros_like(eta)]), atol=1e-12)
    bent = centreline(BeamState(0.01, 0.0, 0.0, np.array([0.1, -0.05, 0.02, 0.01])), units, eta)
    np.testing.assert_allclose(bent[0], [0.0, 0.01], atol=1e-12)  # s(0) = 0: D only


def test_tof_rays_end_on_the_reflector_along_the_sensor_y_axis():
    units = Parabola()
    straight = tof_rays(BeamState(0.0, 0.0, 0.0, np.zeros(1)), units, np.array([1.0, 3.0]), 0.5)
    np.testing.assert_allclose(straight[:, 0], [[0, 0, -1], [0, 0, -3]], atol=1e-6)
    np.testing.assert_allclose(straight[:, 1], [[0.5, 0, -1], [0.5, 0, -3]], atol=1e-6)
    # Tilted by φ: y axis (−sin φ, cos φ) in (η, ζ); length = gap / cos φ (Eq. 18).
    rays = tof_rays(BeamState(0.0, 0.0, PHI, np.zeros(1)), units, np.array([0.5]), 0.5)
    start, end = rays[0]
    np.testing.assert_allclose(start, [0.3, 0.0, -0.4], atol=1e-6)  # ζ = 0.6·0.5, η = 0.8·0.5
    np.testing.assert_allclose(end[0], 0.5, atol=1e-6)  # ends on the reflector plane
    np.testing.assert_allclose(np.linalg.norm(end - start), 0.2 / 0.8, atol=1e-6)
    np.testing.assert_allclose(end[2] - start[2], 0.6 * 0.25, atol=1e-6)  # −η grows by sin φ · ρ


@pytest.mark.parametrize(
    ("x", "message"),
    [
        (np.zeros(8), "needs 10"),
        (np.zeros((2, 10)), "1-D"),
        (np.full(10, np.nan), "NaN"),
        ("abc", "numeric"),
    ],
)
def test_bad_state_vectors_are_refused_clearly(x, message):
    with pytest.raises(ValueError, match=message):
        parse_state(x, 4)


def test_accelerometer_state_layout_is_accepted():
    x = np.arange(5 + 2 * 4 + 1, dtype=float)
    state = parse_state(x, 4)
    assert state.d == 0 and state.h == 1 and state.phi == 4
    np.testing.assert_array_equal(state.b, [5, 6, 7, 8])


def test_bad_geometry_inputs():
    with pytest.raises(ValueError, match="width"):
        ribbon(np.zeros((3, 2)), 0.0)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        to_world(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="at least 2"):
        ribbon_faces(1)
    with pytest.raises(ValueError, match="elastic_scale"):
        centreline(BeamState(0, 0, 0, np.zeros(1)), Parabola(), [1.0], elastic_scale=-1)
    with pytest.raises(ValueError, match="one value per station"):
        centreline(BeamState(0, 0, 0, np.zeros(1)), Parabola(), [1.0, 2.0], deflection=np.zeros(3))


def test_window_and_trend_rows_are_read():
    window = {
        "start_s": 0.0, "end_s": 60.0, "kind": "ambient", "trusted": True, "temperature_c": 21.0,
        "modes": [{"mode": 1, "unit": 1, "frequency_hz": 0.86, "damping_ratio": 0.004, "confidence": 0.9},
                  {"mode": 2, "unit": 2, "frequency_hz": None, "amplitude": None, "confidence": 0.0}],
        "frequency_scores_sigma": [1.5, None],
        "curvature_index": [0.1, 0.2, 0.3], "curvature_eta_m": 3.5, "curvature_third": "lower",
        "levels": {"mode1": "ok"},
    }
    rec = normalise_window(window, n_stations=3)
    assert rec.frequency_hz == {1: 0.86, 2: None} and rec.score_sigma == {1: 1.5, 2: None}
    np.testing.assert_allclose(rec.curvature_profile, [0.1, 0.2, 0.3])
    assert rec.curvature_total == pytest.approx(math.sqrt((0.01 + 0.04 + 0.09) / 3))
    with pytest.raises(ValueError, match="one per station"):
        normalise_window(window, n_stations=4)
    with pytest.raises(ValueError, match="start_s"):
        normalise_window({"modes": []})
    with pytest.raises(ValueError, match="must be a dict"):
        normalise_window([1, 2])
    rows = [
        {"source": "a", "window_start_s": 0.0, "window_end_s": 30.0, "mode": m, "frequency_hz": f, "damping_ratio": 0.01,
         "temperature_c": 20.0, "curvature_index": 0.1}
        for m, f in ((1, 0.8), (2, 1.9))
    ] + [{"source": "a", "window_start_s": "bad"}]
    (merged,) = windows_from_trend_rows(rows)
    assert merged.frequency_hz == {1: 0.8, 2: 1.9} and merged.t_s == 30.0


def test_alarm_states_and_bad_alarms():
    a = normalise_alarm({"id": 3, "level": "alarm", "state": "raised", "mode": 2, "message": "m", "since_s": 5.0})
    assert a.active and not a.acknowledged and a.since_s == 5.0
    b = normalise_alarm({"id": 3, "level": "alarm", "state": "active", "acknowledged_at_s": 9.0, "raised_at_s": 5.0})
    assert b.active and b.acknowledged
    c = normalise_alarm({"id": 3, "level": "warning", "state": "cleared"})
    assert not c.active
    for bad, message in (({"level": "alarm"}, "integer 'id'"), ({"id": 1, "level": "fire"}, "level"), ({"id": 1, "state": "x"}, "state")):
        with pytest.raises(ValueError, match=message):
            normalise_alarm(bad)


def test_spectrum_plot_marks_tracked_and_baseline_frequencies():
    f = np.linspace(0, 10, 101)
    a = np.exp(-((f - 2.0) ** 2) / 0.01) + 1e-3
    x, y, tracked, baseline = spectrum_plot(f, a, 2.03, 1.9, f_max=5.0)
    assert x.size == y.size == tracked.size == baseline.size
    assert np.all(np.diff(x) > 0) and x[-1] <= 5.0
    assert x[np.argmax(tracked)] == pytest.approx(2.03) and x[np.argmax(baseline)] == pytest.approx(1.9)
    assert tracked.max() > y.max() and np.all(y > 0)  # log scale: no zeros
    _, _, none_marker, _ = spectrum_plot(f, a, None, None)
    assert np.ptp(none_marker) == 0


def test_nice_overscale_steps():
    assert [_nice(v) for v in (1.0, 3.7, 19.9, 20.0, 499.0)] == [1.0, 2.0, 10.0, 20.0, 200.0]


@pytest.fixture(scope="module")
def dashboard():
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), 4)
    stations = np.asarray(rig.truth_stations, dtype=float)
    dash = Dashboard(host="127.0.0.1", port=0, rig=rig, units=units, stations=stations, service=FakeService())
    yield dash
    dash.stop()


def test_dashboard_refuses_bad_pushes_with_clear_messages(dashboard):
    dash = dashboard
    assert dash.url == f"http://127.0.0.1:{dash.port}/" and dash.port > 0
    ok_x = np.zeros(10)
    dash.push_estimate(1.0, ok_x, {"/imu/s1": "ok"})
    with pytest.raises(ValueError, match="needs 10"):
        dash.push_estimate(1.0, np.zeros(7), {})
    with pytest.raises(ValueError, match="must be one of"):
        dash.push_estimate(1.0, ok_x, {"/imu/s1": "broken"})
    with pytest.raises(ValueError, match="t_s"):
        dash.push_estimate(float("nan"), ok_x, {})
    with pytest.raises(ValueError, match="truth_deflection must have shape"):
        dash.push_estimate(1.0, ok_x, {}, truth_deflection=np.zeros(3))
    f = np.linspace(0, 10, 50)
    dash.push_spectra(f, np.ones((50, 4)), [1.0, None, 3.0, 5.0], [None] * 4)
    with pytest.raises(ValueError, match=r"shape \(len\(frequencies_hz\), Γ\)"):
        dash.push_spectra(f, np.ones((50, 3)), [None] * 4, [None] * 4)
    with pytest.raises(ValueError, match="tracked_hz"):
        dash.push_spectra(f, np.ones((50, 4)), [1.0], [None] * 4)
    with pytest.raises(ValueError, match="strictly increasing"):
        dash.push_spectra(f[::-1], np.ones((50, 4)), [None] * 4, [None] * 4)
    with pytest.raises(ValueError, match="start_s"):
        dash.push_window({"kind": "ambient"})
    with pytest.raises(ValueError, match="integer 'id'"):
        dash.push_alarm({"level": "alarm"})
    dash.push_alarm({"id": 1, "level": "warning", "state": "raised", "message": "x"})
    snap = dash.snapshot()
    assert snap.estimate.t_s == 1.0 and snap.alarms[0].id == 1 and snap.spectra.amplitudes.shape == (50, 4)


def test_dashboard_constructor_checks_its_arguments():
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), 2)
    with pytest.raises(ValueError, match="stations"):
        Dashboard(host="127.0.0.1", port=0, rig=rig, units=units, stations=np.array([0.5, 9.0]), service=FakeService())
    with pytest.raises(TypeError, match="DashboardService"):
        Dashboard(host="127.0.0.1", port=0, rig=rig, units=units, stations=np.array([1.0, 2.0]), service=object())
