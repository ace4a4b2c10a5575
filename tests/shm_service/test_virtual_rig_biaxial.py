"""The virtual rig's biaxial beam (beam.bending = "biaxial"): its ξ plant, the contract's signs of
accel z and gyro y, gauges around the section, the veering wind, the truth's _xi keys."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from example_mast import planar_mast_data

from contract import parse_rig
from shm_service.virtual_rig import SensorErrors, SimulationSettings, VirtualRig
from shm_service.virtual_rig._biaxial import biaxial_points_motion
from shm_service.virtual_rig._kinematics import points_motion

NO_ERRORS = SensorErrors(**{name: 0.0 for name in SensorErrors.model_fields if name != "bias_correlation_time"})
MAST = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"
#: β_k L of the clamped-free beam (roots of cos βL cosh βL = −1)
CANTILEVER_BETA_L = (1.875104069, 4.694091133, 7.854757438, 10.99554073)


def tube_rig(*, length=3.0, gravity=0.0, orientation="hanging", sensors=None, beam=None):
    """A uniform steel tube (or ``beam``), clamped, biaxial, IMUs at L/2 and L, gauges at 0°/90°/45°."""
    half = round(length / 2, 9)
    return parse_rig({
        "beam": beam or {"length": length, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": "biaxial",
                         "sections": [{"position": 0.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004},
                                      {"position": length, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}]},
        "gravity": gravity, "support": "clamped", "orientation": orientation,
        "sensors": sensors or [
            {"name": "D", "kind": "imu", "position": 0.0}, {"name": "m", "kind": "imu", "position": half},
            {"name": "tip", "kind": "imu", "position": length},
            {"name": "g0", "kind": "strain", "position": half},
            {"name": "g90", "kind": "strain", "position": half, "angle_deg": 90},
            {"name": "g45", "kind": "strain", "position": half, "angle_deg": 45},
        ],
        "truth_stations": [half, length],
    })


def run(rig, **settings):
    defaults = dict(duration=60.0, rest=1.0, ideal=True, seed=7, errors=NO_ERRORS, excitation="ambient",
                    support="clamped", orientation=rig.orientation, length=rig.beam.length)
    vr = VirtualRig(SimulationSettings(**(defaults | settings)), rig)
    blocks = list(vr.blocks(20.0))
    meas = {k: np.concatenate([b.measurements[k][1] for b in blocks]) for k in blocks[0].measurements}
    truth = {k: np.concatenate([b.truth[k] for b in blocks]) for k in blocks[0].truth}
    return vr, meas, truth


def test_the_xi_plant_of_a_uniform_tube_and_a_rectangle_has_the_clamped_beam_frequencies():
    for beam, i_zeta, i_xi in (
        ({"length": 3.0, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": "biaxial",
          "sections": [{"position": 0.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004},
                       {"position": 3.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}]},
         math.pi / 64 * (0.1**4 - 0.092**4), math.pi / 64 * (0.1**4 - 0.092**4)),
        ({"length": 3.0, "width": 0.06, "thickness": 0.02, "youngs_modulus": 2.1e11, "density": 7850.0,
          "bending": "biaxial"}, 0.06 * 0.02**3 / 12, 0.02 * 0.06**3 / 12),
    ):
        rig = tube_rig(beam=beam)
        vr = VirtualRig(SimulationSettings(duration=1.0, ideal=True, support="clamped", length=3.0), rig)
        mu = vr.plant_rig.beam.mass_per_length_at(1.0)
        for plant, inertia in ((vr.plants[0], i_zeta), (vr.plants_xi[0], i_xi)):
            analytic = [(bl / 3.0) ** 2 / (2 * math.pi) * math.sqrt(2.1e11 * inertia / mu) for bl in CANTILEVER_BETA_L]
            np.testing.assert_allclose(plant.linear_frequencies_hz[:4], analytic, rtol=5e-3)
        meta = vr.truth_metadata()
        assert meta["bending"] == "biaxial"
        np.testing.assert_allclose(json.loads(meta["eigenfrequencies_xi_hz"])[:4],
                                   vr.plants_xi[0].linear_frequencies_hz[:4], rtol=1e-6)


def test_wind_across_zeta_moves_only_xi_and_accel_z_and_gyro_y_carry_it_with_the_contracts_signs():
    rig = tube_rig(gravity=9.81, orientation="standing")
    vr, meas, truth = run(rig, wind_direction={"mean_deg": 90.0, "veer_deg": 0.0})
    assert np.abs(truth["e_xi"]).max() > 1e-4
    assert np.abs(truth["e"]).max() < 1e-12 * np.abs(truth["e_xi"]).max()
    assert np.abs(truth["curvature"]).max() < 1e-12 * np.abs(truth["curvature_xi"]).max()
    # the tip's motion from the ξ plant's states (modal accelerations: exact, unlike differences at 200 Hz)
    tip = meas["/imu/tip"]
    vr2 = VirtualRig(vr.settings, rig)
    vr2._integrate_range(0, vr.n_samples)
    r, rd, rdd = (a[:, 1:] for a in vr2._xi_range)
    L = rig.beam.length
    np.testing.assert_allclose(r @ vr2.basis_xi.evaluate(L, 0), truth["e_xi"], rtol=1e-12, atol=1e-15)
    beta = np.arcsin(r @ vr2.basis_xi.evaluate(L, 1))
    rate = (rd @ vr2.basis_xi.evaluate(L, 1)) / np.cos(beta)
    acc_xi = rdd @ vr2.basis_xi.evaluate(L, 0)
    # accel z relates to Δξ as accel y to Δζ: the tangent tilted by β sees −sin β of the +g along η
    # (standing) and cos β of the ξ acceleration (the foreshortening's own acceleration is second order)
    expected = np.cos(beta) * acc_xi - np.sin(beta) * 9.81
    scale = np.abs(acc_xi).max()
    assert scale > 0.1
    np.testing.assert_allclose(tip[:, 2], expected, atol=1e-3 * scale)
    assert np.abs(tip[:, 1]).max() < 1e-9 * scale and np.abs(tip[:, 5]).max() < 1e-9 * np.abs(tip[:, 4]).max()
    # gyro y is minus the rate of the ξ tangent (a tangent turning towards +ξ turns about −y)
    np.testing.assert_allclose(tip[:, 4], -rate, rtol=1e-9, atol=1e-12)
    assert np.corrcoef(tip[:, 4], rate)[0, 1] < -0.999


def test_gauges_around_the_tube_read_both_curvatures():
    rig = tube_rig()
    radius = 0.05
    # wind along ζ only: the gauge at 90° (the +ξ face) sees nothing
    _, meas, truth = run(rig, wind_direction={"mean_deg": 0.0, "veer_deg": 0.0}, duration=20.0)
    k_zeta = truth["curvature"][:, 0]
    assert np.abs(k_zeta).max() > 1e-5
    assert np.abs(meas["/strain/g90"][:, 0]).max() < 1e-9 * radius * np.abs(k_zeta).max()
    # a veering wind: ε(θ) = −R (κζ cos θ + κξ sin θ); the exact curvatures differ from the truth's
    # linear ones (∂²Δ/∂η²) at second order in the slopes only
    _, meas, truth = run(rig, wind_direction={"mean_deg": 30.0, "veer_deg": 40.0, "period_s": 20.0}, duration=40.0)
    k_zeta, k_xi = truth["curvature"][:, 0], truth["curvature_xi"][:, 0]
    assert np.abs(k_xi).max() > 0.3 * np.abs(k_zeta).max()
    scale = radius * np.abs(np.hypot(k_zeta, k_xi)).max()
    for name, angle in (("g0", 0.0), ("g90", 90.0), ("g45", 45.0)):
        theta = math.radians(angle)
        expected = -radius * (k_zeta * math.cos(theta) + k_xi * math.sin(theta))
        np.testing.assert_allclose(meas[f"/strain/{name}"][:, 0], expected, atol=1e-3 * scale)
    np.testing.assert_allclose(meas["/strain/g90"][:, 0], -radius * k_xi, atol=1e-3 * scale)


def test_without_xi_motion_the_biaxial_kinematics_are_the_planar_rigs():
    rig = tube_rig(gravity=9.81, orientation="standing")
    vr = VirtualRig(SimulationSettings(duration=5.0, rest=0.5, ideal=True, seed=3, errors=NO_ERRORS,
                                       excitation="ambient", support="clamped", orientation="standing", length=3.0,
                                       wind_direction={"mean_deg": 0.0, "veer_deg": 0.0}), rig)
    y, yd, ydd = vr._integrate_range(0, vr.n_samples)
    zero = np.zeros((y.shape[0], vr.basis_xi.count))
    d = np.zeros(y.shape[0])
    xs = [0.7, 1.5, 3.0]
    planar = points_motion(vr.basis, xs, y, yd, ydd, d, d, -9.81)
    both = biaxial_points_motion(vr.basis, vr.basis_xi, xs, (y[:, 1:], yd[:, 1:], ydd[:, 1:]), (zero, zero, zero), d, d, -9.81)
    assert np.abs(planar.specific_force_y).max() > 1e-3
    np.testing.assert_allclose(both.specific_force[0], planar.specific_force_x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(both.specific_force[1], planar.specific_force_y, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(both.rate[2], planar.rate, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(both.curvature, planar.curvature, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(both.specific_force[2], 0.0)
    np.testing.assert_array_equal(both.rate[1], 0.0)


def _biaxial_mast() -> dict:
    data = json.loads(MAST.read_text())
    data["beam"]["bending"] = "biaxial"
    return data


def test_the_biaxial_mast_veers_the_wind_into_xi_and_carries_a_tip_mass_and_a_temperature_swing():
    rig = parse_rig(_biaxial_mast())
    vr, meas, truth = run(rig, duration=600.0, rest=5.0, ideal=False, errors=SensorErrors(), seed=11,
                          damage=("mass:14.4@20",), damage_at=300.0, temperature_swing=20.0)
    ratio = truth["e_xi"][1000:].std() / truth["e"][1000:].std()
    assert 0.45 < ratio < 0.75  # the default veering wind: ξ about 0.6 of ζ
    meta = vr.truth_metadata()
    for key in ("eigenfrequencies_hz", "eigenfrequencies_xi_hz"):
        before = np.array(json.loads(meta[key]))
        after = np.array(json.loads(meta[key.replace("eigenfrequencies", "eigenfrequencies_after_damage")]))
        assert np.all(after[:3] < before[:3])  # the tip mass lowers both planes' frequencies
    # a round tube: the two planes are a degenerate pair (the same plant as built)
    np.testing.assert_allclose(json.loads(meta["eigenfrequencies_xi_hz"])[:4], json.loads(meta["eigenfrequencies_hz"])[:4],
                               rtol=1e-9)
    assert all(np.all(np.isfinite(v)) for v in meas.values())
    assert json.loads(meta["wind_direction"]) == {"mean_deg": 25.0, "veer_deg": 30.0, "period_s": 600.0}


def test_bad_biaxial_input_is_refused():
    planar = planar_mast_data()
    with pytest.raises(ValueError, match="wind_direction.*biaxial"):
        VirtualRig(SimulationSettings(duration=1.0, support="clamped", orientation="standing", length=20.0,
                                      wind_direction={"mean_deg": 10.0}), parse_rig(planar))
    planar["sensors"].append({"name": "g45", "kind": "strain", "position": 1.0, "angle_deg": 45})
    with pytest.raises(ValueError, match="angle_deg.*planar beam accepts only 0 and 180"):
        VirtualRig(SimulationSettings(duration=1.0, support="clamped", orientation="standing", length=20.0),
                   parse_rig(planar))
    table = {"length": 3.0, "bending": "biaxial", "sections": [
        {"position": 0.0, "shape": "table", "bending_stiffness": 1e5, "mass_per_length": 5.0, "fibre_distance": 0.05},
        {"position": 3.0, "shape": "table", "bending_stiffness": 1e5, "mass_per_length": 5.0, "fibre_distance": 0.05}]}
    with pytest.raises(ValueError, match=r"beam.sections\[0\].bending_stiffness_xi"):
        VirtualRig(SimulationSettings(duration=1.0, support="clamped", length=3.0), tube_rig(beam=table))
