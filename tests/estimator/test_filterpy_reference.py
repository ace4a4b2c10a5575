"""The project's filter and a straightforward filterpy loop on the same model agree."""

import numpy as np
import pytest
from simdata import simulate

from estimator import FilterConfig, ImmsFilter, build_events, build_model, calibrate_at_rest
from estimator._filterpy_reference import run_filterpy


@pytest.mark.parametrize(("peripheral", "rig"), [
    ("gyro", {}),
    ("acc", {}),
    # The fixed bearing (no φ, a residual mode) and a standing mast: the same agreement.
    ("gyro", {"support": "clamped"}),
    ("acc", {"support": "clamped", "orientation": "standing", "length": 1.5}),
])
def test_project_filter_matches_filterpy(peripheral, rig):
    duration = 60.0 if not rig else 24.0
    meas, truth, vr = simulate(duration=duration, rest=4.0, seed=4, ideal=False, **rig)
    model = build_model(vr.nominal_rig, peripheral=peripheral, modes=4)
    config = FilterConfig()
    calibration = calibrate_at_rest(meas, model, config)
    events = build_events(meas, model)
    ours = ImmsFilter(model, calibration, config, t0=meas.start)
    parts = [ours.process(events.slice(lo, lo + 5000)) for lo in range(0, len(events), 5000)] + [ours.flush()]
    t = np.concatenate([p.t for p in parts])
    x = np.concatenate([p.x for p in parts])
    P = np.concatenate([p.P_diag for p in parts])
    reference = run_filterpy(events, model, calibration, config, t0=meas.start)
    np.testing.assert_array_equal(t, reference.t)
    layout = model.state_layout
    # the beam moved: not a trivial comparison (the 1.5 m mast's b1 stays below 1 mm in 24 s)
    assert np.abs(x[:, layout.b.start]).max() > 3e-4
    if layout.phi is not None:
        assert np.abs(x[:, layout.phi]).max() > 1e-4
    else:
        assert layout.residual == 1 and np.abs(x[:, layout.residual_modes]).max() > 1e-6
    scale = np.maximum(np.abs(reference.x).max(axis=0), 1e-6)
    np.testing.assert_allclose(x / scale, reference.x / scale, rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, reference.P_diag, rtol=1e-7, atol=1e-20)
