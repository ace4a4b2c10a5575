"""The plausibility and stuck-sensor stage (``SampleChecks``) on small hand-made blocks."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from shm_service.recording import FollowBlock
from shm_service.service.stages._checks import CheckSettings, SampleChecks
from shm_service.recording._plausibility import ValueLimits

_MS = 1_000_000  # ns


def _imu(times_ms, values=None) -> FollowBlock:
    t = np.asarray(times_ms, dtype=np.int64) * _MS
    v = np.tile([-9.81, 0.0, 0.0, 0.0, 0.0, 0.0], (len(t), 1)) if values is None else np.asarray(values, dtype=float)
    return FollowBlock("/imu/D", "imu", "D", t, t.copy(), v)


def test_samples_judged_by_the_source_pass_unchanged():
    checks = SampleChecks()  # no clock, no limits: ingest judged them
    block = _imu([1, 2, 2, 1])
    assert checks.judge([block]) == [block] and not checks.rejected


def test_duplicates_and_samples_going_backwards_are_refused_and_counted():
    checks = SampleChecks(limits=ValueLimits())
    (out,) = checks.judge([_imu([1, 2, 2, 3, 1])], newest_ns=7)
    assert out.log_time_ns.tolist() == [1 * _MS, 2 * _MS, 3 * _MS]
    assert checks.rejected == {"duplicate": 1, "backwards": 1}
    assert checks.refused_at == {"/imu/D": 7}
    # the next block continues after 3 ms: its sample at 3 ms is a duplicate
    (out,) = checks.judge([_imu([3, 4])], newest_ns=8)
    assert out.log_time_ns.tolist() == [4 * _MS] and checks.rejected["duplicate"] == 2


def test_readings_beyond_the_limits_and_non_finite_ones_are_refused():
    values = np.tile([-9.81, 0.0, 0.0, 0.0, 0.0, 0.0], (4, 1))
    values[1, 0] = 5000.0  # beyond 2000 m/s²
    values[2, 5] = np.nan
    checks = SampleChecks(limits=ValueLimits())
    (out,) = checks.judge([_imu([1, 2, 3, 4], values)])
    assert out.log_time_ns.tolist() == [1 * _MS, 4 * _MS]
    assert checks.rejected == {"implausible_value": 1, "nonfinite": 1}


def test_a_reading_unchanged_for_stuck_after_s_marks_the_sensor_stuck():
    checks = SampleChecks(CheckSettings(stuck_after_s=1.0))
    checks.watch_stuck(_imu(range(0, 900, 5)))  # 0.895 s the same
    assert checks.stuck_sensors() == []
    checks.watch_stuck(_imu(range(900, 1010, 5)))  # 1.005 s the same, across two blocks
    assert checks.stuck_sensors() == ["/imu/D"]
    noisy = np.tile([-9.81, 0.0, 0.0, 0.0, 0.0, 0.0], (3, 1))
    noisy[2, 1] = 1e-3
    checks.watch_stuck(_imu([1010, 1015, 1020], noisy))  # it changed at 1.020 s
    assert checks.stuck_sensors() == []


def test_a_sensor_refused_recently_is_degraded_for_silent_after_s():
    checks = SampleChecks(CheckSettings(silent_after_s=2.0))
    checks.note_refused(("/tof/1",), 10 * 1_000_000_000)
    assert checks.degraded(11 * 1_000_000_000) == {"/tof/1"}
    assert checks.degraded(int(12.5 * 1_000_000_000)) == set()


@pytest.mark.parametrize("field", ["stuck_after_s", "silent_after_s"])
def test_the_settings_refuse_a_non_positive_time(field):
    with pytest.raises(ValidationError, match=field):
        CheckSettings(**{field: 0.0})
