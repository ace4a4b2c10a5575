"""Issue 3's bars: accuracy over five seeds (ideal, realistic, another tool's recordings),
consistency (NEES), and speed side by side with the straightforward filterpy loop.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_estimator [--quick]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.stats

from benchmarks.other_tool import write_other_tool_recording
from estimator import FilterConfig, ImmsFilter, build_events, build_model, calibrate_at_rest, estimate
from estimator._filterpy_reference import run_filterpy
from shm_service.estimation import measurements_from_recording, truth_from_recording
from shm_service.recording import read_recording
from shm_service.study import StudySettings
from shm_service.virtual_rig import SimulationSettings, simulate


def _errors(result, truth, after):
    i = np.searchsorted(truth.t, result.t)
    m = result.t >= after
    return (result.phi - truth.phi[i])[m], (result.e - truth.e[i])[m], result.P_diag[m, result.model.state_layout.phi], result.var_e[m]


def accuracy(workdir: Path, seeds, duration: float) -> None:
    print(f"\n== accuracy: paper excitation, {duration:.0f} s, benchmark layout, Γ = 4, seeds {list(seeds)} ==")
    print(f"{'plant':10} {'periph':6} {'RMSE phi [deg]':>22} {'RMSE e [mm]':>20} {'NEES phi':>9} {'NEES e':>8} {'in band':>8}")
    plants = {
        "ideal": dict(ideal=True),
        "realistic": dict(ideal=False),
        "+friction": dict(ideal=False, plant={"friction_torque": StudySettings.model_fields["friction_torque"].default}),  # the study's plant
        "other-tool": dict(ideal=True),
    }
    for plant, options in plants.items():
        recs = []
        for seed in seeds:
            path = workdir / f"{plant}-{seed}.mcap"
            settings = SimulationSettings(duration=duration, seed=seed, **options)
            if plant == "other-tool":
                write_other_tool_recording(path, settings.model_copy(update={"errors": settings.errors.model_copy(update={"tof_time_offset": 0.003})}))
            else:
                simulate(settings, path)
            recs.append(read_recording(path))
        for peripheral in ("gyro", "acc"):
            phi_rmse, e_rmse, nees_phi, nees_e = [], [], [], []
            for rec in recs:
                result = estimate(measurements_from_recording(rec), build_model(rec.rig, peripheral=peripheral))
                dphi, de, vphi, ve = _errors(result, truth_from_recording(rec), result.calibration.rest_end)
                phi_rmse.append(np.degrees(np.sqrt(np.mean(dphi**2))))
                e_rmse.append(np.sqrt(np.mean(de**2)))
                nees_phi.append(dphi**2 / vphi)
                nees_e.append(de**2 / ve)
            n = min(len(a) for a in nees_phi)
            mean_phi = np.mean([a[:n] for a in nees_phi], axis=0)
            mean_e = np.mean([a[:n] for a in nees_e], axis=0)
            M = len(recs)
            lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], M) / M
            in_band = 0.5 * (np.mean((mean_phi > lo) & (mean_phi < hi)) + np.mean((mean_e > lo) & (mean_e < hi)))
            print(f"{plant:10} {peripheral:6} {np.mean(phi_rmse):10.4f} ± {np.std(phi_rmse):.4f} "
                  f"{1000 * np.mean(e_rmse):12.3f} ± {1000 * np.std(e_rmse):.3f} {mean_phi.mean():9.2f} {mean_e.mean():8.2f} {100 * in_band:7.0f}%")
    print("NEES: mean over seeds and time (1 is consistent); 'in band': share of time the seed-averaged NEES of phi and e "
          "lies in the two-sided 95 % chi-square band for that many seeds.")


def speed(workdir: Path, duration: float) -> None:
    print(f"\n== speed: one core, {duration:.0f} s of the benchmark layout ==")
    path = workdir / "speed.mcap"
    simulate(SimulationSettings(duration=duration, seed=1, ideal=True), path)
    rec = read_recording(path)
    meas = measurements_from_recording(rec)
    reference_seconds = min(duration, 60.0)
    print(f"{'periph':6} {'filter steps/s':>15} {'x real time':>12} {'filterpy steps/s':>17} {'x real time':>12} {'ratio':>6}")
    for peripheral in ("gyro", "acc"):
        model = build_model(rec.rig, peripheral=peripheral)
        config = FilterConfig()
        cal = calibrate_at_rest(meas, model, config)
        events = build_events(meas, model)
        best = np.inf
        for _ in range(3):
            filt = ImmsFilter(model, cal, config, t0=meas.start)
            started = time.perf_counter()
            filt.process(events)
            filt.flush()
            best = min(best, time.perf_counter() - started)
        steps = int(np.count_nonzero(events.kind == 0))
        part = events.slice(0, int(np.searchsorted(events.t, meas.start + reference_seconds)))
        started = time.perf_counter()
        run_filterpy(part, model, cal, config, t0=meas.start)
        ref = time.perf_counter() - started
        ref_steps = int(np.count_nonzero(part.kind == 0))
        ours_rate, ref_rate = steps / best, ref_steps / ref
        print(f"{peripheral:6} {ours_rate:15.0f} {ours_rate / 200:12.0f} {ref_rate:17.0f} {ref_rate / 200:12.1f} {ours_rate / ref_rate:6.0f}")
    print("(steps: 200 Hz predict with its aiding updates; filterpy timed on the first "
          f"{reference_seconds:.0f} s, the same events and model; reading excluded)")


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    quick = "--quick" in argv
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        speed(work, 120.0 if quick else 300.0)
        accuracy(work, range(1, 3) if quick else range(1, 6), 150.0 if quick else 300.0)


if __name__ == "__main__":
    main()
