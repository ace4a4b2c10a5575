"""Rigs without ToFs and without a bearing sensor (a mast on its foundation): the contract's keys,
the estimator's fixed support (d ≡ 0) and its refusal of rigs that cannot observe Γ unit
deformations, against the virtual rig's truth."""

import numpy as np
import pytest
from simdata import simulate

from contract import RigError, parse_rig
from estimator import build_model, estimate


def _mast(*, gauges=(0.5, 4.0, 8.5, 13.0), imus=(6.0, 11.0, 15.5, 20.0), bearing=False, **overrides):
    """A 20 m standing clamped steel mast, uniform (a rectangle with a 300 × 6 mm tube's EI and μ),
    IMUs and strain gauges only: no ToF, no reflector, and without a bearing sensor."""
    description = {
        "beam": {"length": 20.0, "width": 0.01539, "thickness": 0.3603, "youngs_modulus": 2.1e11, "density": 7850.0},
        "gravity": 9.81,
        "support": "clamped",
        "orientation": "standing",
        "point_masses": [{"position": 20.0, "mass": 15.0}],
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]
        + [{"name": f"s{j}", "kind": "imu", "position": p} for j, p in enumerate(imus, start=1)]
        + [{"name": f"g{j}", "kind": "strain", "position": p} for j, p in enumerate(gauges, start=1)]
        + ([{"name": "bearing", "kind": "bearing"}] if bearing else []),
        "truth_stations": [5.0, 10.0, 15.0, 20.0],
    }
    description.update(overrides)
    return parse_rig(description)


def test_reflector_distance_is_required_exactly_with_tofs():
    rig = _mast()
    assert rig.reflector_distance is None
    assert rig.support_fixed_to_ground
    assert not _mast(bearing=True).support_fixed_to_ground
    data = rig.model_dump(mode="json")
    data["sensors"].append({"name": "t1", "kind": "tof", "position": 10.0})
    with pytest.raises(RigError, match=r"reflector_distance is required: the rig has ToF sensors \(t1\)"):
        parse_rig(data)
    data["reflector_distance"] = 0.5
    assert parse_rig(data).reflector_distance == 0.5
    with pytest.raises(RigError, match="reflector_distance=nan must be finite"):
        parse_rig({**data, "reflector_distance": float("nan")})


def test_fixed_support_keeps_the_state_layout_and_tells_the_filter_d_is_zero():
    model = build_model(_mast())
    assert model.fixed_support
    assert model.state_layout.names[:4] == ("d", "h", "d_rate", "h_rate")
    assert model.aiding_channels == ["/strain/g1", "/strain/g2", "/strain/g3", "/strain/g4", "pseudo:d", "pseudo:h",
                                     "pseudo:h_rate"]
    assert build_model(_mast(bearing=True)).aiding_channels[4] == "/bearing/displacement"


def test_a_rig_that_cannot_observe_its_unit_deformations_is_refused_naming_what_is_missing():
    # Two gauges and no ToF: two of the four unit deformations have no aiding and would drift.
    with pytest.raises(ValueError, match=r"cannot observe b\d \(mode \d\), b\d \(mode \d\) of the Γ=4 unit deformations.*"
                                         r"ToFs: none; strain gauges: g1 at 0.5 m, g2 at 4 m aiding b3,4.*add 2 strain gauge"):
        build_model(_mast(gauges=(0.5, 4.0)))
    # Neither ToFs nor gauges: nothing holds b.
    with pytest.raises(ValueError, match=r"b1 \(mode 1\), b2 \(mode 2\), b3 \(mode 3\), b4 \(mode 4\).*add 4 strain gauge"):
        build_model(_mast(gauges=()))
    # Four IMUs at one position see one combination of the unit deformations.
    with pytest.raises(ValueError, match=r"peripheral IMUs \(gyro: s1 at 10 m, .*\) cannot tell the Γ=4 unit deformations "
                                         r"apart.*rank 1 of 4.*add 3 peripheral IMU"):
        build_model(_mast(imus=(10.0, 10.0, 10.0, 10.0)))
    with pytest.raises(ValueError, match=r"need at least 4 peripheral IMUs \(gyro\), got 3 \(the rig has 3\): add 1 peripheral IMU"):
        build_model(_mast(imus=(6.0, 11.0, 20.0)))
    # With fewer unit deformations the same rigs work.
    assert build_model(_mast(gauges=(0.5, 4.0)), modes=2).gamma == 2
    assert build_model(_mast(gauges=()), check_observable=False).gamma == 4


@pytest.fixture(scope="module")
def mast_run():
    """60 s of the mast in the wind (operational, realistic sensor errors), support fixed."""
    return simulate(duration=60.0, rest=20.0, seed=4, ideal=False, excitation="operational", rig=_mast(),
                    plant={"modes": 6})


@pytest.mark.parametrize("peripheral", ["gyro", "acc"])
def test_mast_without_tofs_and_bearing_estimates_with_bounded_d_and_its_tip(mast_run, peripheral):
    meas, truth, vr = mast_run
    assert meas.bearing is None and not meas.tof
    assert np.all(truth["d"] == 0.0)
    result = estimate(meas, build_model(vr.nominal_rig, peripheral=peripheral))
    # d ≡ 0 is told to the filter: it stays at the foundation's micrometres (it drifted to metres).
    assert np.max(np.abs(result.d)) < 1e-3
    after = result.t > result.calibration.rest_end + 15.0
    e_true = np.interp(result.t[after], truth["t"], truth["e"])
    rms = np.sqrt(np.mean(e_true**2))
    assert rms > 5e-3  # the wind moves the tip by millimetres: a real test of the estimate
    error = np.sqrt(np.mean((result.e[after] - e_true) ** 2))
    assert error <= 0.05 * rms
    assert result.diagnostics["aiding"]["pseudo:d"]["rejected"] == 0
