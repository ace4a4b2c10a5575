"""The processing pipeline: merge → estimator (every sample) → analytics (every window step) →
storage, alarms, recordings, dashboard.

It runs in one thread fed by a bounded queue of ``Batch`` objects (the sources block when it is
full: back-pressure). Memory is bounded: the merge holds at most ``lateness_s`` of samples, the
estimator a few seconds, the analytics one window of b(t) (chunks older than the next window
are dropped).
"""

from __future__ import annotations

import logging
import math
import os
import queue
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from threadpoolctl import threadpool_limits

from analytics import AnalysisConfig, Baseline, EngineWindow, ModalMonitor, MonitoringEngine, WindowResult
from contract import (
    TEMPERATURE_TOPIC,
    AlarmDocument,
    ChartDocument,
    CurvatureDocument,
    FlagDocument,
    LocationDocument,
    ModeDocument,
    PipelineStatusDocument,
    SpectrumDocument,
    TrendRow,
    WindowDocument,
    estimate_payloads,
)
from estimator import (
    StreamingEstimator,
    StreamingSettings,
    FilterOutput,
    ImmsModel,
    RestCalibration,
    damage_signatures,
)

from ..analysis import trend_rows
from ..recording import FollowBlock, encode_payloads_json
from ._alarms import alarm_changes, clear_changes
from ._archive import Archive
from ._sinks import SinkGuard
from ._checks import CheckSettings, SampleChecks
from ._merge import MergeSettings, MergeStage
from ._plausibility import SourceClock, ValueLimits
from ._storage import AlarmChange, Storage, WindowCommit, is_transient

__all__ = ["Batch", "Pipeline", "PipelineSink"]

log = logging.getLogger("shm.serve.pipeline")

FS = 200.0
_NS = 1_000_000_000
_D_TOPIC = "/imu/D"


@dataclass
class Batch:
    """What a source hands the pipeline: new accepted samples per topic, optionally the raw
    messages for the recordings (topic, log_time_ns, payload, publish_time_ns) and the truth
    deflection (simulation)."""

    blocks: list[FollowBlock]
    raw: list[tuple[str, int, bytes, int]] | None = None
    truth: tuple[np.ndarray, np.ndarray] | None = None
    received: float = field(default_factory=time.monotonic)
    refused: dict[str, int] | None = None  # samples per topic the source refused (its sensor is degraded meanwhile)


class PipelineSink(Protocol):
    """Where the pipeline pushes live data (the dashboard adapter). ``x`` is a state vector in
    the model's ``StateLayout``. Whatever a sink raises is counted and never stops the pipeline."""

    def estimate(self, t_s: float, x: np.ndarray, truth_deflection: np.ndarray | None) -> None: ...
    def spectra(self, spectrum: SpectrumDocument) -> None: ...
    def window(self, window: WindowDocument) -> None: ...
    def alarm(self, alarm: AlarmDocument) -> None: ...


class LiveRingLike(Protocol):
    """A structure's live ring (``_live.LiveRing``): takes every batch's estimates (``t_s`` (n,), ``x`` (n, nx))."""

    def add(self, t_s: np.ndarray, x: np.ndarray) -> None: ...


_blas_limit = None


def _one_blas_thread() -> None:
    """Run BLAS/LAPACK single-threaded in this process (once; an explicit OPENBLAS_NUM_THREADS or
    OMP_NUM_THREADS is left alone).

    The analysis multiplies and decomposes small matrices (a 120 × 120 block Toeplitz per window)
    while the source thread decodes on the other core: OpenBLAS's worker threads then spin for
    the cores and one SSI-cov window took 4-10× the CPU of a single thread (measured on the
    2-core machine under load). Results are the same bits: each output element is computed by
    the same kernel either way."""
    global _blas_limit
    if _blas_limit is None and not {"OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"} & set(os.environ):
        _blas_limit = threadpool_limits(1, user_api="blas")


# -- merge ------------------------------------------------------------------------------------


# the merge stage (``MergeStage``): its own module


# -- estimator --------------------------------------------------------------------------------


def calibration_to_dict(cal: RestCalibration) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in vars(cal).items()}


def calibration_from_dict(d: dict) -> RestCalibration:
    fields = RestCalibration.__dataclass_fields__
    kw = {}
    for name in fields:
        value = d[name]
        kw[name] = np.asarray(value, dtype=float) if isinstance(value, list) else value
    kw["rest_end"] = float(kw["rest_end"])
    kw["rested"] = bool(kw["rested"])
    kw["bearing_std"] = float("nan") if kw["bearing_std"] is None else float(kw["bearing_std"])
    return RestCalibration(**kw)


# -- analytics --------------------------------------------------------------------------------


class _LazySpectrum:
    """A window's ``SpectrumDocument``, built the first time it is asked for (the API, the
    dashboard): validating its few thousand amplitudes costs about 30 ms a window, and a replay
    without a dashboard asks for none. Safe to call from any thread (the arguments are kept)."""

    __slots__ = ("_kwargs", "_document")

    def __init__(self, **kwargs) -> None:
        self._kwargs = kwargs
        self._document: SpectrumDocument | None = None

    def get(self) -> SpectrumDocument:
        if self._document is None:
            self._document = SpectrumDocument.from_arrays(**self._kwargs)
        return self._document


@dataclass
class WindowOutput:
    result: WindowResult
    rows: list[TrendRow]
    spectrum: _LazySpectrum
    start_s: float
    new_baseline: bool
    alarm_changes: list[AlarmChange]


def _monitor_stations(model) -> np.ndarray:
    """Where curvature is monitored: the rig's truth stations, else (``truth_stations: []``) 8 evenly
    spaced stations (damage_signatures' default)."""
    if len(model.stations):
        return np.asarray(model.stations, dtype=float)
    return np.linspace(0.0, model.rig.beam.length, 9)[1:]


class _Analytics:
    """The one engine (``analytics.MonitoringEngine``, the same ``shm analyze`` runs) over the
    estimator's b(t) and support displacement d(t), and what the service makes of its windows:
    trend rows, spectra, alarm changes. Windows are aligned to multiples of the step in UNIX
    time, so replaying a period gives the same windows (and the unique key of the trend rows holds)."""

    def __init__(self, model: ImmsModel, config: AnalysisConfig, monitor_state: dict | None, last_window_start: float | None,
                 source_id: str, min_coverage: float = 0.8, baseline: dict | None = None) -> None:
        self.model = model
        self.config = config
        self.source_id = source_id
        self.gamma = model.gamma
        self.window_s = config.window_s
        self.step_s = config.window_s * (1 - config.overlap)
        self.min_coverage = min_coverage
        self.signatures = None
        self.monitor = self._monitor(monitor_state, baseline)
        self.engine: MonitoringEngine | None = None
        self._next_start_ns = None if last_window_start is None else int(round(last_window_start * _NS)) + int(round(self.step_s * _NS))
        self.not_before_ns: int | None = None  # windows starting earlier are not analysed (filter converging)
        self._latest_spectrum: _LazySpectrum | None = None
        self.learning_baseline = self.monitor.baseline is None
        self._temperature: list[tuple[np.ndarray, np.ndarray]] = []  # samples before the engine starts

    def _monitor(self, state: dict | None, baseline: dict | None = None) -> ModalMonitor:
        m = self.model
        if self.signatures is None:
            # FE-predicted damage signatures of the rig: where along the beam a flag points.
            self.signatures = damage_signatures(m.rig, _monitor_stations(m), gamma=m.gamma)
        if state is not None:
            try:
                monitor = ModalMonitor.from_state_dict(state)
                if monitor.config != self.config:
                    raise ValueError("the analytics configuration changed")
                monitor.signatures = self.signatures  # model-derived, not part of the stored state
                return monitor
            except (ValueError, TypeError) as exc:
                log.warning("stored monitor state unusable (%s); starting a new monitor", exc)
        stored = None
        if baseline is not None:
            try:
                stored = Baseline.from_dict(baseline)
            except ValueError as exc:
                log.warning("stored baseline unusable (%s); learning a new one", exc)
        try:
            stations = _monitor_stations(m)
            return ModalMonitor(m.units.frequencies_hz, m.units.curvature(stations), stations, fs=FS, config=self.config,
                                baseline=stored, beam_length=m.rig.beam.length, signatures=self.signatures)
        except ValueError as exc:  # a baseline of another model (modes)
            if stored is None:
                raise
            log.warning("stored baseline does not fit the model (%s); learning a new one", exc)
            return self._monitor(None)

    @property
    def latest_spectrum(self) -> SpectrumDocument | None:
        latest = self._latest_spectrum
        return None if latest is None else latest.get()

    # -- the engine's counters ------------------------------------------------------------------
    @property
    def windows(self) -> int:
        return 0 if self.engine is None else self.engine.windows

    @property
    def skipped_incomplete(self) -> int:
        return 0 if self.engine is None else self.engine.skipped_incomplete

    @property
    def skipped_warmup(self) -> int:
        return 0 if self.engine is None else self.engine.skipped_warmup

    @property
    def next_start(self) -> float | None:
        ns = self._next_start_ns if self.engine is None else self.engine.next_start_ns
        return None if ns is None else ns / _NS

    def active(self) -> dict[str, str]:
        return self.monitor.alarms.raised()

    def set_not_before(self, ns: int) -> None:
        self.not_before_ns = int(ns)
        if self.engine is not None:
            self.engine.not_before_ns = self.not_before_ns

    def reset(self) -> None:
        """A new baseline is learnt from the next windows (the alarms are cleared by the caller)."""
        self.monitor = self._monitor(None)
        if self.engine is not None:
            self.engine.reset(self.monitor)
        self.learning_baseline = True

    # -- data ---------------------------------------------------------------------------------
    def add(self, epoch_ns: int, t: np.ndarray, b: np.ndarray, d: np.ndarray | None,
            temperature: tuple[np.ndarray, np.ndarray] | None) -> list[WindowOutput]:
        """b (n, Γ) and the support displacement d (n,) at t (n,) s after ``epoch_ns``; temperature
        (times s after epoch_ns, °C) or None."""
        if self.engine is None:
            if temperature is not None:
                self._temperature.append(temperature)
            if not len(t):
                return []
            self.engine = MonitoringEngine(self.monitor, origin_ns=epoch_ns, time_zero_ns=0, not_before_ns=self.not_before_ns,
                                           next_start_ns=self._next_start_ns, min_coverage=self.min_coverage)
            for tt, tv in self._temperature:  # the current chunk's temperature is among them
                self.engine.add([], np.zeros((0, self.gamma)), temperature=(tt, tv))
            self._temperature = []
            temperature_now = None
        else:
            temperature_now = temperature
        out: list[WindowOutput] = []
        if not len(t):
            if temperature_now is not None:
                self.engine.add([], np.zeros((0, self.gamma)), temperature=temperature_now)
            return out
        had = self.monitor.baseline is not None
        for w in self.engine.add(t, b, support=d, temperature=temperature_now):
            out.append(self._output(w, had))
            had = self.monitor.baseline is not None
        return out

    def _per_unit(self, per_mode: list[float]) -> list[list[float]]:
        """Per-mode frequencies grouped by unit deformation (unit 1, the combimode, holds modes 1 and 2)."""
        return [[f for f, u in zip(per_mode, self.monitor.units) if u == unit] for unit in range(self.gamma)]

    def _output(self, w: EngineWindow, had_baseline: bool) -> WindowOutput:
        res = w.result
        start, end = w.start_ns / _NS, res.end_s
        self.learning_baseline = self.monitor.baseline is None
        rows = trend_rows(self.source_id, res, start, end)
        spec = res.spectrum
        pad = spec.pad_factor
        f, amp = spec.frequencies[::pad], spec.amplitude[::pad]  # the unpadded DFT bins of the window
        keep = f <= 12.0
        baseline = self.monitor.baseline
        self._latest_spectrum = spectrum = _LazySpectrum(
            source=self.source_id, window_start_s=start, window_end_s=end, frequencies_hz=f[keep],
            amplitudes=amp[keep], tracked_hz=self._per_unit([float(x) for x in self.monitor.ref]),
            baseline_hz=None if baseline is None else self._per_unit([m.f_ref_hz for m in baseline.modes]),
        )
        return WindowOutput(res, rows, spectrum, start, baseline is not None and not had_baseline,
                            alarm_changes(res.alarm_events))


# -- the pipeline -----------------------------------------------------------------------------


@dataclass
class _SetAside:
    """What a stop under a backlog left unanalysed: samples (and how many of them went to the
    recording), their data time span, analysis chunks."""

    samples: int = 0
    recorded: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    chunks: int = 0

    def add(self, batch: Batch) -> None:
        for block in batch.blocks:
            if len(block):
                self.samples += len(block)
                lo, hi = int(block.log_time_ns[0]), int(block.log_time_ns[-1])
                self.first_ns = lo if self.first_ns is None else min(self.first_ns, lo)
                self.last_ns = hi if self.last_ns is None else max(self.last_ns, hi)

    def describe(self) -> str | None:
        if not self.samples and not self.chunks:
            return None
        span = "" if self.first_ns is None else f" ({(self.last_ns - self.first_ns) / _NS:.1f} s of data from {self.first_ns / _NS:.3f})"
        where = (f"{self.recorded} of them in the recording" if self.recorded
                 else "not recorded (their source's file holds them, or the recording of raw samples is off)")
        return (f"stopped under a backlog: {self.samples} samples{span} not estimated, {where}; "
                f"{self.chunks} estimator chunk(s) not analysed")


@dataclass
class _PendingCommit:
    """A window's transaction not yet written (the database was unavailable), with the alarm
    state it leads to and what goes to the dashboard once it is written."""

    commit: WindowCommit
    raised: dict[str, str]  # chart -> level of the alarms standing once it is written
    document: WindowDocument | None = None
    spectrum: _LazySpectrum | None = None


class Pipeline:
    """Runs the stages for one source. ``process(batch)`` and ``finish()`` are called from one
    thread; ``status()`` from any."""

    def __init__(self, *, model: ImmsModel, source_id: str, storage: Storage, analysis: AnalysisConfig,
                 calibration_s: float, chunk_s: float, lateness_s: float, silent_after_s: float,
                 archive: Archive | None = None, archive_raw: bool = False,
                 archive_estimates: bool = True, estimate_decimation: int = 1, sink: PipelineSink | None = None,
                 sink_guard: SinkGuard | None = None, sink_estimate_hz: float = 15.0, warmup_s: float = 120.0,
                 commit_retry_s: float = 5.0, max_pending_commits: int = 20_000, clock: SourceClock | None = None,
                 limits: ValueLimits | None = None, stuck_after_s: float = 1.0, analysis_thread: bool = False) -> None:
        _one_blas_thread()
        self.model = model
        self.rig = model.rig
        self.warmup_s = warmup_s
        self.source_id = source_id
        self.storage = storage
        stored = storage.load_state(source_id) or {}
        blob = stored.get("monitor") or {}
        cal = stored.get("calibration")
        calibration = None
        if cal is not None:
            try:
                calibration = calibration_from_dict(cal)
            except (KeyError, TypeError, ValueError) as exc:
                log.warning("stored calibration unusable (%s); calibrating again", exc)
        self.resumed = bool(stored)
        self.merger = MergeStage(MergeSettings(lateness_s=lateness_s))
        # the one estimator policy (estimate(), shm estimate, shm analyze run the same)
        self.estimator = StreamingEstimator(model, StreamingSettings(calibration_s=calibration_s, chunk_s=chunk_s), calibration)
        # one alarm path: the engine's (the service's [alarms] hysteresis is in it: ServiceSettings.engine_config)
        self.analysis = analysis
        # Without a monitor to resume, the source's active baseline (shm baseline learn) arms a new one.
        baseline = None if blob.get("monitor") else storage.active_baseline(source_id)
        self.analytics = _Analytics(model, analysis, blob.get("monitor"), stored.get("last_window_start_s"), source_id,
                                    baseline=baseline)
        # The alarms as the database holds them: the engine's alarm logic runs ahead of it while
        # windows wait for the database, and what is reported comes from here.
        self.committed_alarms: dict[str, str] = self.analytics.active()
        self._pending_commits: deque[_PendingCommit] = deque()
        self.commit_retry_s = commit_retry_s
        self.max_pending_commits = max_pending_commits
        # plausibility of what the source delivers (None: judged by the source itself, as ingest is)
        self.checks = SampleChecks(CheckSettings(stuck_after_s=stuck_after_s, silent_after_s=silent_after_s), clock, limits)
        self.storage_error: str | None = None  # set while windows wait for the database
        self.storage_errors = 0  # commits that failed (and wait to be retried)
        self.trend_rows_dropped = 0  # rows of waiting windows dropped beyond max_pending_commits (their alarms kept)
        self.silent_after_ns = int(silent_after_s * _NS)
        self.archive = archive
        self.archive_raw = archive_raw and archive is not None
        self.archive_estimates = archive_estimates and archive is not None
        self.decimation = estimate_decimation
        self.sink = sink
        self.live: "LiveRingLike | None" = None  # set by the service: the batches' estimates for a live view of the structure
        # A failing sink is counted and logged once per kind; it never stops a batch.
        self.sink_guard = sink_guard or SinkGuard("dashboard", log)
        self.sink_period = 1.0 / sink_estimate_hz
        self._last_push = -math.inf
        self._truth: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=8)
        self._reset_requested = False
        # counters
        self.samples: Counter = Counter()
        self.last_time_ns: dict[str, int] = {}
        self.estimates = 0
        self.newest_ns: int | None = None
        self.processed_ns: int | None = None
        self.latency_s = 0.0
        self.busy_s = 0.0
        self.started = time.monotonic()
        self.windows_committed = 0
        self.last_window: WindowDocument | None = None
        self.latest_x: np.ndarray | None = None
        self._temperature_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._bearing_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._estimate_maps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._warmup_set = False
        # The analysis stage (windows, commits) in a thread of its own (``start_analysis``), so that
        # a window's analysis never holds up the estimator and the batches behind it; None: it
        # runs inline, within ``process`` (replays into a database, tests, benchmarks).
        self._analysis: queue.Queue | None = queue.Queue(maxsize=256) if analysis_thread else None
        self._analysis_thread: threading.Thread | None = None
        self._on_analysis_error = None
        self.analysis_error: str | None = None  # the last chunk's analysis error; None once one analyses fine
        # A stop under a backlog: after this monotonic instant the batches and chunks left are set
        # aside (their raw samples recorded when the recording takes them), not estimated.
        self.stop_deadline: float | None = None
        self.set_aside = _SetAside()

    # -- control ----------------------------------------------------------------------------

    def request_baseline(self) -> None:
        """Learn a new baseline from the next windows (called from the API thread)."""
        self._reset_requested = True

    def start_analysis(self, on_error=None, name: str = "analysis") -> None:
        """Start the analysis thread (``analysis_thread=True``); ``on_error(exc)`` is called for
        what a chunk's analysis raises (the chunk's windows are skipped, the next are analysed)."""
        if self._analysis is None or self._analysis_thread is not None:
            return
        self._on_analysis_error = on_error
        self._analysis_thread = threading.Thread(target=self._analysis_loop, name=name, daemon=True)
        self._analysis_thread.start()

    def _analysis_loop(self) -> None:
        assert self._analysis is not None
        while True:
            try:
                item = self._analysis.get(timeout=1.0)
            except queue.Empty:
                # No data: windows that wait for the database are tried again meanwhile.
                if self._pending_commits:
                    self._guarded(self.flush_commits)
                continue
            if item is None:
                return
            kind, args = item
            if kind == "chunk" and self.past_stop_deadline():
                self.set_aside.chunks += 1
                continue
            if kind == "chunk":
                if self._guarded(self._flush_then_analyse, *args):
                    self.analysis_error = None
            elif kind == "not_before":
                self._not_before_now(args)
            else:
                raise ValueError(f"unknown analysis item {kind!r}")

    def _flush_then_analyse(self, *args) -> None:
        if self._pending_commits:
            self.flush_commits()
        self._analyse_now(*args)

    def _guarded(self, fn, *args) -> bool:
        try:
            fn(*args)
            return True
        except Exception as exc:  # one chunk's failure must not stop the analysis of the next
            self.analysis_error = f"{type(exc).__name__}: {exc}"
            if self._on_analysis_error is not None:
                self._on_analysis_error(exc)
            else:
                log.exception("%s: analysis error; chunk skipped", self.source_id)
            return False

    # -- data path --------------------------------------------------------------------------

    def process(self, batch: Batch) -> None:
        began = time.monotonic()
        if self._pending_commits and self._analysis_thread is None:
            self.flush_commits()
        for block in self.checks.judge(batch.blocks, self.newest_ns):
            if not len(block):
                continue
            self.checks.watch_stuck(block)
            self.samples[block.topic] += len(block)
            last = int(block.log_time_ns[-1])
            self.last_time_ns[block.topic] = max(self.last_time_ns.get(block.topic, last), last)
            self.newest_ns = last if self.newest_ns is None else max(self.newest_ns, last)
            self.merger.add(block)
        self.checks.note_refused(tuple(batch.refused or ()), self.newest_ns)
        if batch.truth is not None:
            self._truth.append(batch.truth)
        if self.archive_raw and batch.raw:
            self.archive.write_many(batch.raw)
        self._advance(self.merger.release())
        if self.archive is not None:
            self.archive.maybe_flush()
        done = time.monotonic()
        self.latency_s = done - batch.received
        self.busy_s += done - began

    def past_stop_deadline(self) -> bool:
        return self.stop_deadline is not None and time.monotonic() > self.stop_deadline

    def set_batch_aside(self, batch: Batch) -> None:
        """A batch of the backlog left at the stop's deadline: recorded (when the recording takes
        the raw samples; a file source's data are in its file), not estimated."""
        self.set_aside.add(batch)
        if self.archive_raw and batch.raw:
            self.archive.write_many(batch.raw)
            self.set_aside.recorded += sum(len(b) for b in batch.blocks)

    def stuck_sensors(self) -> list[str]:
        """Topics whose readings have stayed exactly the same for ``stuck_after_s`` and more."""
        return self.checks.stuck_sensors()

    @property
    def rejected(self) -> Counter:
        return self.checks.rejected

    @property
    def clock(self) -> SourceClock | None:
        return self.checks.clock

    def _advance(self, released: dict[str, tuple[np.ndarray, np.ndarray]], final: bool = False) -> None:
        if released:
            self.processed_ns = max(int(t[-1]) for t, _ in released.values())
        elif not final:
            return
        restarts = self.estimator.resets
        out = self.estimator.feed(released) if released else None
        if final:
            tail = self.estimator.finish()
            if tail is not None and out is not None:
                out = FilterOutput.concatenate([out, tail], self.model.state_size)
            elif tail is not None:
                out = tail
        if self.estimator.resets != restarts and self.estimator.restarted_at_s is not None and self.estimator.epoch_ns:
            # Windows that would hold the diverged filter's b (or the new one's first seconds) are not analysed.
            settle = self.estimator.epoch_ns + int(round((self.estimator.restarted_at_s + self.estimator.health_config.settle_s) * _NS))
            self._not_before(settle)
        self._emit(out, released.get(TEMPERATURE_TOPIC))

    def _emit(self, out: FilterOutput | None, temp) -> None:
        epoch = self.estimator.epoch_ns
        if epoch is None:
            return
        # times after the estimator's epoch (whole UNIX seconds): the engine aligns its windows
        # in data time from there to the nanosecond
        temperature = None if temp is None else ((temp[0] - epoch) * 1e-9, temp[1][:, 0])
        if out is None or not len(out.t):
            if temperature is not None:
                self._analyse(epoch, np.zeros(0), np.zeros((0, self.model.gamma)), None, temperature, None)
            return
        self.estimates += len(out.t)
        if not self._warmup_set and self.estimator.calibration is not None:
            self._warmup_set = True
            warm = epoch + int(round((float(self.estimator.calibration.rest_end) + self.warmup_s) * _NS))
            self._not_before(warm)
        t_abs = epoch / _NS + out.t
        layout = self.model.state_layout
        b = layout.b_of(out.x)
        d = out.x[:, layout.d]  # the support displacement: the measured input of the identification
        self.latest_x = out.x[-1]
        if self.archive_estimates:
            self._archive_estimates(out)
        self._push_estimates(t_abs, out)
        self._analyse(epoch, out.t, b, d, temperature, float(t_abs[0]))

    # -- the analysis stage (inline, or in its thread in this order) ----------------------------

    def _analyse(self, epoch: int, t: np.ndarray, b: np.ndarray, d: np.ndarray | None, temperature, first_s: float | None) -> None:
        if self._analysis_thread is None:
            self._analyse_now(epoch, t, b, d, temperature, first_s)
        else:
            self._put(("chunk", (epoch, t, b, d, temperature, first_s)))

    def _not_before(self, ns: int) -> None:
        if self._analysis_thread is None:
            self._not_before_now(ns)
        else:
            self._put(("not_before", ns))

    def _put(self, item) -> None:
        if self._analysis_thread is not None and not self._analysis_thread.is_alive():
            raise RuntimeError("the analysis thread has ended")
        self._analysis.put(item)  # bounded: an analysis falling behind holds the data path back

    def _not_before_now(self, ns: int) -> None:
        self.analytics.set_not_before(max(self.analytics.not_before_ns or ns, ns))

    def _analyse_now(self, epoch: int, t: np.ndarray, b: np.ndarray, d: np.ndarray | None, temperature,
                     first_s: float | None) -> None:
        if first_s is not None and self._reset_requested:
            self._reset_requested = False
            self.analytics.reset()
            self._clear_for_new_baseline(first_s)
        for window in self.analytics.add(epoch, t, b, d, temperature):
            self._commit(window)

    def drain_analysis(self) -> None:
        """Wait until the analysis thread analysed everything handed to it, and end it."""
        if self._analysis_thread is None:
            return
        self._put(None)
        self._analysis_thread.join()

    def _archive_estimates(self, out: FilterOutput) -> None:
        k = self.decimation
        t, x, P = out.t[::k], out.x[::k], out.P_diag[::k]
        if not len(t):
            return
        layout = self.model.state_layout
        if self._estimate_maps is None:  # b → tip deflection, deflection and curvature at the stations
            m = self.model
            self._estimate_maps = (m.tip_row(), m.units.shape(m.stations).T, m.units.curvature(m.stations).T)
        tip, shape, curvature = self._estimate_maps
        b = layout.b_of(x)
        rows = estimate_payloads(layout, x, P, b @ tip, b @ shape, b @ curvature)
        stamps = self.estimator.epoch_ns + np.round(t * 1e9).astype(np.int64)
        self.archive.write_estimates(stamps, encode_payloads_json(rows))

    def _push_estimates(self, t_abs: np.ndarray, out: FilterOutput) -> None:
        if self.live is not None:  # the structure's live ring: keeps them (decimated) only while watched
            self.sink_guard.call("live", self.live.add, t_abs, out.x)
        if self.sink is None:
            return
        now = time.monotonic()
        if now - self._last_push < self.sink_period:
            return
        self._last_push = now
        truth = None
        if self._truth:
            tt, defl = self._truth[-1]
            target = self.estimator.epoch_ns + int(round(out.t[-1] * 1e9))
            k = int(np.clip(np.searchsorted(tt, target), 0, len(tt) - 1))
            if abs(int(tt[k]) - target) < 50_000_000:
                truth = defl[k]
        self.sink_guard.call("estimate", self.sink.estimate, float(t_abs[-1]), out.x[-1].copy(), truth)

    def _clear_for_new_baseline(self, at_s: float) -> None:
        """A new baseline: every chart starts over and every active alarm of the source clears
        (those stored and those raised by windows still waiting for the database)."""
        active = {a.chart: a for a in self.storage.alarms(state="active") if a.source == self.source_id}
        for pending in self._pending_commits:
            for c in pending.commit.alarm_changes:
                if c.action == "raise":
                    active[c.chart] = AlarmDocument(id=1, source=self.source_id, chart=c.chart, kind=c.kind, mode=c.mode,
                                                    level=c.level, state="active", raised_at_s=c.at_s, message=c.message)
                elif c.action == "clear":
                    active.pop(c.chart, None)
        changes = clear_changes(active.values(), at_s)
        start = self.analytics.next_start - self.analytics.step_s if self.analytics.next_start else at_s
        commit = WindowCommit(self.source_id, start, at_s, [], {"monitor": None}, None, changes)
        self._pending_commits.append(_PendingCommit(commit, {}))
        self.flush_commits()

    def _commit(self, window: WindowOutput) -> None:
        res = window.result
        charts = list(res.charts)
        changes = window.alarm_changes
        baseline = self.analytics.monitor.baseline.to_dict() if window.new_baseline else None
        calibration = None
        if self.estimator.new_calibration and self.estimator.calibration is not None:
            calibration = calibration_to_dict(self.estimator.calibration)
            self.estimator.new_calibration = False
        document = window_document(self.source_id, res, window.rows, charts)
        commit = WindowCommit(
            source=self.source_id, window_start_s=window.start_s, data_time_s=res.end_s, rows=window.rows,
            monitor_state={"monitor": self.analytics.monitor.state_dict()},
            calibration=calibration, alarm_changes=changes, baseline=baseline,
        )
        self._pending_commits.append(_PendingCommit(commit, self.analytics.active(), document, window.spectrum))
        if len(self._pending_commits) > self.max_pending_commits:
            oldest = self._pending_commits[0]
            self.trend_rows_dropped += len(oldest.commit.rows)
            oldest.commit.rows = []
        self.flush_commits()

    def flush_commits(self, retry_s: float | None = None) -> bool:
        """Write the waiting windows in their order. Alarm state changes take effect (and reach
        the dashboard) only once their window is written; a transient database error leaves the
        window waiting for the next attempt (the storage already retried it for ``retry_s``).
        Returns True when nothing waits any more."""
        while self._pending_commits:
            pending = self._pending_commits[0]
            try:
                self.storage.commit_window(pending.commit, retry_s=self.commit_retry_s if retry_s is None else retry_s)
            except Exception as exc:
                if not is_transient(exc):
                    # Not a passing fault but a bad transaction: retrying it would stop every later window.
                    self._pending_commits.popleft()
                    raise
                self.storage_errors += 1
                self.storage_error = (f"storage: {exc}; {len(self._pending_commits)} window(s) wait to be written "
                                      "(retried with every batch)")
                if self.storage_errors <= 3 or self.storage_errors % 100 == 0:
                    log.error("%s", self.storage_error)
                return False
            self._pending_commits.popleft()
            self.committed_alarms = dict(pending.raised)
            if pending.document is not None:
                self.windows_committed += 1
                self.last_window = pending.document
            self._after_commit(pending)
        self.storage_error = None
        return True

    @property
    def analysis_threaded(self) -> bool:
        """Whether the windows are analysed in the analysis thread (``start_analysis``)."""
        return self._analysis_thread is not None

    @property
    def pending_commits(self) -> int:
        return len(self._pending_commits)

    def _after_commit(self, pending: _PendingCommit) -> None:
        if self.sink is None:
            return
        guard = self.sink_guard
        if pending.document is not None:
            guard.call("window", self.sink.window, pending.document)
        if pending.spectrum is not None:
            guard.call("spectra", self.sink.spectra, pending.spectrum.get())
        changes = pending.commit.alarm_changes
        if changes:
            changed = {c.chart for c in changes}
            for alarm in self.storage.alarms(limit=len(changes) + 5):
                if alarm.source == self.source_id and alarm.chart in changed:
                    guard.call("alarm", self.sink.alarm, alarm)

    def finish(self) -> None:
        """The source ended: release everything, flush the filter, analyse what is left, close the recording."""
        self._advance(self.merger.release(final=True), final=True)
        self.drain_analysis()
        if self._pending_commits:
            self.flush_commits(retry_s=max(self.commit_retry_s, 30.0))
        if self.archive is not None:
            self.archive.close()

    # -- status -----------------------------------------------------------------------------

    def health_problems(self) -> list[str]:
        """Why the pipeline's output cannot be trusted right now (empty: it can)."""
        problems = self.estimator.health_problems()
        if self.clock is not None:
            problems.extend(self.clock.problems())
        return problems

    def sensor_states(self) -> dict[str, str]:
        states: dict[str, str] = {}
        newest = self.newest_ns
        diag = self.estimator.filter.diagnostics() if self.estimator.filter is not None else {}
        inactive = {d["sensor"] for d in diag.get("degraded_imus", []) if not d.get("active", True)}
        inactive.update(self.checks.degraded(newest))
        for sensor in self.rig.sensors:
            topic = sensor.topic
            last = self.last_time_ns.get(topic)
            if last is None or (newest is not None and newest - last > self.silent_after_ns) or topic in inactive:
                states[topic] = "degraded"
            else:
                states[topic] = "ok"
        return states

    def status(self, *, queue_depth: int, queue_capacity: int) -> PipelineStatusDocument:
        elapsed = max(time.monotonic() - self.started, 1e-9)
        span = None
        if self.estimator.epoch_ns is not None and self.processed_ns is not None:
            span = (self.processed_ns - self.estimator.epoch_ns) / _NS
        return PipelineStatusDocument(
            queue_depth=queue_depth,
            queue_capacity=queue_capacity,
            samples=sum(self.samples.values()),
            samples_by_topic=dict(self.samples),
            late_samples=sum(self.merger.late.values()),
            late_by_topic=dict(self.merger.late),
            estimates=self.estimates,
            estimator=self.estimator.diagnostics(),
            windows=self.analytics.windows,
            windows_committed=self.windows_committed,
            windows_skipped_incomplete=self.analytics.skipped_incomplete,
            windows_skipped_warmup=self.analytics.skipped_warmup,
            baseline="learning" if self.analytics.learning_baseline else "active",
            data_time_s=None if self.newest_ns is None else self.newest_ns / _NS,
            processed_data_s=span,
            realtime_factor=None if span is None else round(span / elapsed, 2),
            pipeline_latency_s=round(self.latency_s, 4),
            busy_fraction=round(self.busy_s / elapsed, 3),
            active_alarms=dict(self.committed_alarms),
        )


def window_document(source: str, res: WindowResult, rows: list[TrendRow] | tuple = (),
                    charts: list[ChartDocument] | tuple = ()) -> WindowDocument:
    """The window as the dashboard shows it: the engine's result with each mode's estimate
    (frequency, damping and their 1σ, MPC, MAC), its chart, and the curvature change along η."""
    damping = {row.mode: row.damping_ratio for row in rows}
    by_mode = {c.mode: c for c in charts if c.kind == "frequency"}
    modes = []
    for i, e in enumerate(res.estimates):
        chart = by_mode.get(e.mode)
        modes.append(ModeDocument(
            mode=e.mode, unit=e.unit, frequency_hz=e.frequency_hz, amplitude=e.amplitude, confidence=round(e.confidence, 4),
            damping_ratio=damping.get(e.mode, e.damping_ratio), score_sigma=res.frequency_scores[i] if i < len(res.frequency_scores) else None,
            level=None if chart is None else chart.level, frequency_std_hz=e.frequency_std_hz, damping_std=e.damping_std,
            mpc=e.mpc, mac=e.mac, method=e.method,
        ))
    curvature = None
    if res.curvature is not None:
        c = res.curvature
        curvature = CurvatureDocument(index=[float(v) for v in c.index], total=float(c.total), eta_m=float(c.eta_m),
                                      third=c.third, score_sigma=res.curvature_score)
    return WindowDocument(
        source=source, start_s=res.start_s, end_s=res.end_s, kind=res.kind, trusted=res.trusted,
        temperature_c=res.temperature_c, modes=modes, charts=list(charts), curvature=curvature,
        flags=[FlagDocument(**f) for f in res.flags],
        location=None if res.location is None else LocationDocument(**res.location.as_dict()),
    )
