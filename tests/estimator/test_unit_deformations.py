"""Unit deformations: body-frame conditions, normalisation, the combimode, exact derivatives."""

import numpy as np
import pytest

from estimator import MAX_UNIT_DEFORMATIONS, assemble_beam, natural_modes, unit_deformations
from shm_service.rig_layouts import default_rig


@pytest.fixture(scope="module")
def model():
    return assemble_beam(default_rig())


@pytest.fixture(scope="module")
def units(model):
    return unit_deformations(model, MAX_UNIT_DEFORMATIONS)


def test_body_frame_conditions_and_unit_norm(units):
    np.testing.assert_allclose(units.shape(0.0), 0.0, atol=1e-14)
    np.testing.assert_allclose(units.slope(0.0), 0.0, atol=1e-14)
    grid = np.linspace(0.0, units.length, 20001)
    np.testing.assert_allclose(np.abs(units.shape(grid)).max(axis=0), 1.0, rtol=1e-6)


def test_mapping_to_eigenmodes_follows_table1(units, model):
    assert units.modes == ((1, 2), (3,), (4,), (5,), (6,))
    freqs = natural_modes(model, 6).frequencies_hz
    assert units.frequencies_hz[0] == pytest.approx(tuple(freqs[:2]))
    assert [f[0] for f in units.frequencies_hz[1:]] == pytest.approx(list(freqs[2:]))


def test_unit_deformations_are_transformed_eigenmodes(units, model):
    modes = natural_modes(model, 6)
    grid = np.linspace(0.0, units.length, 401)
    w = modes.shapes.evaluate(grid)
    transformed = w - np.outer(grid, modes.shapes.evaluate(0.0, 1))
    # Unit deformation 2 is mode 3 in the body frame, up to its scale.
    s2 = units.shape(grid)[:, 1]
    scale = (transformed[:, 2] @ s2) / (transformed[:, 2] @ transformed[:, 2])
    np.testing.assert_allclose(scale * transformed[:, 2], s2, atol=1e-9)
    # The combimode lies in the span of the transformed modes 1 and 2 and is their dominant shape.
    pair = transformed[:, :2]
    coeff, *_ = np.linalg.lstsq(pair, units.shape(grid)[:, 0], rcond=None)
    np.testing.assert_allclose(pair @ coeff, units.shape(grid)[:, 0], atol=1e-9)


def test_derivatives_are_exact_interpolation(units):
    # s' and s'' are derivatives of the same Hermite interpolant: central differences agree.
    eta = np.array([0.37, 1.11, 2.53, 3.333, 3.87])  # inside elements: s'' jumps at nodes
    step = 1e-5
    slope_fd = (units.shape(eta + step) - units.shape(eta - step)) / (2 * step)
    curvature_fd = (units.slope(eta + step) - units.slope(eta - step)) / (2 * step)
    np.testing.assert_allclose(units.slope(eta), slope_fd, atol=1e-7)
    np.testing.assert_allclose(units.curvature(eta), curvature_fd, atol=1e-5)


def test_tip_is_positive_and_subset_keeps_order(units):
    assert np.all(units.shape(units.length) > 0)
    sub = units.subset(3)
    np.testing.assert_array_equal(sub.shapes.dofs, units.shapes.dofs[:, :3])


def test_without_combimode_each_mode_is_its_own_unit(model):
    separate = unit_deformations(model, 3, combimode=False)
    assert separate.modes == ((1,), (2,), (3,))


@pytest.mark.parametrize("count", [0, 6, 2.5])
def test_bad_count_is_refused(model, count):
    with pytest.raises(ValueError, match="count="):
        unit_deformations(model, count)


@pytest.fixture(scope="module")
def clamped_model():
    from shm_service.rig_layouts import build_rig

    return assemble_beam(build_rig(length=1.5, support="clamped", orientation="standing"))


def test_clamped_support_has_no_combimode_and_each_unit_is_its_own_mode(clamped_model):
    units = unit_deformations(clamped_model, MAX_UNIT_DEFORMATIONS)
    assert units.modes == ((1,), (2,), (3,), (4,), (5,))
    modes = natural_modes(clamped_model, 5)
    assert [f[0] for f in units.frequencies_hz] == pytest.approx(list(modes.frequencies_hz))
    grid = np.linspace(0.0, units.length, 401)
    w = modes.shapes.evaluate(grid)
    # The clamp's frame is the body frame: unit χ is eigenmode χ scaled to max |s| = 1.
    scale = np.abs(modes.shapes.evaluate(np.linspace(0.0, units.length, 4001))).max(axis=0)
    np.testing.assert_allclose(units.shape(grid), w / scale, atol=1e-9)
    np.testing.assert_array_equal(units.shape(0.0), 0.0)
    np.testing.assert_array_equal(units.slope(0.0), 0.0)


def test_combimode_follows_the_support_unless_told(model, clamped_model):
    assert unit_deformations(model, 2).modes == ((1, 2), (3,))  # pinned: the combimode
    assert unit_deformations(natural_modes(clamped_model, 3), 2).modes == ((1,), (2,))  # from the modes' support
    assert unit_deformations(clamped_model, 2, combimode=True).modes == ((1, 2), (3,))
    assert unit_deformations(model, 2, combimode=False).modes == ((1,), (2,))


def test_bad_combimode_is_refused(model):
    with pytest.raises(ValueError, match="combimode='yes'"):
        unit_deformations(model, 2, combimode="yes")
