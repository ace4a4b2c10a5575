"""The FE beam model against closed forms, and its bad-input handling."""

import numpy as np
import pytest
import scipy.special

from estimator import RigError, assemble_beam, natural_modes, parse_rig

L, W, H, RHO, E = 4.0, 0.2, 0.002, 7850.0, 2.1e11
EI = E * W * H**3 / 12
MU = RHO * W * H


def rig(**overrides):
    description = {
        "beam": {"length": L, "width": W, "thickness": H, "youngs_modulus": E, "density": RHO},
        "gravity": 9.81,
        "reflector_distance": 0.5,
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}],
    }
    beam = overrides.pop("beam", {})
    description["beam"].update(beam)
    description.update(overrides)
    return parse_rig(description)


def test_pinned_free_beam_without_gravity_matches_closed_form():
    # Pinned–free Euler–Bernoulli beam: tan(λL) = tanh(λL), λL = 3.9266, 7.0686, 10.2102, 13.3518.
    model = assemble_beam(rig(gravity=1e-12), elements=60)
    modes = natural_modes(model, 5)
    assert modes.frequencies_hz[0] == pytest.approx(0.0, abs=1e-4)  # the rigid rotation about D
    lam_l = np.sqrt(2 * np.pi * modes.frequencies_hz[1:] * np.sqrt(MU / EI)) * L
    np.testing.assert_allclose(lam_l, [3.92660231, 7.06858275, 10.21017612, 13.35176878], rtol=1e-5)


def test_hanging_chain_limit_matches_bessel_zeros():
    # EI → 0: ω_n = (j_0,n / 2) √(g / L) for a chain pinned at the top.
    model = assemble_beam(rig(beam={"youngs_modulus": 1e4}), elements=100)
    expected = scipy.special.jn_zeros(0, 4) / 2 * np.sqrt(9.81 / L) / (2 * np.pi)
    np.testing.assert_allclose(natural_modes(model, 4).frequencies_hz, expected, rtol=1e-5)


@pytest.mark.parametrize("tip_mass, clamp_inertia", [(0.0, 0.0), (2.0, 0.0), (0.0, 5.0), (1.5, 3.0)])
def test_stiff_beam_is_a_physical_pendulum(tip_mass, clamp_inertia):
    # A beam far stiffer than gravity swings as a rigid body: ω² = g S_D / I_D.
    masses = [{"position": L, "mass": tip_mass}, {"position": 0.0, "mass": 1.0, "rotary_inertia": clamp_inertia}]
    model = assemble_beam(rig(beam={"youngs_modulus": 1e15}, point_masses=masses))
    m = MU * L
    first_moment = m * L / 2 + tip_mass * L
    inertia = m * L**2 / 3 + tip_mass * L**2 + clamp_inertia
    expected = np.sqrt(9.81 * first_moment / inertia) / (2 * np.pi)
    assert natural_modes(model, 1).frequencies_hz[0] == pytest.approx(expected, rel=2e-5)


def test_total_mass_includes_point_masses():
    model = assemble_beam(rig(point_masses=[{"position": 1.3, "mass": 0.25}, {"position": 4.0, "mass": 0.5}]))
    assert model.total_mass == pytest.approx(MU * L + 0.75, rel=1e-12)


def test_youngs_modulus_follows_temperature():
    # Without gravity the flexible frequencies scale with √E: −0.03 %/K over +10 K.
    cold = rig(gravity=1e-12, beam={"youngs_modulus_temperature_coefficient": -3e-4, "reference_temperature": 20.0})
    f_ref = natural_modes(assemble_beam(cold), 3).frequencies_hz[1:]
    f_hot = natural_modes(assemble_beam(cold, temperature_c=30.0), 3).frequencies_hz[1:]
    np.testing.assert_allclose(f_hot / f_ref, np.sqrt(1 - 3e-3), rtol=1e-9)


def test_stiffness_segment_over_whole_beam_scales_frequencies():
    soft = rig(gravity=1e-12, beam={"stiffness_segments": [{"start": 0.0, "end": L, "factor": 0.64}]})
    f_ref = natural_modes(assemble_beam(rig(gravity=1e-12)), 3).frequencies_hz[1:]
    f_soft = natural_modes(assemble_beam(soft), 3).frequencies_hz[1:]
    np.testing.assert_allclose(f_soft / f_ref, 0.8, rtol=1e-9)


def test_local_stiffness_loss_lowers_frequencies_and_adds_nodes():
    damaged = rig(beam={"stiffness_segments": [{"start": 1.03, "end": 1.23, "factor": 0.8}]})
    model = assemble_beam(damaged)
    assert 1.03 in model.nodes and 1.23 in model.nodes
    f_ref = natural_modes(assemble_beam(rig()), 6).frequencies_hz
    f_dam = natural_modes(model, 6).frequencies_hz
    assert np.all(f_dam <= f_ref * (1 + 1e-9)) and np.any(f_dam < f_ref * (1 - 1e-4))


def test_mesh_refinement_converges():
    coarse = natural_modes(assemble_beam(rig(), elements=40), 6).frequencies_hz
    fine = natural_modes(assemble_beam(rig(), elements=160), 6).frequencies_hz
    np.testing.assert_allclose(coarse, fine, rtol=1e-4)


def test_modes_are_mass_normalised_with_positive_tip():
    model = assemble_beam(rig())
    modes = natural_modes(model, 6)
    dofs = modes.shapes.dofs
    np.testing.assert_allclose(dofs.T @ model.mass @ dofs, np.eye(6), atol=1e-9)
    assert np.all(modes.shapes.evaluate(L) > 0)
    assert np.all(modes.shapes.evaluate(0.0) == 0.0)


def test_bad_inputs_are_refused_with_named_values():
    with pytest.raises(ValueError, match="elements=1"):
        assemble_beam(rig(), elements=1)
    with pytest.raises(ValueError, match="count=0"):
        natural_modes(assemble_beam(rig()), 0)
    with pytest.raises(RigError, match="temperature_c=nan"):
        assemble_beam(rig(), temperature_c=float("nan"))
    with pytest.raises(ValueError, match="eta must lie on the beam"):
        natural_modes(assemble_beam(rig()), 2).shapes.evaluate(4.5)
    with pytest.raises(ValueError, match="derivative=4"):
        natural_modes(assemble_beam(rig()), 2).shapes.evaluate(1.0, derivative=4)
