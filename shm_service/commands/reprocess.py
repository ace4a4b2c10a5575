"""Archives through the estimator and the analysis on a dask.distributed cluster:
``shm reprocess`` (per-window trend rows into the service's database) and ``shm baseline learn``
(a baseline from a healthy period spread over files, stored for the live service).

Each file is one task. A task runs exactly what ``shm analyze`` runs on the file (the analyze
command's own path), so both give the same windows and figures; its trend
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
from typing import Any, Literal

from ._common import CliError, _print_json

__all__ = ["AnalysisOptions", "FileOutcome", "cmd_baseline_learn", "cmd_reprocess", "learn_baseline", "reprocess", "source_of"]


@dataclass(frozen=True)
class AnalysisOptions:
    """What ``shm analyze`` takes (the same names and defaults as its options); ``config`` is a
    ``shm serve`` TOML whose analytics, alarm hysteresis and warm-up are used."""

    rig: str | None = None
    peripheral: Literal["gyro", "acc"] = "gyro"
    modes: int = 4
    modes_xi: int | None = None
    imus: str | None = None
    tofs: str | None = None
    gauges: str | None = None
    config: str | None = None

    def namespace(self) -> argparse.Namespace:
        return argparse.Namespace(**asdict(self))

    def configuration(self, source: str) -> str:
        """The configuration part of a file's key: these options, the rig and configuration
        files' content, the program's version and the source the rows go to (JSON)."""
        from importlib.metadata import PackageNotFoundError, version

        try:
            program = version("imms-shm")
        except PackageNotFoundError:
            program = "unknown"

        def digest(path: str | None) -> str | None:
            return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()

        options = asdict(self)
        if options["modes_xi"] is None:  # left out at its default: a planar configuration's key is as before
            del options["modes_xi"]
        return json.dumps({**options, "rig_sha256": digest(self.rig), "config_sha256": digest(self.config),
                           "program": program, "source": source}, sort_keys=True)

    def settings(self):
        """(AnalysisConfig or None for the defaults, warm-up s): those ``shm analyze`` uses."""
        from ._common import _analysis_settings

        return _analysis_settings(self.namespace())

    def deformations(self, path: str):
        """(recording, DeformationRecord) of ``path``, the estimator run as ``shm analyze`` runs it."""
        from ._common import _deformations_of

        return _deformations_of(path, self.namespace())


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
    from ..service.storage._archive_names import parse_archive_name

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
    """The task: ``shm analyze``'s analysis of ``path`` (shm_service.processing.analysis, the one engine) and
    its trend rows (window times in UNIX s, as the live service stores them)."""
    from analytics import AnalysisConfig

    from ..processing.analysis import analyze_deformations, recording_gauges, trend_rows

    config, warmup = options.settings()
    rec, data = options.deformations(path)
    offset = data.origin_ns / 1e9
    window_s = (config or AnalysisConfig()).window_s
    loads = None
    if rec.rig.hot_spots:
        from analytics import LoadsMonitor

        loads = LoadsMonitor.from_rig(rec.rig, data.units.curvature)  # a fresh one: the chain's (``_LoadsChain``)
    if data.times.size == 0 or data.times[-1] - data.times[0] < window_s:
        # shorter than one analysis window: nothing to analyse, which is not a failure
        return {"windows": 0, "rows": [], "start_s": rec.start_ns / 1e9, "end_s": rec.end_ns / 1e9, "loads": loads, "tap": []}
    tap: list = []
    # the recording's strain gauges, as ``shm analyze`` passes them: each window's loads carry their band
    result = analyze_deformations(rec.rig, data, config=config, warmup_s=warmup, loads_tap=tap, gauges=recording_gauges(rec))
    rows = [row.model_dump() for w in result.windows
            for row in trend_rows(source, w, offset + w.start_s, offset + w.end_s)]
    if result.xi is not None:  # a biaxial beam: the ξ plane's windows, their rows marked "xi"
        rows += [row.model_dump() for w in result.xi.windows
                 for row in trend_rows(source, w, offset + w.start_s, offset + w.end_s, plane="xi")]
    # each window's counted hot-spot stress, in UNIX s: this process chains them across the files
    tap = [(offset + start, *rest) for start, *rest in tap]
    return {"windows": len(result.windows), "rows": rows, "start_s": rec.start_ns / 1e9, "end_s": rec.end_ns / 1e9,
            "loads": loads, "tap": tap}


class _LoadsChain:
    """The hot spots' count of one source across the files of a run, in data-time order: the live
    service counts its archive's files as one record (the residue of open reversals goes on from
    file to file), and so does ``shm reprocess``. A file is committed once every file of its source
    that starts earlier is (committed or failed); its windows' loads are counted by one
    ``LoadsMonitor`` fed with the windows' stress that the file's task counted (``LoadsMonitor.tap``)."""

    def __init__(self, order: list[int]) -> None:
        self.order = list(order)  # the source's files (indices) by their recording's start
        self.position = 0
        self.monitor: Any = None

    def ready(self, finished: set[int]) -> list[int]:
        """The next files that may be committed now (their predecessors finished)."""
        out = []
        while self.position < len(self.order) and self.order[self.position] in finished:
            out.append(self.order[self.position])
            self.position += 1
        return out

    def count(self, result: dict[str, Any]) -> list:
        """The file's windows' loads (contract.LoadsWindowDocument), continuing the chain."""
        if result.get("loads") is None:
            return []
        if self.monitor is None:
            self.monitor = result["loads"]
        return [self.monitor.process_stress(start, stress, duration, temperature, stations=stations, band=band)
                for start, stress, duration, temperature, stations, band in result["tap"]]


def recording_start_ns(path: str) -> int | None:
    """The recording's first message time (its summary; None when it has none: the file's task says why)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return None if summary is None or summary.statistics is None else int(summary.statistics.message_start_time)
    except Exception:  # noqa: BLE001 - a damaged file fails in its task, with the reason
        return None


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

    from ..service.storage._storage import Storage

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
        # the files of each source in data-time order: the hot spots' count runs through them as one record
        starts = dict(zip(todo.values(), client.gather(client.map(recording_start_ns, [paths[i] for i in todo.values()],
                                                                  pure=False))))
        chains = {src: _LoadsChain(sorted((i for i in todo.values() if sources[i] == src),
                                          key=lambda i: (starts[i] is None, starts[i] or 0, paths[i])))
                  for src in {sources[i] for i in todo.values()}}
        futures = {client.submit(analyse_file, paths[i], options, sources[i], key=f"reprocess-{key}", pure=False): (key, i)
                   for key, i in todo.items()}
        bar = _progress(len(paths), "reprocess", progress)
        bar.update(len(outcomes))
        results: dict[int, Any] = {}  # a finished file's result (or its exception) until its turn to be committed
        for future in as_completed(futures):
            key, i = futures[future]
            try:
                results[i] = (key, future.result())
            except Exception as exc:  # noqa: BLE001 - one file's failure never stops the others
                results[i] = (key, exc)
            chain = chains[sources[i]]
            for j in chain.ready(set(results)):
                key_j, out = results.pop(j)
                try:
                    if isinstance(out, Exception):
                        raise out
                    storage.commit_reprocessed(
                        key=key_j, path=str(Path(paths[j]).resolve()), source=sources[j], content_sha256=digests[j],
                        configuration=configurations[j], windows=out["windows"], start_s=out["start_s"], end_s=out["end_s"],
                        rows=[TrendRow.model_validate(r) for r in out["rows"]], loads=chain.count(out))
                    outcomes[j] = FileOutcome(paths[j], "done", out["windows"], None)
                except Exception as exc:  # noqa: BLE001 - one file's failure never stops the others
                    outcomes[j] = FileOutcome(paths[j], "failed", None, _error(exc))
                bar.update(1)
        bar.close()
    return [outcomes[i] for i in range(len(paths))]


# -- baselines from archives ----------------------------------------------------------------------


def deformation_task(path: str, options: AnalysisOptions, period: tuple[float, float]) -> dict[str, Any] | None:
    """The task of ``learn_baseline``: b(t) of ``path`` (the estimator as ``shm analyze`` runs it,
    the warm-up after its rest phase left out) within ``period`` (UNIX s), with the support
    displacement on the same times and the temperature samples of the period."""
    import numpy as np

    _, warmup = options.settings()
    rec, data = options.deformations(path)
    offset = data.origin_ns / 1e9
    t = offset + data.times
    keep = (t >= period[0]) & (t < period[1])
    if data.rest_end_s is not None and warmup is not None:
        keep &= data.times >= data.rest_end_s + warmup
    if not keep.any():
        return None
    temperature = None
    if data.temperature is not None:
        tt = offset + np.asarray(data.temperature[0], dtype=float)
        inside = (tt >= period[0]) & (tt < period[1])
        if inside.any():
            temperature = (tt[inside], np.asarray(data.temperature[1], dtype=float)[inside])
    return {"t": t[keep], "b": data.b[keep], "support": None if data.support is None else data.support[keep],
            "temperature": temperature, "path": path}


def learn_baseline(paths: list[str], db: str | Path, structure: str, period: tuple[float, float], *,
                   workers: int | None = None, scheduler: str | None = None, options: AnalysisOptions = AnalysisOptions(),
                   progress: bool = True) -> dict[str, Any]:
    """Learn a baseline of ``structure`` from ``paths`` within ``period`` (UNIX s) and store it as
    the structure's active baseline in ``db``. The files are estimated in parallel; their b(t),
    in time order, go through the one engine (``analytics.learn_baseline``, as ``shm analyze
    --baseline`` learns one), which learns from every trusted window of the period. Returns a
    summary; raises ValueError when no baseline can be learnt (saying what was missing)."""
    import numpy as np

    from analytics import AnalysisConfig
    from analytics import learn_baseline as engine_baseline
    from estimator import build_model, damage_signatures

    from ._common import model_kwargs
    from ..recording import read_recording
    from ..service.storage._storage import Storage

    lo, hi = period
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"period={period!r} must be (start, end) in UNIX s with end after start")
    parts, failures = _estimate_parts(paths, options, (lo, hi), workers, scheduler, progress)
    if not parts:
        raise ValueError(f"no samples of {len(paths)} file(s) within the period {lo:.0f}..{hi:.0f} s"
                         + (f" ({len(failures)} failed: {failures[0]['error']})" if failures else ""))
    kept = _without_overlaps(parts)
    rec = read_recording(kept[0]["path"], rig=options.rig, kinds=())
    model = build_model(rec.rig, **model_kwargs(rec.rig, options.namespace()))
    config, _ = options.settings()
    config = config or AnalysisConfig()
    origin_ns, t, b, support, temperature = _joined(kept)
    try:
        baseline = engine_baseline(
            t, b, model.units.curvature(model.stations), model.stations, temperature=temperature, bearing=support,
            expected_hz=model.units.frequencies_hz, config=config, beam_length=model.rig.beam.length,
            signatures=damage_signatures(model.rig, model.stations, gamma=model.gamma), time_origin_ns=origin_ns)
    except ValueError as exc:  # analytics.BaselineError names what each mode lacked
        raise ValueError(f"no baseline of {structure} from {len(kept)} file(s): {exc}") from None
    lacking = [m.mode for m in baseline.modes if m.windows < config.baseline_min_windows]
    storage = Storage(db)
    try:
        baseline_id = storage.store_baseline(structure, baseline.to_dict())
    finally:
        storage.close()
    return {
        "structure": structure, "baseline_id": baseline_id, "files": len(paths), "files_used": len(kept), "failed": failures,
        "trusted_windows": baseline.trusted_windows,
        "start_s": origin_ns / 1e9 + baseline.start_s, "end_s": origin_ns / 1e9 + baseline.end_s,
        "modes": [{"mode": m.mode, "unit": m.unit, "frequency_hz": m.f_ref_hz, "sigma_rel": m.sigma_rel, "windows": m.windows}
                  for m in baseline.modes],
        "modes_without_enough_windows": lacking,
        "samples": int(t.size),
        "mean_temperature_c": None if temperature is None else float(np.mean(temperature[1])),
    }


def _estimate_parts(paths: list[str], options: AnalysisOptions, period: tuple[float, float], workers: int | None,
                    scheduler: str | None, progress: bool) -> tuple[list[dict[str, Any]], list[dict[str, str]]]:
    """The files' b(t) within ``period``, estimated in parallel (``deformation_task``), and the failures."""
    from distributed import as_completed

    parts, failures = [], []
    with _client(workers, scheduler) as client:
        futures = {client.submit(deformation_task, p, options, period, pure=False): p for p in paths}
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
    return parts, failures


def _without_overlaps(parts: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The parts in time order; overlapping files (the same period twice) keep the earlier file's samples."""
    kept, newest = [], -math.inf
    for p in sorted(parts, key=lambda p: float(p["t"][0])):
        m = p["t"] > newest
        if m.any():
            kept.append({**p, "t": p["t"][m], "b": p["b"][m], "support": None if p["support"] is None else p["support"][m]})
            newest = float(p["t"][m][-1])
    return kept


def _joined(kept: list[dict[str, Any]]) -> tuple[int, Any, Any, Any, Any]:
    """The parts as one record: origin (whole UNIX s, ns), t (s after it), b, the support's d (None
    unless every part has it) and the temperature (times s after the origin, °C; None: none)."""
    import numpy as np

    origin_ns = int(math.floor(float(kept[0]["t"][0]))) * 1_000_000_000
    t = np.concatenate([p["t"] for p in kept]) - origin_ns / 1e9
    b = np.concatenate([p["b"] for p in kept])
    with_support = all(p["support"] is not None for p in kept)
    support = np.concatenate([p["support"] for p in kept]) if with_support else None
    temps = [p["temperature"] for p in kept if p["temperature"] is not None]
    temperature = None
    if temps:
        tt = np.concatenate([x[0] for x in temps]) - origin_ns / 1e9
        tv = np.concatenate([x[1] for x in temps])
        order = np.argsort(tt, kind="stable")
        tt, tv = tt[order], tv[order]
        first = np.concatenate([[True], np.diff(tt) > 0])
        temperature = (tt[first], tv[first])
    return origin_ns, t, b, support, temperature


# -- the commands: shm reprocess, shm baseline learn ------------------------------------------
def _analysis_options(args: argparse.Namespace):
    return AnalysisOptions(rig=args.rig, peripheral=args.peripheral, modes=args.modes, modes_xi=args.modes_xi, imus=args.imus,
                           tofs=args.tofs, gauges=args.gauges, config=args.config)


def cmd_reprocess(args: argparse.Namespace) -> int:
    import time

    started = time.perf_counter()
    outcomes = reprocess(args.recordings, args.db, workers=args.workers, scheduler=args.scheduler, force=args.force,
                         options=_analysis_options(args), source=args.structure, progress=not args.json)
    wall = time.perf_counter() - started
    if args.json:
        _print_json({"files": [o.as_dict() for o in outcomes], "wall_s": round(wall, 3)})
    else:
        for o in outcomes:
            detail = f"{o.windows} windows" if o.status == "done" else (o.error or "")
            print(f"{o.status:8} {o.path}  {detail}")
        counts = {s: sum(o.status == s for o in outcomes) for s in ("done", "skipped", "failed")}
        print(f"{counts['done']} done, {counts['skipped']} skipped, {counts['failed']} failed in {wall:.1f} s -> {args.db}")
    return 1 if any(o.status == "failed" for o in outcomes) else 0


def cmd_baseline_learn(args: argparse.Namespace) -> int:
    period = (args.start if args.start is not None else -math.inf, args.end if args.end is not None else math.inf)
    if period[0] >= period[1]:
        raise CliError(f"--from {args.start} must be before --to {args.end}")
    try:
        summary = learn_baseline(args.recordings, args.db, args.structure, (max(period[0], -1e18), min(period[1], 1e18)),
                                 workers=args.workers, scheduler=args.scheduler, options=_analysis_options(args),
                                 progress=not args.json)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.json:
        _print_json(summary)
    else:
        print(f"baseline {summary['baseline_id']} of {summary['structure']} from {summary['trusted_windows']} trusted "
              f"windows in {summary['files_used']} file(s), stored in {args.db} (active)")
        for m in summary["modes"]:
            print(f"  mode {m['mode']} (unit {m['unit']}): {m['frequency_hz']:.4f} Hz ± {100 * m['sigma_rel']:.3f} % "
                  f"({m['windows']} windows)")
        for failure in summary["failed"]:
            print(f"  failed: {failure['path']}: {failure['error']}")
    return 0
