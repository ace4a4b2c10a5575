"""What runs in the worker processes: simulate one seed, estimate one configuration on it, score.

Tasks carry only paths and a configuration; every worker reads the recording itself and keeps
the last one it read (tasks arrive grouped by seed), so little crosses the process boundary.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._config import Configuration, StudySettings

# Per-process caches: the last recording (rig, measurements, truth) and benchmark series read.
_RECORDING: dict[str, tuple] = {}
_BENCHMARK: dict[str, dict[str, np.ndarray]] = {}


@dataclass(frozen=True)
class SimulationTask:
    settings: StudySettings
    seed: int
    path: str


@dataclass(frozen=True)
class EstimateTask:
    seed: int
    recording: str
    benchmark: str  # .npz of the gyro benchmark of this seed (written by the benchmark task)
    config: Configuration
    want_series: bool = False
    is_benchmark: bool = False  # the study's reference configuration (it writes ``benchmark``)


@dataclass(frozen=True)
class RunOutcome:
    seed: int
    config: Configuration
    selection: dict  # sensor names chosen by EfI
    rmse_truth: dict[str, float]  # phi_deg, e_m, deflection_m
    rmse_benchmark: dict  # phi_deg, e_m, b (list of Γ)
    filter_seconds: float
    series: dict[str, np.ndarray] | None  # t, phi, e, b (float32), when asked for


def simulate_seed(task: SimulationTask) -> str:
    from ..virtual_rig import PlantSettings, SimulationSettings, simulate

    s = task.settings
    rig = s.rig_description() if s.rig is not None else None
    # the bearing's friction acts on a pinned support's rotation; a clamp has none
    friction = s.friction_torque if rig is None or rig.support == "pinned" else 0.0
    common = {"duration": s.duration, "seed": task.seed, "excitation": s.excitation, "ideal": s.ideal, "rest": s.rest,
              "plant": PlantSettings(friction_torque=friction)}
    if rig is None:
        settings = SimulationSettings(layout=s.layout, **common)
    else:
        settings = SimulationSettings(support=rig.support, orientation=rig.orientation, **common)
    simulate(settings, task.path, rig=rig)
    return task.path


def _load_recording(path: str) -> tuple:
    if path not in _RECORDING:
        from ..processing.estimation import measurements_from_recording, truth_from_recording
        from ..recording import read_recording

        _RECORDING.clear()
        rec = read_recording(path)
        truth = truth_from_recording(rec)
        if truth is None:
            raise ValueError(f"{path}: the recording carries no /truth/state; the study needs simulated recordings")
        _RECORDING[path] = (rec.rig, measurements_from_recording(rec), truth)
    return _RECORDING[path]


def _load_benchmark(path: str) -> dict[str, np.ndarray]:
    if path not in _BENCHMARK:
        _BENCHMARK.clear()
        with np.load(path) as data:
            _BENCHMARK[path] = {k: data[k] for k in data.files}
    return _BENCHMARK[path]


def _rms(a: np.ndarray, axis=None):
    return np.sqrt(np.mean(np.square(a), axis=axis))


def score_against_benchmark(t, phi, e, b, rest_end: float, bench: dict[str, np.ndarray]) -> dict:
    """Eq. (21): RMSE against the benchmark's estimates at the same instants after both rest phases."""
    after = max(float(rest_end), float(bench["rest_end"]))
    if t.shape == bench["t"].shape and np.array_equal(t, bench["t"]):
        ref_phi, ref_e, ref_b = bench["phi"], bench["e"], bench["b"]
    else:  # different sample instants: the benchmark interpolated onto this run's times
        ref_phi = np.interp(t, bench["t"], bench["phi"])
        ref_e = np.interp(t, bench["t"], bench["e"])
        ref_b = np.column_stack([np.interp(t, bench["t"], bench["b"][:, k]) for k in range(b.shape[1])])
    mask = (t >= after) & (t <= bench["t"][-1])
    if not np.any(mask):
        raise ValueError("no estimate after the rest phase overlaps the benchmark")
    return {
        "phi_deg": float(np.degrees(_rms(phi[mask] - ref_phi[mask]))),
        "e_m": float(_rms(e[mask] - ref_e[mask])),
        "b": [float(v) for v in _rms(b[mask] - ref_b[mask], axis=0)],
    }


def _truth_at(truth, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = np.clip(np.searchsorted(truth.t, t), 0, truth.t.size - 1)
    ok = np.abs(truth.t[idx] - t) < 1e-6
    return np.where(ok, truth.phi[idx], np.nan), np.where(ok, truth.e[idx], np.nan)


def estimate_configuration(task: EstimateTask) -> RunOutcome:
    from estimator import build_model, estimate

    from ..processing.estimation import score_against_truth

    rig, meas, truth = _load_recording(task.recording)
    c = task.config
    model = build_model(rig, peripheral=c.peripheral, modes=c.modes, imus=c.imus, tofs=c.tofs, gauges=c.gauges,
                        aided=c.aided if c.gauges else None)
    result = estimate(meas, model)
    rest_end = float(result.calibration.rest_end)
    t, phi, e, b = result.t, result.phi, result.e, result.b
    rmse = score_against_truth(result, truth, after=rest_end)["rmse"]
    if task.is_benchmark:
        truth_phi, truth_e = _truth_at(truth, t)
        Path(task.benchmark).parent.mkdir(parents=True, exist_ok=True)
        tmp = task.benchmark + ".part.npz"
        np.savez(tmp, t=t, phi=phi, e=e, b=b, rest_end=rest_end, truth_phi=truth_phi, truth_e=truth_e)
        Path(tmp).replace(task.benchmark)
        # the arrays and rest_end: a scalar here, a 0-d array when _load_benchmark reads the file
        bench: dict[str, Any] = {"t": t, "phi": phi, "e": e, "b": b, "rest_end": np.float64(rest_end)}
    else:
        bench = _load_benchmark(task.benchmark)
    series: dict[str, Any] | None = None  # arrays and the scalar rest_end
    if task.want_series:
        series = {"t": t, "phi": phi.astype(np.float32), "e": e.astype(np.float32), "b": b.astype(np.float32),
                  "rest_end": np.float64(rest_end)}
    return RunOutcome(
        seed=task.seed,
        config=c,
        selection=model.selection.as_dict(),
        rmse_truth={"phi_deg": rmse["phi_deg"], "e_m": rmse["e_m"], "deflection_m": rmse["deflection_m"]},
        rmse_benchmark=score_against_benchmark(t, phi, e, b, rest_end, bench),
        filter_seconds=float(result.filter_seconds),
        series=series,
    )
