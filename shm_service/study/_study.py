"""Running the study over a process pool, aggregating over seeds, writing the table."""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, TextIO, cast

import numpy as np

from ._config import Configuration, StudySettings
from ._runs import EstimateTask, RunOutcome, SimulationTask, estimate_configuration, simulate_seed

RESULT_KEYS = ("phi_deg", "e_m", "deflection_m")
BENCHMARK_KEYS = ("phi_deg", "e_m")


class StudyError(RuntimeError):
    """A run of the study failed; the message names the seed and configuration."""


@dataclass(frozen=True)
class ConfigurationResult:
    """One configuration over all seeds: mean and spread (sample standard deviation) of the RMSEs."""

    config: Configuration
    seeds: tuple[int, ...]
    selection: dict  # sensor names picked by EfI (identical for every seed: same nominal rig)
    rmse_truth: dict[str, float]
    rmse_truth_std: dict[str, float]
    rmse_benchmark: dict  # phi_deg, e_m, b (list of Γ)
    rmse_benchmark_std: dict
    filter_seconds: float

    @property
    def boards(self) -> int:
        """IMU/ToF boards on the beam: the one at the bearing D plus every board whose IMU or ToF is used."""
        return 1 + len(set(self.selection["imus"]) | set(self.selection["tofs"]))

    def as_json(self) -> dict:
        c = self.config
        return {
            "peripheral": c.peripheral,
            "imus": c.imus,
            "tofs": c.tofs,
            "gauges": c.gauges,
            "aided": list(c.aided),
            "seeds": list(self.seeds),
            "rmse_truth": dict(self.rmse_truth),
            "rmse_benchmark": {"phi_deg": self.rmse_benchmark["phi_deg"], "e_m": self.rmse_benchmark["e_m"],
                               "b": list(self.rmse_benchmark["b"])},
            "rmse_truth_std": dict(self.rmse_truth_std),
            "rmse_benchmark_std": {"phi_deg": self.rmse_benchmark_std["phi_deg"], "e_m": self.rmse_benchmark_std["e_m"],
                                   "b": list(self.rmse_benchmark_std["b"])},
        }


@dataclass
class StudyResult:
    settings: StudySettings
    results: tuple[ConfigurationResult, ...]
    wall_seconds: float
    workers: int
    # Time series of the first seed for the figures: configuration → t, phi, e, b, rest_end;
    # "benchmark" holds the gyro benchmark with the truth's phi and e at the same instants.
    series: dict[Configuration, dict[str, np.ndarray]] = field(default_factory=dict)
    benchmark_series: dict[str, np.ndarray] = field(default_factory=dict)

    def find(self, config: Configuration) -> ConfigurationResult | None:
        return next((r for r in self.results if r.config == config), None)


# -- progress -----------------------------------------------------------------------------
def _clock(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 60}:{seconds % 60:02d}"


class _Progress:
    def __init__(self, stream: TextIO | None, runs: int, simulations: int) -> None:
        self.stream, self.runs, self.simulations = stream, runs, simulations
        self.started = time.perf_counter()
        self.sims_done = self.runs_done = 0
        self._last = 0.0

    def _say(self, text: str, force: bool = False) -> None:
        if self.stream is None:
            return
        now = time.perf_counter()
        if force or now - self._last >= 1.0:
            self._last = now
            print(text, file=self.stream, flush=True)

    def simulated(self, seed: int) -> None:
        self.sims_done += 1
        self._say(f"study: simulated seed {seed} ({self.sims_done}/{self.simulations} recordings, "
                  f"{_clock(time.perf_counter() - self.started)} elapsed)", force=True)

    def ran(self, outcome: RunOutcome) -> None:
        self.runs_done += 1
        elapsed = time.perf_counter() - self.started
        # Simulations are part of the work left: count each as one run's worth of time.
        done = self.runs_done + self.sims_done
        left = (self.runs - self.runs_done) + (self.simulations - self.sims_done)
        eta = elapsed / done * left
        self._say(f"study: {self.runs_done}/{self.runs} configuration runs ({100 * self.runs_done / self.runs:.0f}%), "
                  f"{_clock(elapsed)} elapsed, ETA {_clock(eta)} — seed {outcome.seed}: {outcome.config.label}",
                  force=self.runs_done == self.runs)


# -- execution ------------------------------------------------------------------------------
def _execute(settings: StudySettings, configs: tuple[Configuration, ...], seeds: tuple[int, ...], workdir: Path,
             want_series: set[Configuration], series_seed: int, progress: TextIO | None,
             recorded: dict[int, Path] | None = None) -> tuple[list[RunOutcome], int]:
    bm = settings.benchmark()
    if bm not in configs:
        configs = (bm, *configs)
    others = [c for c in configs if c != bm]
    workers = settings.workers or os.cpu_count() or 1
    prog = _Progress(progress, len(configs) * len(seeds), len(seeds))
    outcomes: list[RunOutcome] = []
    recorded = recorded or {}
    paths = {s: str(recorded.get(s, workdir / f"seed{s}.mcap")) for s in seeds}
    bench = {s: str(workdir / f"seed{s}_benchmark.npz") for s in seeds}

    def task(seed: int, c: Configuration) -> EstimateTask:
        return EstimateTask(seed, paths[seed], bench[seed], c, want_series=seed == series_seed and c in want_series,
                            is_benchmark=c == bm)

    # "spawn": workers start clean (no fork of a threaded parent), the worker functions are importable.
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        pending: dict[Future, tuple[str, int, Configuration | None]] = {}
        for s in seeds:
            if s in recorded:  # kept from an earlier run with the same settings
                prog.simulated(s)
                pending[pool.submit(estimate_configuration, task(s, bm))] = ("bm", s, bm)
            else:
                pending[pool.submit(simulate_seed, SimulationTask(settings, s, paths[s]))] = ("sim", s, None)
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    kind, seed, config = pending.pop(fut)
                    try:
                        value = fut.result()
                    except Exception as exc:
                        if kind == "sim":
                            what = "simulating"
                        else:
                            assert config is not None, "an estimation task names its configuration"
                            what = f"estimating {config.label} on"
                        raise StudyError(f"{what} seed {seed} failed: {type(exc).__name__}: {exc}") from exc
                    if kind == "sim":
                        prog.simulated(seed)
                        pending[pool.submit(estimate_configuration, task(seed, bm))] = ("bm", seed, bm)
                        continue
                    outcomes.append(value)
                    prog.ran(value)
                    if kind == "bm":  # the benchmark's series are on disk: the rest of this seed can run
                        for c in others:
                            pending[pool.submit(estimate_configuration, task(seed, c))] = ("run", seed, c)
        except BaseException:
            for fut in pending:
                fut.cancel()
            raise
    return outcomes, workers


def _aggregate(outcomes: Iterable[RunOutcome], configs: tuple[Configuration, ...]) -> tuple[ConfigurationResult, ...]:
    by_config: dict[Configuration, list[RunOutcome]] = {}
    for o in outcomes:
        by_config.setdefault(o.config, []).append(o)
    results = []
    for c in configs:
        runs = sorted(by_config.get(c, []), key=lambda o: o.seed)
        if not runs:
            continue

        def stats(values: list) -> tuple[float | list[float], float | list[float]]:
            a = np.asarray(values, dtype=float)
            mean = a.mean(axis=0)
            std = a.std(axis=0, ddof=1) if len(a) > 1 else np.zeros_like(mean)
            return (mean.tolist(), std.tolist())

        truth = {k: stats([o.rmse_truth[k] for o in runs]) for k in RESULT_KEYS}
        bench = {k: stats([o.rmse_benchmark[k] for o in runs]) for k in ("phi_deg", "e_m", "b")}
        results.append(ConfigurationResult(
            config=c,
            seeds=tuple(o.seed for o in runs),
            selection=runs[0].selection,
            # each seed's RMSE against the truth is one number, so are their mean and std
            rmse_truth={k: cast(float, v[0]) for k, v in truth.items()},
            rmse_truth_std={k: cast(float, v[1]) for k, v in truth.items()},
            rmse_benchmark={k: v[0] for k, v in bench.items()},
            rmse_benchmark_std={k: v[1] for k, v in bench.items()},
            filter_seconds=float(np.mean([o.filter_seconds for o in runs])),
        ))
    return tuple(results)


def run_study(settings: StudySettings, out: str | Path, *, progress: TextIO | None = sys.stderr,
              series_for: Iterable[Configuration] = (), keep_recordings: bool = False) -> StudyResult:
    """Simulate one recording per seed, run every configuration on every recording, score each
    against the simulator's truth and against the gyro benchmark of the same seed (Eq. 21),
    and write ``results.json``, ``results.csv`` and ``study.json`` into ``out``.

    Time series of the first seed are kept for the configurations in ``series_for``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configs = settings.configurations()
    started = time.perf_counter()
    workdir = out / "recordings" if keep_recordings else Path(tempfile.mkdtemp(prefix=".recordings-", dir=out))
    workdir.mkdir(parents=True, exist_ok=True)
    try:
        outcomes, workers = _execute(settings, configs, settings.seeds, workdir, set(series_for),
                                     settings.seeds[0], progress)
        bench_series = _load_npz(workdir / f"seed{settings.seeds[0]}_benchmark.npz")
    finally:
        if not keep_recordings:
            shutil.rmtree(workdir, ignore_errors=True)
    result = StudyResult(
        settings=settings,
        results=_aggregate(outcomes, configs),
        wall_seconds=time.perf_counter() - started,
        workers=workers,
        series={o.config: o.series for o in outcomes if o.series is not None},
        benchmark_series=bench_series,
    )
    write_tables(result, out)
    return result


def series_of(settings: StudySettings, configs: Iterable[Configuration], out: str | Path, *,
              progress: TextIO | None = sys.stderr) -> tuple[dict[Configuration, dict], dict[str, np.ndarray]]:
    """Time series of ``configs`` (and the benchmark) on the first seed: re-simulates that seed
    unless ``out/recordings`` keeps it (``keep_recordings``; call only when ``load_results`` or
    ``run_study`` vouched for the settings of that folder)."""
    configs = tuple(dict.fromkeys(configs))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    workdir = Path(tempfile.mkdtemp(prefix=".recordings-", dir=out))
    seed = settings.seeds[0]
    kept = out / "recordings" / f"seed{seed}.mcap"
    try:
        outcomes, _ = _execute(settings, configs, (seed,), workdir, set(configs) | {settings.benchmark()}, seed, progress,
                               recorded={seed: kept} if kept.is_file() else None)
        bench_series = _load_npz(workdir / f"seed{seed}_benchmark.npz")
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return {o.config: o.series for o in outcomes if o.series is not None}, bench_series


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


# -- tables ---------------------------------------------------------------------------------
def write_tables(result: StudyResult, out: Path) -> None:
    rows = [r.as_json() for r in result.results]
    (out / "results.json").write_text(json.dumps(rows, indent=2, allow_nan=False) + "\n")
    with open(out / "results.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        b_cols = [f"bm_b{k + 1}" for k in range(result.settings.modes)]
        writer.writerow(
            ["peripheral", "imus", "tofs", "gauges", "aided", "seeds", "boards",
             "truth_phi_deg", "truth_phi_deg_std", "truth_e_m", "truth_e_m_std", "truth_deflection_m", "truth_deflection_m_std",
             "bm_phi_deg", "bm_phi_deg_std", "bm_e_m", "bm_e_m_std"]
            + [x for col in b_cols for x in (col, col + "_std")]
            + ["imu_names", "tof_names", "gauge_names", "filter_seconds"])
        for r in result.results:
            c = r.config
            truth = [x for k in RESULT_KEYS for x in (r.rmse_truth[k], r.rmse_truth_std[k])]
            bm = [x for k in BENCHMARK_KEYS for x in (r.rmse_benchmark[k], r.rmse_benchmark_std[k])]
            bm_b = [x for k in range(result.settings.modes) for x in (r.rmse_benchmark["b"][k], r.rmse_benchmark_std["b"][k])]
            writer.writerow(
                [c.peripheral, c.imus, c.tofs, c.gauges, " ".join(map(str, c.aided)), " ".join(map(str, r.seeds)), r.boards]
                + [f"{v:.6g}" for v in truth + bm + bm_b]
                + [" ".join(r.selection["imus"]), " ".join(r.selection["tofs"]), " ".join(r.selection["gauges"]),
                   f"{r.filter_seconds:.3f}"])
    meta = {
        "settings": result.settings.model_dump(mode="json"),
        "wall_seconds": round(result.wall_seconds, 1),
        "workers": result.workers,
        "configurations": len(result.results),
        "runs": sum(len(r.seeds) for r in result.results),
        "selections": {r.config.slug: r.selection for r in result.results},
    }
    (out / "study.json").write_text(json.dumps(meta, indent=2) + "\n")


def load_results(out: str | Path, settings: StudySettings) -> tuple[ConfigurationResult, ...] | None:
    """The table of an earlier study in ``out`` if it ran with exactly ``settings`` (else None)."""
    out = Path(out)
    try:
        meta = json.loads((out / "study.json").read_text())
        rows = json.loads((out / "results.json").read_text())
    except (OSError, ValueError):
        return None
    compare = {k: v for k, v in settings.model_dump(mode="json").items() if k != "workers"}
    if {k: v for k, v in meta.get("settings", {}).items() if k != "workers"} != compare:
        return None
    results = []
    try:
        for row in rows:
            c = Configuration(peripheral=row["peripheral"], imus=row["imus"], tofs=row["tofs"], gauges=row["gauges"],
                              aided=tuple(row["aided"]), modes=settings.modes)
            results.append(ConfigurationResult(
                config=c, seeds=tuple(row["seeds"]), selection=meta["selections"][c.slug],
                rmse_truth=row["rmse_truth"], rmse_truth_std=row["rmse_truth_std"],
                rmse_benchmark=row["rmse_benchmark"], rmse_benchmark_std=row["rmse_benchmark_std"], filter_seconds=0.0))
    except (KeyError, TypeError, ValueError):
        return None
    return tuple(results)
