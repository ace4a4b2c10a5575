"""A recording written by another tool to the contract feeds the reader and the estimator unchanged."""

import numpy as np

from benchmarks.other_tool import write_other_tool_recording
from estimator import build_model, estimate
from shm_service.processing.estimation import measurements_from_recording, score_against_truth, truth_from_recording
from shm_service.recording import read_recording
from shm_service.virtual_rig import SensorErrors, SimulationSettings


def test_other_tools_recording_meets_the_estimator_bars(tmp_path):
    path = tmp_path / "other.mcap"
    errors = SensorErrors(tof_time_offset=0.004)
    write_other_tool_recording(path, SimulationSettings(duration=150, rest=30, seed=11, ideal=True, errors=errors))
    rec = read_recording(path)
    assert rec.report.problems == [] or all("silent" not in p for p in rec.report.problems)
    tof_times = rec.channels["/tof/s1"].log_time_ns - rec.channels["/imu/D"].log_time_ns[0]
    assert np.all(tof_times % 5_000_000 != 0)  # off the IMU grid
    meas = measurements_from_recording(rec)
    truth = truth_from_recording(rec)
    for peripheral, e_bar in (("gyro", 1e-3), ("acc", 2e-3)):
        result = estimate(meas, build_model(rec.rig, peripheral=peripheral))
        rmse = score_against_truth(result, truth, after=result.calibration.rest_end)["rmse"]
        assert rmse["phi_deg"] <= 0.02 and rmse["e_m"] <= e_bar, (peripheral, rmse)
