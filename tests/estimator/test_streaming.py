"""The streaming estimator's bookkeeping on hand-made samples (the b(t) it gives is checked
through every entry point by tests/shm_service/test_one_estimator.py)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from estimator import StreamingEstimator, StreamingSettings, build_model
from shm_service.rig_layouts import default_rig

_NS = 1_000_000_000
T0 = 1_767_225_600 * _NS + 250_000_000  # a quarter second into a UNIX second


def _d(seconds: float, start_ns: int = T0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    t = start_ns + np.arange(int(seconds * 200)) * 5_000_000
    v = np.tile([-9.81, 0.0, 0.0, 0.0, 0.0, 0.0], (len(t), 1))
    return {"/imu/D": (t.astype(np.int64), v)}


@pytest.fixture(scope="module")
def model():
    return build_model(default_rig("benchmark"))


def test_it_gathers_calibration_s_before_it_calibrates(model):
    est = StreamingEstimator(model, StreamingSettings(calibration_s=10.0, chunk_s=1.0))
    assert est.feed(_d(3.0)) is None
    assert est.epoch_ns == T0 - 250_000_000  # the first sample's whole second
    assert est.calibration is None and est.state == "calibrating"
    assert est.buffer_span == (T0, T0 + (600 - 1) * 5_000_000)
    assert est.feed({"/unknown": (np.array([T0]), np.zeros((1, 1)))}) is None  # not the rig's: ignored


def test_a_calibration_without_the_reference_imu_waits_and_counts_what_it_drops(model):
    est = StreamingEstimator(model, StreamingSettings(calibration_s=5.0, chunk_s=1.0))
    other = {"/imu/s1": _d(6.0)["/imu/D"]}
    est.feed(other)
    assert est.calibration is None and est.state == "waiting for /imu/D" and est.dropped == 1000


@pytest.mark.parametrize("field, value", [("chunk_s", 0.0), ("calibration_s", -1.0), ("gap_reset_s", 0.0)])
def test_the_settings_name_a_bad_value(field, value):
    with pytest.raises(ValidationError, match=field):
        StreamingSettings(**{field: value})
