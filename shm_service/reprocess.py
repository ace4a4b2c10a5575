"""Archives through the estimator and the analysis on a dask.distributed cluster:
``shm reprocess`` (per-window trend rows into the service's database) and ``shm baseline learn``
(a baseline from a healthy period spread over files, stored for the live service).

Each file is one task. A task runs exactly what ``shm analyze`` runs on the file (the analyze
command's own path, ``cli._analysis_of``), so both give the same windows and figures; its trend
rows are committed by this process (the database's only writer) in one transaction with the
file's ledger row. A file is done only once that commit happened: a killed run is restarted by
running it again, and a file already done under the same key (content hash + configuration,
the source included) is skipped unless ``force``. A local cluster (``workers`` processes of one
thread each) is started unless a scheduler address is given; the code that runs is the same
(the workers of an existing cluster need this package installed and the files at the same paths).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import math
import os
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

__all__ = ["AnalysisOptions", "FileOutcome", "learn_baseline", "reprocess", "source_of"]


@dataclass(frozen=True)
class AnalysisOptions:
    """What ``shm analyze`` takes (the same names and defaults as its options)."""

    rig: str | None = None
    peripheral: str = "gyro"
    modes: int = 4
    imus: str | None = None
    tofs: str | None = None
    gauges: str | None = None

    def namespace(self) -> argparse.Namespace:
        return argparse.Namespace(**asdict(self))

    def configuration(self, source: str) -> str:
        """The configuration part of a file's key: these options, the rig file's content, the
        program's version and the source the rows go to (JSON)."""
        from importlib.metadata import PackageNotFoundError, version

        try:
            program = version("imms-shm")
        except PackageNotFoundError:
            program = "unknown"
        rig_digest = None if self.rig is None else hashlib.sha256(Path(self.rig).read_bytes()).hexdigest()
        return json.dumps({**asdict(self), "rig_sha256": rig_digest, "program": program, "source": source}, sort_keys=True)


@dataclass(frozen=True)
class FileOutcome:
    """One file of a run: status "done", "skipped" or "failed"; windows analysed (None unless
    done); error (failed only)."""

    path: str
    status: str
    windows: int | None
    error: str | None

    def as_dict(self) -> dict[str, Any]:
        return {"path": self.path, "status": self.status, "windows": self.windows, "error": self.error}


def source_of(path: str | Path) -> str:
    """The source (structure) id a recording's rows go to by default: the service's own for its
    archive files (``SOURCE-YYYYmmddTHHMMSSZ-w....mcap``), else the file's stem, as ``shm serve
    --source replay:FILE`` names it."""
    from .service._archive import parse_archive_name

    name = parse_archive_name(path)
    return name.source if name is not None else Path(path).stem


def content_sha256(path: str) -> str:
    """SHA-256 of the file's bytes (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(8 << 20):
            digest.update(block)
    return digest.hexdigest()


def analyse_file(path: str, options: AnalysisOptions, source: str) -> dict[str, Any]:
    """The task: ``shm analyze``'s analysis of ``path`` and its trend rows (window times in UNIX s:
    the recording's first sample plus analyze's window times)."""
    from contract import TrendRow, chart_name

    from .cli import _analysis_of

    try:
        rec, data, result = _analysis_of(path, options.namespace())
    except ValueError:
        # shorter than one analysis window: nothing to analyse, which is not a failure
        from analytics import AnalysisConfig

        from .recording import read_recording

        rec = read_recording(path, rig=options.rig, kinds=())
        if rec.duration_s < AnalysisConfig().window_s:
            return {"windows": 0, "rows": [], "start_s": rec.start_ns / 1e9, "end_s": rec.end_ns / 1e9}
        raise
    offset = rec.start_ns / 1e9
    rows = []
    for w in result.windows:
        for i, e in enumerate(w.estimates):
            score = w.frequency_scores[i] if i < len(w.frequency_scores) else None
            rows.append(TrendRow(
                source=source, window_start_s=offset + w.start_s, window_end_s=offset + w.end_s, mode=e.mode, unit=e.unit,
                kind=w.kind, frequency_hz=e.frequency_hz, damping_ratio=None, amplitude=e.amplitude, confidence=e.confidence,
                temperature_c=w.temperature_c, curvature_index=None if w.curvature is None else w.curvature.total,
                score_sigma=score, level=w.levels.get(chart_name("frequency", e.mode)),
            ).model_dump())
    return {"windows": len(result.windows), "rows": rows, "start_s": offset, "end_s": rec.end_ns / 1e9}


@contextmanager
def _client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A client of the cluster at ``scheduler``, else of a LocalCluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as client:
            yield client
        return
    n = workers or os.cpu_count() or 1
    # one thread per worker process: the estimator and the analysis hold the GIL most of the time
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:  # failures: reported per file
        yield client


def _progress(total: int, description: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="file", disable=None if enabled else True)


def _error(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def reprocess(paths: list[str], db: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              force: bool = False, options: AnalysisOptions = AnalysisOptions(), source: str | None = None,
              progress: bool = True) -> list[FileOutcome]:
    """Reprocess ``paths`` into the database ``db`` (see the module's text); one outcome per path,
    in the order given."""
    from distributed import as_completed

    from contract import TrendRow

    from .service._storage import Storage

    if workers is not None and workers < 1:
        raise ValueError(f"{workers=} must be at least 1")
    storage = Storage(db)
    outcomes: dict[int, FileOutcome] = {}
    with _client(workers, scheduler) as client, closing(storage):
        sources = [source or source_of(p) for p in paths]
        configurations = [options.configuration(s) for s in sources]
        hashes = client.map(content_sha256, paths, key=[f"sha256-{i}-{Path(p).name}" for i, p in enumerate(paths)], pure=False)
        digests: dict[int, str] = {}
        for i, future in enumerate(hashes):
            try:
                digests[i] = future.result()
            except Exception as exc:  # noqa: BLE001 - a missing or unreadable file fails alone
                outcomes[i] = FileOutcome(paths[i], "failed", None, _error(exc))
        keys = {i: hashlib.sha256(f"{d}\n{configurations[i]}".encode()).hexdigest() for i, d in digests.items()}
        done = storage.reprocessed(list(keys.values())) if keys else set()
        todo: dict[str, int] = {}
        for i, key in keys.items():
            if (key in done and not force) or key in todo:  # done before, or the same file twice in one run
                outcomes[i] = FileOutcome(paths[i], "skipped", None, None)
            else:
                todo[key] = i
        futures = {client.submit(analyse_file, paths[i], options, sources[i], key=f"reprocess-{key}", pure=False): (key, i)
                   for key, i in todo.items()}
        bar = _progress(len(paths), "reprocess", progress)
        bar.update(len(outcomes))
        for future in as_completed(futures):
            key, i = futures[future]
            try:
                out = future.result()
                storage.commit_reprocessed(
                    key=key, path=str(Path(paths[i]).resolve()), source=sources[i], content_sha256=digests[i],
                    configuration=configurations[i], windows=out["windows"], start_s=out["start_s"], end_s=out["end_s"],
                    rows=[TrendRow.model_validate(r) for r in out["rows"]])
                outcomes[i] = FileOutcome(paths[i], "done", out["windows"], None)
            except Exception as exc:  # noqa: BLE001 - one file's failure never stops the others
                outcomes[i] = FileOutcome(paths[i], "failed", None, _error(exc))
            bar.update(1)
        bar.close()
    return [outcomes[i] for i in range(len(paths))]


# -- baselines from archives ----------------------------------------------------------------------


def deformation_task(path: str, options: AnalysisOptions, period: tuple[float, float]) -> dict[str, Any] | None:
    """The task of ``learn_baseline``: b(t) of ``path`` (the estimator as ``shm analyze`` runs it)
    within ``period`` (UNIX s), with the temperature and bearing displacement at those times."""
    import numpy as np

    from .cli import _sensor_counts
    from .estimation import deformation_record
    from .recording import read_recording

    rec = read_recording(path, rig=options.rig)
    args = options.namespace()
    data = deformation_record(rec, model_args=dict(peripheral=options.peripheral, modes=options.modes,
                                                     **_sensor_counts(rec.rig, args)))
    offset = rec.start_ns / 1e9
    t = offset + data.times
    keep = (t >= period[0]) & (t < period[1])
    if not keep.any():
        return None
    temperature = None
    if data.temperature is not None:
        temperature = np.interp(t[keep], offset + data.temperature[0], data.temperature[1])
    return {"t": t[keep], "b": data.b[keep], "temperature": temperature,
            "bearing": None if data.bearing is None else data.bearing[keep], "path": path}


def _windows(parts: list[dict], window_s: float, step_s: float, fs: float):
    """Windows of b aligned to multiples of the step in UNIX time (as the live service's), each
    inside one file's samples: (start, grid, B, temperature, bearing)."""
    import numpy as np

    n = int(round(window_s * fs))
    for part in sorted(parts, key=lambda p: float(p["t"][0])):
        t, b = part["t"], part["b"]
        start = math.ceil(float(t[0]) / step_s) * step_s
        while start + window_s <= float(t[-1]):
            k0, k1 = np.searchsorted(t, [start, start + window_s])
            if k1 - k0 >= 0.8 * n:
                grid = start + np.arange(n) / fs
                B = np.column_stack([np.interp(grid, t[k0:k1], b[k0:k1, k]) for k in range(b.shape[1])])
                temp = None if part["temperature"] is None else float(np.mean(part["temperature"][k0:k1]))
                bearing = None if part["bearing"] is None else np.interp(grid, t[k0:k1], part["bearing"][k0:k1])
                yield start, grid, B, temp, bearing
            start += step_s


def learn_baseline(paths: list[str], db: str | Path, structure: str, period: tuple[float, float], *,
                   workers: int | None = None, scheduler: str | None = None, options: AnalysisOptions = AnalysisOptions(),
                   progress: bool = True) -> dict[str, Any]:
    """Learn a baseline of ``structure`` from the windows of ``paths`` within ``period`` (UNIX s)
    and store it as the structure's active baseline in ``db``. The files are estimated in
    parallel; their windows, in time order, go through one monitor (the live service's
    configuration) that learns from every trusted window of the period. Returns a summary;
    raises ValueError when no baseline can be learnt (saying what was missing)."""
    import numpy as np
    from distributed import as_completed

    from analytics import AnalysisConfig, ModalMonitor
    from estimator import build_model, damage_signatures

    from .cli import _sensor_counts
    from .recording import read_recording
    from .service._storage import Storage

    lo, hi = period
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"period={period!r} must be (start, end) in UNIX s with end after start")
    parts, failures = [], []
    with _client(workers, scheduler) as client:
        futures = {client.submit(deformation_task, p, options, (lo, hi), pure=False): p for p in paths}
        bar = _progress(len(paths), "baseline", progress)
        for future in as_completed(futures):
            try:
                part = future.result()
                if part is not None:
                    parts.append(part)
            except Exception as exc:  # noqa: BLE001
                failures.append({"path": futures[future], "error": _error(exc)})
            bar.update(1)
        bar.close()
    if not parts:
        raise ValueError(f"no samples of {len(paths)} file(s) within the period {lo:.0f}..{hi:.0f} s"
                         + (f" ({len(failures)} failed: {failures[0]['error']})" if failures else ""))
    rec = read_recording(parts[0]["path"], rig=options.rig, kinds=())
    model = build_model(rec.rig, peripheral=options.peripheral, modes=options.modes,
                        **_sensor_counts(rec.rig, options.namespace()))
    fs = 200.0
    config = AnalysisConfig()
    step = config.window_s * (1 - config.overlap)
    signatures = damage_signatures(model.rig, model.stations, gamma=model.gamma)

    def monitor(baseline_s: float) -> ModalMonitor:
        return ModalMonitor(model.units.frequencies_hz, model.units.curvature(model.stations), model.stations, fs=fs,
                            config=config.model_copy(update={"baseline_s": baseline_s}), beam_length=model.rig.beam.length,
                            signatures=signatures)

    # Pass 1 finds the trusted windows; pass 2 learns from all of them (its baseline period ends
    # with the last trusted window of the period).
    first = monitor(math.inf)
    trusted = [(start, start + config.window_s) for start, grid, B, temp, bearing in _windows(parts, config.window_s, step, fs)
               if first.process_window(grid, B, temp, bearing).trusted]
    windows = sum(1 for _ in _windows(parts, config.window_s, step, fs))
    if not trusted:
        raise ValueError(f"none of the {windows} window(s) of the period is trusted (ambient or free decay)")
    learner = monitor(max(trusted[-1][1] - trusted[0][0] - 1e-6, 1e-6))
    for start, grid, B, temp, bearing in _windows(parts, config.window_s, step, fs):
        learner.process_window(grid, B, temp, bearing)
    if learner.baseline is None:
        raise ValueError(f"no baseline from {len(trusted)} trusted window(s) of {windows}: the modes' shapes need "
                         "ambient windows")
    baseline = learner.baseline
    lacking = [m.mode for m in baseline.modes if m.windows < config.baseline_min_windows]
    storage = Storage(db)
    try:
        baseline_id = storage.store_baseline(structure, baseline.to_dict())
    finally:
        storage.close()
    return {
        "structure": structure, "baseline_id": baseline_id, "files": len(paths), "files_used": len(parts), "failed": failures,
        "windows": windows, "trusted_windows": len(trusted), "start_s": baseline.start_s, "end_s": baseline.end_s,
        "modes": [{"mode": m.mode, "unit": m.unit, "frequency_hz": m.f_ref_hz, "sigma_rel": m.sigma_rel, "windows": m.windows}
                  for m in baseline.modes],
        "modes_without_enough_windows": lacking,
        "samples": int(sum(len(p["t"]) for p in parts)),
        "mean_temperature_c": None if all(p["temperature"] is None for p in parts) else float(np.nanmean(
            np.concatenate([p["temperature"] for p in parts if p["temperature"] is not None]))),
    }
