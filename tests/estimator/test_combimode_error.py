"""The gauges' model error from the combimode: what it is and what it explains."""

import numpy as np
import pytest

from estimator import assemble_beam, build_model, unit_deformations
from shm_service.rig_layouts import build_rig


def _tip_as_read(units, pair, rows_units, rows_pair, k):
    """Tip of mode k of the pair as the least squares over ``rows`` reads it, over its own tip."""
    b = np.linalg.lstsq(rows_units, rows_pair[:, k], rcond=None)[0]
    L = units.length
    return float(np.atleast_1d(units.shape(L)) @ b) / float(np.atleast_1d(pair.shape(L))[k])


def test_gauges_misread_the_first_mode_where_the_imus_do_not():
    # The reason for the model error: the combimode is s̃₂, so every path reads mode 2 exactly;
    # the four benchmark gauges read the first mode's tip ~4 % off, the IMUs (deflections or
    # slopes) within 0.3 %.
    rig = build_rig("benchmark")
    beam = assemble_beam(rig)
    units = unit_deformations(beam, 4)
    pair = unit_deformations(beam, 2, combimode=False)
    model = build_model(rig, peripheral="acc")
    g, imu = model.gauge_eta, model.imu_eta
    strain = [_tip_as_read(units, pair, units.curvature(g), pair.curvature(g), k) for k in range(2)]
    acc = [_tip_as_read(units, pair, units.shape(imu), pair.shape(imu), k) for k in range(2)]
    gyro = [_tip_as_read(units, pair, units.slope(imu), pair.slope(imu), k) for k in range(2)]
    assert strain[1] == pytest.approx(1.0, abs=1e-9) and acc[1] == pytest.approx(1.0, abs=1e-9)
    assert gyro[1] == pytest.approx(1.0, abs=1e-9)
    assert 0.01 < abs(strain[0] - 1) < 0.08, strain
    assert abs(acc[0] - 1) < 0.003 and abs(gyro[0] - 1) < 0.003, (acc, gyro)


@pytest.mark.parametrize("peripheral", ["gyro", "acc"])
def test_combimode_strain_errors_are_the_conflict_per_unit_b1(peripheral):
    rig = build_rig("benchmark")
    model = build_model(rig, peripheral=peripheral)
    u = model.combimode_strain_errors()
    assert u.shape == (len(model.selection.gauges), 2)
    # µε per unit b1 (m): a 0.1 m combimode amplitude would give gauge errors of a few tenths of a
    # µε up to ~1 µε if it were all mode 1, comparable to the gauges' noise and far below their
    # signal (~100 µε). Mode 2 is the combimode's own shape: no conflict.
    assert 1e-7 < np.abs(u[:, 0]).max() < 2e-5
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-12)


def test_no_combimode_no_error_term():
    rig = build_rig("benchmark", support="clamped")
    model = build_model(rig, peripheral="gyro")
    assert model.combimode_strain_errors().shape == (len(model.selection.gauges), 0)
