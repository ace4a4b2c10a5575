"""Wiring between recordings and the estimator: measurements in, estimates and scores out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import EstimateResult, Measurements, SensorSeries

from .recording import Recording

__all__ = ["TruthSeries", "measurements_from_recording", "truth_from_recording", "score_against_truth"]

_NS = 1e-9


def measurements_from_recording(rec: Recording) -> Measurements:
    """The planar measurements of a recording (times in s from the recording's start)."""
    start = rec.start_ns

    def series(channel, columns) -> SensorSeries:
        return SensorSeries((channel.log_time_ns - start) * _NS, channel.values[:, columns])

    imu, tof, strain, bearing = {}, {}, {}, None
    for topic, channel in rec.channels.items():
        if channel.kind == "imu":
            imu[channel.name] = series(channel, [0, 1, 5])  # accel x, accel y, gyro z
        elif channel.kind == "tof":
            tof[channel.name] = series(channel, [0])
        elif channel.kind == "strain":
            strain[channel.name] = series(channel, [0])
        elif channel.kind == "bearing":
            bearing = series(channel, [0])
    if "D" not in imu:
        raise ValueError(f"{rec.path}: no samples of /imu/D, the IMU at the bearing")
    return Measurements(imu=imu, tof=tof, strain=strain, bearing=bearing)


@dataclass(frozen=True)
class TruthSeries:
    t: np.ndarray
    d: np.ndarray
    h: np.ndarray
    phi: np.ndarray
    e: np.ndarray
    deflection: np.ndarray
    curvature: np.ndarray


def truth_from_recording(rec: Recording) -> TruthSeries | None:
    channel = rec.channels.get("/truth/state")
    if channel is None or len(channel) == 0:
        return None
    v = channel.values
    n_st = (v.shape[1] - 4) // 2
    return TruthSeries((channel.log_time_ns - rec.start_ns) * _NS, v[:, 0], v[:, 1], v[:, 2], v[:, 3],
                       v[:, 4:4 + n_st], v[:, 4 + n_st:4 + 2 * n_st])


def score_against_truth(result: EstimateResult, truth: TruthSeries, *, after: float) -> dict:
    """RMSE of the estimates against the truth at common sample times after ``after`` (s)."""
    idx = np.searchsorted(truth.t, result.t)
    idx = np.clip(idx, 0, truth.t.size - 1)
    match = (np.abs(truth.t[idx] - result.t) < 1e-6) & (result.t >= after)
    if not np.any(match):
        raise ValueError("no estimate coincides with a truth sample after the rest phase")
    i = idx[match]
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    phi_err = result.phi[match] - truth.phi[i]
    e_err = result.e[match] - truth.e[i]
    var_phi = result.P_diag[match, 4]
    return {
        "rmse": {
            "phi_deg": rms(np.degrees(phi_err)),
            "e_m": rms(e_err),
            "d_m": rms(result.d[match] - truth.d[i]),
            "deflection_m": rms(result.deflection()[match] - truth.deflection[i]),
            "curvature_per_m": rms(result.curvature()[match] - truth.curvature[i]),
        },
        "nees": {
            "phi": float(np.mean(phi_err**2 / var_phi)),
            "e": float(np.mean(e_err**2 / result.var_e[match])),
        },
        "scored_samples": int(match.sum()),
    }
