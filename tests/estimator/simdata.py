"""Simulated measurements for estimator tests, straight from the virtual rig (no files)."""

from __future__ import annotations

import numpy as np

from contract import IMU_BIAXIAL_COLUMNS, IMU_PLANAR_COLUMNS
from estimator import Measurements, SensorSeries
from shm_service.virtual_rig import SensorErrors, SimulationSettings, VirtualRig

NO_ERRORS = SensorErrors(**{name: 0.0 for name in SensorErrors.model_fields if name != "bias_correlation_time"})


def simulate(duration=40.0, *, rest=10.0, seed=1, ideal=True, errors=None, rig=None, **settings):
    """Run the virtual rig; returns (Measurements, truth dict with "t", VirtualRig). A biaxial rig's
    IMUs carry [f_x, f_y, ω_z, f_z, ω_y] (``IMU_BIAXIAL_COLUMNS``)."""
    kwargs = dict(duration=duration, rest=rest, seed=seed, ideal=ideal, **settings)
    if errors is not None:
        kwargs["errors"] = errors
    vr = VirtualRig(SimulationSettings(**kwargs), rig)
    blocks = list(vr.blocks(20.0))
    topics = blocks[0].measurements.keys()
    data = {t: (np.concatenate([b.measurements[t][0] for b in blocks]), np.concatenate([b.measurements[t][1] for b in blocks])) for t in topics}
    truth = {k: np.concatenate([b.truth[k] for b in blocks]) for k in blocks[0].truth}
    truth["t"] = np.concatenate([b.times for b in blocks])
    columns = IMU_BIAXIAL_COLUMNS if vr.plant_rig.beam.biaxial else IMU_PLANAR_COLUMNS
    imu = {t.split("/")[-1]: SensorSeries(v[0], v[1][:, columns]) for t, v in data.items() if t.startswith("/imu/")}
    tof = {t.split("/")[-1]: SensorSeries(*v) for t, v in data.items() if t.startswith("/tof/")}
    strain = {t.split("/")[-1]: SensorSeries(*v) for t, v in data.items() if t.startswith("/strain/")}
    bearing = SensorSeries(*data["/bearing/displacement"]) if "/bearing/displacement" in data else None  # none: fixed support
    return Measurements(imu=imu, tof=tof, strain=strain, bearing=bearing), truth, vr
