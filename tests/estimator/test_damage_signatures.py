"""Damage signatures from the FE model: signs, agreement with an exact solve, localisation."""

import numpy as np
import pytest

from analytics import beam_third, locate_damage
from estimator import DamageSignatures, PointMass, StiffnessSegment, assemble_beam, damage_signatures, natural_modes
from shm_service.rig_layouts import default_rig


@pytest.fixture(scope="module")
def rig():
    return default_rig()


@pytest.fixture(scope="module")
def sig(rig):
    return damage_signatures(rig)


def _pick(s: DamageSignatures, kind: str, eta: float) -> int:
    return int(np.flatnonzero((np.array(s.kind) == kind) & np.isclose(s.eta, eta))[0])


def test_shapes_signs_and_temperature_slope(sig, rig):
    assert isinstance(sig, DamageSignatures)
    m, n = sig.frequency_shift.shape
    assert n == 5 and sig.curvature_change.shape == (m, 5, len(rig.truth_stations))
    assert sig.units == (0, 0, 1, 2, 3)
    tip = _pick(sig, "mass", 4.0)
    assert np.all(sig.frequency_shift[tip] < -1e-3)  # 1 % of the beam's mass at the tip lowers every mode
    stiff = np.array(sig.kind) == "stiffness"
    assert np.all(sig.frequency_shift[stiff] <= 1e-12)  # a stiffness loss never raises a frequency
    np.testing.assert_allclose(np.sqrt(np.mean(sig.healthy_shapes**2, axis=1)), 1.0)
    # E(T): bending-dominated modes follow about half the modulus coefficient, the pendulum mode not
    half = 0.5 * rig.beam.youngs_modulus_temperature_coefficient
    assert abs(sig.temperature_slope[0]) < 0.1 * abs(half)
    assert half < sig.temperature_slope[4] < 0.7 * half  # gravity tension stiffens it too
    assert np.all(np.diff(sig.temperature_slope) < 0)


def test_signatures_match_an_exact_fe_solve(sig, rig):
    seg = StiffnessSegment(start=1.0, end=1.2, factor=0.8)
    damaged = rig.model_copy(update={"beam": rig.beam.model_copy(update={"stiffness_segments": (seg,)})})
    f0 = natural_modes(assemble_beam(rig, extra_nodes=(1.0, 1.2)), 5).frequencies_hz
    f1 = natural_modes(assemble_beam(damaged, extra_nodes=(1.0, 1.2)), 5).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[_pick(sig, "stiffness", 1.1)], f1 / f0 - 1, rtol=2e-3, atol=1e-7)
    mass = rig.model_copy(update={"point_masses": tuple(rig.point_masses) + (PointMass(position=4.0, mass=0.01 * rig.beam.mass),)})
    f2 = natural_modes(assemble_beam(mass, extra_nodes=(4.0,)), 5).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[_pick(sig, "mass", 4.0)], f2 / f0 - 1, rtol=2e-3, atol=1e-7)


def test_signatures_of_a_clamped_standing_mast_match_an_exact_fe_solve():
    # At the clamp the constrained slope carries no residual; a tip mass's weight compresses the mast.
    from shm_service.rig_layouts import build_rig

    mast = build_rig(length=1.5, support="clamped", orientation="standing")
    sig = damage_signatures(mast, step=0.1, segment_length=0.2)
    assert sig.units == (0, 1, 2, 3)  # no combimode: one mode per unit deformation
    seg = StiffnessSegment(start=0.0, end=0.2, factor=0.8)
    damaged = mast.model_copy(update={"beam": mast.beam.model_copy(update={"stiffness_segments": (seg,)})})
    f0 = natural_modes(assemble_beam(mast, extra_nodes=(0.2,)), 4).frequencies_hz
    f1 = natural_modes(assemble_beam(damaged, extra_nodes=(0.2,)), 4).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[_pick(sig, "stiffness", 0.1)], f1 / f0 - 1, rtol=2e-3, atol=1e-7)
    tip = PointMass(position=1.5, mass=0.01 * mast.beam.mass)
    heavy = mast.model_copy(update={"point_masses": tuple(mast.point_masses) + (tip,)})
    f2 = natural_modes(assemble_beam(heavy, extra_nodes=(1.5,)), 4).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[_pick(sig, "mass", 1.5)], f2 / f0 - 1, rtol=2e-3, atol=1e-7)


@pytest.mark.parametrize("kind, eta", [("stiffness", 2.15), ("stiffness", 0.85), ("mass", 1.25), ("mass", 3.55)])
def test_localisation_of_a_damage_between_candidates(sig, rig, kind, eta):
    """The observed change is the FE model's own prediction for a damage half-way between two
    candidates (a finer candidate grid), with noise; the match picks a neighbouring candidate."""
    fine = damage_signatures(rig, step=0.05, kinds=(kind,))
    j = int(np.argmin(np.abs(fine.eta - eta)))
    assert fine.eta[j] == pytest.approx(eta)
    rng = np.random.default_rng(11)
    f_std = np.full(5, 2e-4)
    k_std = np.full(5, 3e-3)
    df = 0.8 * fine.frequency_shift[j] + f_std * rng.standard_normal(5)
    dk = 0.8 * fine.curvature_change[j] + k_std[:, None] * rng.standard_normal(fine.curvature_change[j].shape)
    loc = locate_damage(df, f_std, sig, shape_change=dk, shape_std=k_std)
    assert abs(loc.eta_m - eta) <= 0.1 + 1e-9
    assert loc.kind_best == kind and loc.third == beam_third(eta, rig.beam.length)
    assert loc.best_match > 0.8 and loc.severity == pytest.approx(0.8, rel=0.3)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(stiffness_factor=1.0), "stiffness_factor"),
        (dict(segment_length=5.0), "segment_length"),
        (dict(mass_fraction=-0.01), "mass_fraction"),
        (dict(kinds=("crack",)), "kinds"),
        (dict(stations=[0.5, 9.0]), "stations"),
        (dict(gamma=7), "gamma"),
        (dict(step=0.0), "step"),
    ],
)
def test_bad_inputs(rig, kwargs, match):
    with pytest.raises(ValueError, match=match):
        damage_signatures(rig, **kwargs)
    with pytest.raises(ValueError, match="RigDescription"):
        damage_signatures({"beam": {}})
