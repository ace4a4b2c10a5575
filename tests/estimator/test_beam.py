"""The FE beam model against closed forms and an independent beam-column solution, and its bad-input handling."""

import numpy as np
import pytest
import scipy.special

from beam_column_reference import clamped_frequencies
from estimator import (
    GREENHILL_COEFFICIENT,
    BucklingError,
    RigError,
    assemble_beam,
    critical_load_factor,
    greenhill_length,
    natural_modes,
    parse_rig,
)

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


# -- clamped support, standing beam, buckling ---------------------------------------------
CLAMPED_FREE_LAMBDA_L = [1.87510407, 4.69409113, 7.85475744, 10.99554073]
L_GREENHILL = (7.8373 * EI / (MU * 9.81)) ** (1 / 3)


def test_clamped_free_beam_without_gravity_matches_closed_form():
    # 1 + cos(λL) cosh(λL) = 0.
    model = assemble_beam(rig(gravity=0.0, support="clamped"), elements=60)
    lam_l = np.sqrt(2 * np.pi * natural_modes(model, 4).frequencies_hz * np.sqrt(MU / EI)) * L
    np.testing.assert_allclose(lam_l, CLAMPED_FREE_LAMBDA_L, rtol=1e-5)
    assert model.critical_load_factor == np.inf
    np.testing.assert_array_equal(model.free_dofs, np.arange(2, model.mass.shape[0]))


def test_clamped_modes_leave_the_root_still():
    modes = natural_modes(assemble_beam(rig(support="clamped", orientation="standing", beam={"length": 1.5})), 4)
    assert modes.support == "clamped"
    np.testing.assert_array_equal(modes.shapes.evaluate(0.0), 0.0)
    np.testing.assert_array_equal(modes.shapes.evaluate(0.0, 1), 0.0)
    assert np.all(modes.shapes.evaluate(1.5) > 0)


def test_greenhill_coefficient_and_the_sheets_critical_length():
    assert GREENHILL_COEFFICIENT == pytest.approx(7.8373, abs=1e-4)  # 9 j²/4, j the first zero of J_{-1/3}
    assert greenhill_length(EI, MU, 9.81) == pytest.approx(L_GREENHILL, rel=1e-5)
    assert 1.91 < greenhill_length(EI, MU, 9.81) < 1.93  # the 2 mm sheet of the rig: ≈ 1.92 m
    assert greenhill_length(EI, MU, 0.0) == np.inf


@pytest.mark.parametrize("length", [1.0, 1.5, 4.0])
def test_fe_buckling_factor_gives_the_greenhill_length(length):
    # The weight scales with L, the critical load with 1/L³ at fixed q: λ_cr = (L_cr / L)³.
    beam = rig(support="clamped", orientation="standing", beam={"length": length}, gravity=9.81 * 1e-3)
    model = assemble_beam(beam, elements=60)  # a thousandth of g: stands at every length here
    lam = model.critical_load_factor * 1e-3  # the factor on the real g
    assert length * lam ** (1 / 3) == pytest.approx(L_GREENHILL, rel=1e-5)


def test_standing_beam_is_refused_just_beyond_the_critical_length():
    assemble_beam(rig(support="clamped", orientation="standing", beam={"length": 0.999 * L_GREENHILL}))
    with pytest.raises(BucklingError, match="buckles") as caught:
        assemble_beam(rig(support="clamped", orientation="standing", beam={"length": 1.001 * L_GREENHILL}))
    assert caught.value.critical_load_factor == pytest.approx(1 / 1.001**3, rel=1e-4)
    assert caught.value.bare_critical_length == pytest.approx(L_GREENHILL, rel=1e-5)


def test_the_4m_standing_sheet_buckles_with_its_critical_figures():
    with pytest.raises(BucklingError) as caught:
        assemble_beam(rig(support="clamped", orientation="standing"))
    message = str(caught.value)
    assert "buckles" in message and "L_cr = 1.924 m" in message and "λ_cr = 0.1113" in message
    assert caught.value.critical_load_factor == pytest.approx((L_GREENHILL / L) ** 3, rel=1e-4)


def test_first_frequency_falls_to_zero_as_the_length_approaches_the_critical_one():
    # Near buckling the first mode is close to the buckling mode: ω₁² ≈ ω₁,₀² (1 − 1/λ_cr),
    # with ω₁,₀ the clamped–free frequency without the axial load.
    ratios = []
    for fraction in (0.5, 0.9, 0.99, 0.999):
        length = fraction * L_GREENHILL
        model = assemble_beam(rig(support="clamped", orientation="standing", beam={"length": length}))
        f1 = natural_modes(model, 1).frequencies_hz[0]
        f10 = CLAMPED_FREE_LAMBDA_L[0] ** 2 / (2 * np.pi * length**2) * np.sqrt(EI / MU)
        assert f1 == pytest.approx(f10 * np.sqrt(1 - 1 / model.critical_load_factor), rel=0.02), fraction
        ratios.append(f1 / f10)
    assert np.all(np.diff(ratios) < 0) and ratios[-1] < 0.06


def test_tip_mass_on_a_light_column_buckles_at_eulers_load():
    # Self-weight negligible: P_cr = π² EI / (4 L²) for a column clamped at its foot.
    light = rig(support="clamped", orientation="standing", beam={"density": 1e-6}, gravity=1e-3,
                point_masses=[{"position": L, "mass": 1.0}])
    model = assemble_beam(light, elements=60)
    assert model.critical_load_factor * 1e-3 * 1.0 == pytest.approx(np.pi**2 * EI / (4 * L**2), rel=1e-5)


def test_gravity_stiffens_a_hanging_and_softens_a_standing_clamped_beam():
    def frequencies(**overrides):
        return natural_modes(assemble_beam(rig(support="clamped", beam={"length": 1.5}, **overrides)), 4).frequencies_hz

    none, hanging, standing = frequencies(gravity=0.0), frequencies(), frequencies(orientation="standing")
    assert np.all(hanging > none) and np.all(standing < none)


def _reference(beam_rig, count):
    b = beam_rig.beam
    return clamped_frequencies(
        count, length=b.length, EI=b.youngs_modulus * b.second_moment_of_area, mu=b.mass_per_length,
        masses=[(p.position, p.mass, p.rotary_inertia) for p in beam_rig.point_masses],
        axial_gravity=beam_rig.gravity if beam_rig.orientation == "hanging" else -beam_rig.gravity,
    )


def test_shooting_reference_meets_the_clamped_free_closed_form():
    f = _reference(rig(gravity=0.0, support="clamped"), 4)
    np.testing.assert_allclose(np.sqrt(2 * np.pi * f * np.sqrt(MU / EI)) * L, CLAMPED_FREE_LAMBDA_L, rtol=1e-7)


@pytest.mark.parametrize("orientation", ["hanging", "standing"])
def test_clamped_sheet_of_1_5_m_matches_an_independent_beam_column_solution(orientation):
    # The 1.5 m sheet with four 60 g boards (rotary inertia included) against shooting on the ODE.
    boards = [{"position": p, "mass": 0.06, "rotary_inertia": 5e-5} for p in (0.45, 0.825, 1.05, 1.5)]
    sheet = rig(support="clamped", orientation=orientation, beam={"length": 1.5}, point_masses=boards)
    fe = natural_modes(assemble_beam(sheet), 5).frequencies_hz
    np.testing.assert_allclose(fe, _reference(sheet, 5), rtol=5e-5)


def test_pinned_standing_is_refused_as_an_inverted_pendulum():
    with pytest.raises(RigError, match="inverted pendulum"):
        rig(orientation="standing")


def test_buckling_helpers_refuse_bad_input():
    with pytest.raises(ValueError, match="bending_stiffness=0"):
        greenhill_length(0, MU, 9.81)
    with pytest.raises(ValueError, match="gravity=-1"):
        greenhill_length(EI, MU, -1)
    model = assemble_beam(rig(support="clamped", beam={"length": 1.0}))
    with pytest.raises(ValueError, match="compression=nan"):
        critical_load_factor(model.bending_stiffness, model.tension_stiffness, model.free_dofs, float("nan"))
    assert critical_load_factor(model.bending_stiffness, model.tension_stiffness, model.free_dofs, 0.0) == np.inf
