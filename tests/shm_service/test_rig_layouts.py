"""The shipped rig layouts and their calibration against the paper's Table 1."""

import numpy as np
import pytest

from estimator import TABLE1_HZ, modal_frequencies, unit_deformations, assemble_beam
from shm_service.rig_layouts import (
    CALIBRATED,
    CALIBRATION_WEIGHTS,
    build_rig,
    calibrated_parameters,
    default_rig,
    frozen_calibration_identifiability,
)


def test_default_rig_meets_table1():
    error = modal_frequencies(default_rig()) / np.array(TABLE1_HZ) - 1
    assert np.all(np.abs(error[:4]) <= 0.01), error  # the bar is 2 %; we hold 1 %
    assert np.all(np.abs(error[4:]) <= 0.10), error


@pytest.fixture(scope="module")
def update():
    return calibrated_parameters()


@pytest.fixture(scope="module")
def frozen():
    return frozen_calibration_identifiability()


def test_frozen_calibration_is_what_the_update_finds(update, frozen):
    # What the six frequencies determine must come out again on any CPU and BLAS kernel: the
    # fitted frequencies, the cost and the parameters within their posterior σ. The individual
    # values of parameters the frequencies do not see (the boards' rotary inertia) move along a
    # flat valley of the cost with the kernel's rounding and are not compared tighter than that.
    sigma = frozen.frequency_std  # relative σ of a weight-1 target (~0.4 %)
    # each frequency within a tenth of its target's σ (σ / weight)
    tolerance = 0.1 * sigma / np.asarray(CALIBRATION_WEIGHTS)
    shift = update.frequencies_hz / frozen.frequencies_hz - 1
    assert np.all(np.abs(shift) <= tolerance), shift
    # the cost within Δχ² = 0.01 of the frozen point's (cost = ½ χ² σ²)
    assert abs(update.cost - frozen.cost) <= 0.5 * 0.01 * sigma**2, (update.cost, frozen.cost)
    for name, std in zip(frozen.names, frozen.std):
        assert abs(update.values[name] - CALIBRATED[name]) <= std, name
    assert np.all(np.abs(update.relative_error[:4]) <= 0.01)


def test_calibration_reports_what_the_frequencies_do_not_determine(update, frozen):
    for ident in (update.identifiability, frozen):
        resolution = dict(zip(ident.names, ident.resolution))
        assert resolution["youngs_modulus"] > 0.7  # E is what the frequencies fix
        assert resolution["board_rotary_inertia"] < 0.01  # the boards' rotary inertia is the prior alone
        assert "board_rotary_inertia" in ident.undetermined and "youngs_modulus" not in ident.undetermined
        # the weakest combination of the weighted relative sensitivities is the boards' rotary inertia
        assert abs(ident.combinations[-1][ident.names.index("board_rotary_inertia")]) > 0.9
        assert ident.singular_values[-1] < 1e-3 * ident.singular_values[0]
        assert ident.at_bound == ()


def test_calibrated_parameters_are_physical():
    assert 1.9e11 <= CALIBRATED["youngs_modulus"] <= 2.15e11
    assert 0.02 <= CALIBRATED["board_mass"] <= 0.15


def test_layouts_have_the_papers_sensor_counts():
    bench = default_rig("benchmark")
    dense = default_rig("dense")
    count = lambda rig, kind: len(rig.sensors_of(kind))  # noqa: E731
    assert (count(bench, "imu"), count(bench, "tof"), count(bench, "strain"), count(bench, "bearing")) == (5, 4, 4, 1)
    assert (count(dense, "imu"), count(dense, "tof"), count(dense, "strain")) == (18, 17, 12)


def test_benchmark_layout_separates_four_unit_deformations():
    rig = default_rig()
    units = unit_deformations(assemble_beam(rig), 4)
    boards = [s.position for s in rig.sensors_of("imu") if s.name != "D"]
    gauges = [s.position for s in rig.sensors_of("strain")]
    assert np.linalg.cond(units.slope(np.array(boards))) < 5
    assert np.linalg.cond(units.curvature(np.array(gauges))) < 5


def test_unknown_layout_and_missing_parameters_are_refused():
    with pytest.raises(ValueError, match="layout='sparse'"):
        build_rig("sparse")
    with pytest.raises(ValueError, match="board_mass"):
        build_rig("benchmark", {"youngs_modulus": 2e11, "board_rotary_inertia": 0, "bearing_rotary_inertia": 0})
