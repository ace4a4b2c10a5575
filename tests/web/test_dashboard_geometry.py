"""The dashboard's geometry and input checks, without a browser."""

from __future__ import annotations

import math

import numpy as np
import pytest

import estimator
from contract import LiveEstimatesDocument, SpectrumDocument, StateLayout, StructureModel, TrendRow, WindowDocument
from shm_service.rig_layouts import default_rig
from web import (
    BeamState, Dashboard, StructureFeed, centreline, nice_scale, parse_state, ribbon, ribbon_faces, spectrum_plot,
    tangent_angle, thresholds_of, tof_rays, to_world, window_record, windows_from_trend_rows,
)
from web._geometry import CLAMP_GRIP, clamp_boxes, up_sign

from dashboard_feeder import ID, THRESHOLDS, FakePort, alarm


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
    # x = [d, h, d_rate, h_rate, phi, b1, gyro_bias_D]: gyro, Γ = 1, no peripheral IMU
    state = parse_state([0.2, 0.1, 9.0, 9.0, PHI, 0.5, 7.0], StateLayout("gyro", 1, 0))
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
    # a taper: one width per centre-line point (a tube's diameter falling along a mast)
    tapered = ribbon(line, np.array([0.4, 0.3, 0.2]))
    np.testing.assert_allclose(tapered[:, 1], [-0.2, 0.2, -0.15, 0.15, -0.1, 0.1], atol=1e-7)
    for bad in (np.array([0.4, 0.3]), np.array([0.4, -0.3, 0.2]), np.array([0.4, np.nan, 0.2]), 0.0):
        with pytest.raises(ValueError, match="width"):
            ribbon(line, bad)
    faces = ribbon_faces(3)
    assert faces.shape == (4, 3) and faces.dtype == np.uint32 and faces.max() == 5
    # Every face uses vertices of two neighbouring stations only.
    assert np.all(faces.max(axis=1) - faces.min(axis=1) <= 3)


def test_a_standing_mast_is_drawn_upright_from_its_clamp():
    # The same inertial (η, ζ) points: a hanging beam goes down from D (z = −η), a mast up (z = +η).
    plane = np.array([[0.0, 0.2], [1.5, 0.25]])
    np.testing.assert_allclose(to_world(plane), [[0.2, 0.0, 0.0], [0.25, 0.0, -1.5]], atol=1e-6)
    np.testing.assert_allclose(to_world(plane, standing=True), [[0.2, 0.0, 0.0], [0.25, 0.0, 1.5]], atol=1e-6)
    np.testing.assert_allclose(ribbon(plane, 0.2, standing=True)[2:, 2], [1.5, 1.5], atol=1e-6)
    assert (up_sign(True), up_sign(False)) == (1.0, -1.0)
    with pytest.raises(ValueError, match="standing='yes' must be True or False"):
        up_sign("yes")
    state = parse_state([0.03, 0.0, 0.0, 0.0, 0.1], StateLayout("gyro", 1, 0, attitude=False))  # [d, h, ḋ, ḣ, b1]
    assert state.phi == 0.0 and state.b.tolist() == [0.1]
    for standing, up in ((True, 1.0), (False, -1.0)):
        (jaw_a, dims_a), (jaw_b, _), (base, base_dims) = clamp_boxes(state, 0.2, standing=standing)
        # Jaws on both faces of the sheet at d, gripping its root along the beam; the carriage beyond D.
        assert jaw_a[0] < 0.03 < jaw_b[0] and jaw_a[2] == pytest.approx(up * 0.5 * CLAMP_GRIP)
        assert dims_a[1] > 0.2 and dims_a[2] == CLAMP_GRIP
        assert base[0] == pytest.approx(0.03) and np.sign(base[2]) == -up and base_dims[0] > 2 * dims_a[0]
    with pytest.raises(ValueError, match="width"):
        clamp_boxes(state, 0.0)


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
        (np.zeros(8), "needs 14"),
        (np.zeros((2, 14)), "1-D"),
        (np.full(14, np.nan), "NaN"),
        ("abc", "numeric"),
    ],
)
def test_bad_state_vectors_are_refused_clearly(x, message):
    with pytest.raises(ValueError, match=message):
        parse_state(x, StateLayout("gyro", 4, 4))
    with pytest.raises(ValueError, match="StateLayout"):
        parse_state(np.zeros(14), 4)


# (configuration, Γ, ν, state size): gyro [d, h, ḋ, ḣ, φ, b1..bΓ, β1..βν, β_D], acc [d, h, ḋ, ḣ, φ, b1..bΓ, v1..vΓ, β_D]
LAYOUTS = [("gyro", 1, 0, 7), ("acc", 1, 0, 8), ("gyro", 2, 3, 11), ("acc", 2, 3, 10), ("gyro", 3, 4, 13), ("acc", 3, 4, 12),
           ("gyro", 4, 4, 14), ("acc", 4, 4, 14), ("gyro", 5, 6, 17), ("acc", 5, 6, 16), ("gyro", 5, 17, 28)]


@pytest.mark.parametrize(("peripheral", "gamma", "nu", "size"), LAYOUTS)
def test_every_configuration_reads_the_beam_through_its_layout(peripheral, gamma, nu, size):
    layout = StateLayout(peripheral, gamma, nu)
    assert layout.size == size
    state = parse_state(np.arange(size, dtype=float), layout)
    assert (state.d, state.h, state.phi) == (0.0, 1.0, 4.0)
    b_start = 5  # after d, h, ḋ, ḣ, φ
    np.testing.assert_array_equal(state.b, b_start + np.arange(gamma))
    for wrong in (size - 1, size + 1):
        with pytest.raises(ValueError, match=f"needs {size} entries"):
            parse_state(np.zeros(wrong), layout)


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


def _window(**extra):
    doc = {
        "source": "a", "start_s": 0.0, "end_s": 60.0, "kind": "ambient", "trusted": True, "temperature_c": 21.0,
        "modes": [{"mode": 1, "unit": 1, "frequency_hz": 0.30, "damping_ratio": 0.004, "confidence": 0.9, "score_sigma": 1.5,
                   "level": "ok"},
                  {"mode": 2, "unit": 1, "frequency_hz": None, "amplitude": None, "confidence": 0.0}],
        "charts": [{"name": "mode1", "kind": "frequency", "mode": 1, "unit": 1, "level": "ok", "score_sigma": 1.5,
                    "warning_sigma": 3.0, "alarm_sigma": 5.0},
                   {"name": "curvature", "kind": "curvature", "level": "warning", "score_sigma": 3.5,
                    "warning_sigma": 3.0, "alarm_sigma": 6.0}],
        "curvature": {"index": [0.1, 0.2, 0.3], "total": 0.216, "eta_m": 3.5, "third": "lower", "score_sigma": 3.5},
    }
    return WindowDocument.model_validate({**doc, **extra})


def test_window_and_trend_rows_are_read():
    rec = window_record(_window(), n_stations=3)
    assert rec.frequency_hz == {1: 0.30, 2: None} and rec.score_sigma == {1: 1.5, 2: None}
    assert rec.level == {1: "ok", 2: None} and rec.curvature_level == "warning"
    np.testing.assert_allclose(rec.curvature_profile, [0.1, 0.2, 0.3])
    assert rec.curvature_total == 0.216 and rec.curvature_score_sigma == 3.5
    # the levels each chart was judged against, by kind (the curvature chart's own 6 σ)
    assert rec.levels_sigma == {"frequency": (3.0, 5.0), "curvature": (3.0, 6.0)}
    with pytest.raises(ValueError, match="one per station"):
        window_record(_window(), n_stations=4)
    with pytest.raises(ValueError, match="WindowDocument"):
        window_record({"start_s": 0.0})
    rows = [
        TrendRow(source="a", window_start_s=0.0, window_end_s=30.0, mode=m, unit=u, kind="ambient", frequency_hz=f,
                 damping_ratio=0.01, temperature_c=20.0, curvature_index=0.1, level="ok")
        for m, u, f in ((1, 1, 0.3), (2, 1, 0.86), (3, 2, 1.9))
    ]
    (merged,) = windows_from_trend_rows(rows)
    assert merged.frequency_hz == {1: 0.3, 2: 0.86, 3: 1.9} and merged.t_s == 30.0 and merged.curvature_total == 0.1


def test_thresholds_are_the_services_never_made_up():
    windows = (window_record(_window(), n_stations=3),)
    assert thresholds_of(THRESHOLDS, windows) == {"frequency": (2.5, 4.0), "curvature": (2.5, 6.0)}
    assert thresholds_of(None, windows) == {"frequency": (3.0, 5.0), "curvature": (3.0, 6.0)}
    assert thresholds_of(None, (window_record(_window(charts=[]), n_stations=3),)) == {}


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
    assert [nice_scale(v) for v in (1.0, 3.7, 19.9, 20.0, 499.0)] == [1.0, 2.0, 10.0, 20.0, 200.0]


def _spectrum(gamma, n=50, **extra):
    f = np.linspace(0, 10, n)
    doc = dict(source="a", window_start_s=0.0, window_end_s=60.0, frequencies_hz=f, amplitudes=np.ones((n, gamma)),
               tracked_hz=[[1.0]] * gamma, baseline_hz=None)
    return SpectrumDocument.from_arrays(**{**doc, **extra})


def _feed(gamma=3, **kw):
    rig = kw.pop("rig", None) or default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), gamma)
    stations = kw.pop("stations", None)
    stations = np.asarray(rig.truth_stations, dtype=float) if stations is None else stations
    return StructureFeed(rig=rig, units=units, layout=kw.pop("layout", StateLayout("gyro", gamma, 4)), stations=stations, **kw)


def _live(feed, x, *, t=(1.0,), sensors=None, truth=None):
    return LiveEstimatesDocument(source="s", seq=len(t), state_names=list(feed.layout.names), t_s=list(t),
                                 x=[list(v) for v in x], sensors=sensors or {}, watch_s=20.0, truth_deflection=truth)


def test_a_feed_refuses_what_it_cannot_draw_with_clear_messages():
    feed = _feed()  # Γ = 3 with four peripheral gyroscopes: 5 + 3 + 4 + 1 = 13 states
    ok_x = np.zeros(13)
    feed.add_live(_live(feed, [ok_x], sensors={"/imu/s1": "ok"}, truth=[[0.001] * feed.stations.size]), now=0.0)
    feed.play(100.0)
    snap = feed.snapshot()
    assert snap.estimate.t_s == 1.0 and snap.estimate.truth_deflection.shape == feed.stations.shape
    with pytest.raises(ValueError, match="needs 13"):  # 5 + Γ + 1: the length the dashboard once assumed
        feed.add_live(_live(feed, [np.zeros(9)], t=(2.0,)), now=1.0)
    with pytest.raises(ValueError, match="the model drawn has"):
        feed.add_live(LiveEstimatesDocument(source="s", seq=1, state_names=["d"], t_s=[4.0], x=[[0.0]], watch_s=1.0))
    feed.set_spectra(_spectrum(3))  # before a baseline: tracked frequencies only
    assert feed.snapshot().spectra.baseline_hz == ((), (), ())
    with pytest.raises(ValueError, match=r"shape \(len\(frequencies_hz\), Γ\)"):
        feed.set_spectra(_spectrum(4))
    with pytest.raises(ValueError, match="WindowDocument"):
        feed.add_window({"kind": "ambient"})
    with pytest.raises(ValueError, match="AlarmDocument"):
        feed.upsert_alarm({"id": 1, "level": "alarm"})
    with pytest.raises(ValueError, match="one per station"):
        feed.add_window(_window(curvature={"index": [0.1, 0.2], "total": 0.1, "eta_m": 1.0, "third": "upper"}))
    feed.add_window(_window(curvature=None))
    feed.upsert_alarm(alarm(1, level="warning"))
    snap = feed.snapshot()
    assert snap.alarms[0].id == 1 and snap.spectra.amplitudes.shape == (50, 3)
    assert snap.windows[-1].frequency_hz[1] == 0.30
    # the window's own record replaces the one its trend rows gave (same start): one record per window
    feed.add_window(_window(curvature=None))
    assert len(feed.snapshot().windows) == 1


def test_a_standing_clamped_mast_is_read_through_its_layout():
    import json

    from contract import parse_rig

    data = json.loads(default_rig().to_json())
    data.update(support="clamped", orientation="standing")
    data["beam"]["length"] = 1.5
    data["sensors"] = [s for s in data["sensors"] if s.get("position") is None or s["position"] <= 1.5]
    data["point_masses"] = [m for m in data["point_masses"] if m["position"] <= 1.5]
    data["truth_stations"] = [0.5, 1.0, 1.5]
    rig = parse_rig(data)
    feed = _feed(2, rig=rig, layout=StateLayout("gyro", 2, 1, attitude=False), stations=np.array([0.5, 1.0, 1.5]))
    assert feed.units.modes == ((1,), (2,))
    assert feed.clamped and feed.standing
    assert feed.mode_map.unit_label(1) == "b1 · mode 1" and feed.mode_map.mode_label(2) == "mode 2 (b2)"
    feed.add_live(_live(feed, [[0.01, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0]]), now=0.0)
    feed.play(100.0)
    assert feed.snapshot().estimate.state.phi == 0.0
    hinged = type("Rig", (), {"beam": rig.beam, "reflector_distance": 0.5, "sensors": rig.sensors,
                              "orientation": "standing", "support": "hinged"})()
    with pytest.raises(ValueError, match="support='hinged' must be 'pinned' or 'clamped'"):
        StructureFeed(rig=hinged, units=feed.units, layout=StateLayout("gyro", 2, 1, attitude=False), stations=np.array([0.5, 1.0]))


def test_a_feed_checks_its_model():
    with pytest.raises(ValueError, match="stations"):
        _feed(2, layout=StateLayout("gyro", 2, 4), stations=np.array([0.5, 9.0]))
    with pytest.raises(ValueError, match="Γ=3"):
        _feed(2, layout=StateLayout("gyro", 3, 4), stations=np.array([1.0, 2.0]))


def test_the_dashboard_needs_the_port():
    with pytest.raises(TypeError, match=r"contract.ServicePort: missing structures_document\(\)"):
        Dashboard(host="127.0.0.1", port=0, service=object())
    with pytest.raises(ValueError, match="render_hz"):
        Dashboard(host="127.0.0.1", port=0, service=_port(), render_hz=100.0)


def _port() -> FakePort:
    feed = _feed(2, layout=StateLayout("gyro", 2, 4))
    model = StructureModel(id=ID, rig=feed.rig, units=feed.units, layout=feed.layout, stations=feed.stations)
    return FakePort(model, np.zeros(1), np.zeros((1, feed.layout.size)), None)
