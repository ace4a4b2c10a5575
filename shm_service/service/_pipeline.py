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
    IMU_PLANAR_COLUMNS,
    TEMPERATURE_TOPIC,
    AlarmDocument,
    ChartDocument,
    CurvatureDocument,
    EstimatorStatusDocument,
    FlagDocument,
    LastEstimateDocument,
    LocationDocument,
    ModeDocument,
    PipelineStatusDocument,
    SpectrumDocument,
    TrendRow,
    WindowDocument,
    estimate_payloads,
)
from estimator import (
    FilterOutput,
    HealthConfig,
    ImmsFilter,
    ImmsModel,
    Measurements,
    RestCalibration,
    SensorSeries,
    aiding_window,
    assess_health,
    build_events,
    calibrate_at_rest,
    damage_signatures,
    physical_bounds,
    restart_state,
)

from ..analysis import trend_rows
from ..recording import FollowBlock, encode_payloads_json
from ._alarms import alarm_changes, clear_changes
from ._archive import Archive
from ._sinks import SinkGuard
from ._plausibility import SourceClock, ValueLimits, all_plausible, implausible_values
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


class _Merger:
    """Holds samples until every sensor has reported up to a time (or ``lateness`` passed),
    then releases them in time order; a sample older than what was released is late (counted)."""

    def __init__(self, lateness_s: float) -> None:
        self.lateness_ns = int(lateness_s * _NS)
        self.pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.last: dict[str, int] = {}
        self.released_to = -1  # everything < released_to was released
        self.late: Counter = Counter()

    def add(self, block: FollowBlock) -> None:
        t, v = block.log_time_ns, block.values
        if self.released_to >= 0 and len(t) and t[0] < self.released_to:
            keep = t >= self.released_to
            self.late[block.topic] += int(np.count_nonzero(~keep))
            t, v = t[keep], v[keep]
        if not len(t):
            return
        self.pending.setdefault(block.topic, []).append((t, v))
        self.last[block.topic] = max(self.last.get(block.topic, -1), int(t[-1]))

    def release(self, final: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        if not self.last:
            return {}
        newest = max(self.last.values())
        if final:
            cutoff = newest + 1
        else:
            cutoff = max(newest - self.lateness_ns, min(self.last.values()) + 1)
        if cutoff <= self.released_to:
            return {}
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for topic, parts in self.pending.items():
            if not parts:
                continue
            t = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
            v = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
            k = int(np.searchsorted(t, cutoff))
            if k:
                out[topic] = (t[:k], v[:k])
            parts[:] = [(t[k:], v[k:])] if k < len(t) else []
        self.released_to = cutoff
        return out


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


class _Estimator:
    """The IMMS filter over released samples. Times are s after ``epoch_ns``.

    Restart policy: the filter restarts (a new one, from the current measurements, with the rest
    calibration kept) when its health check finds it diverged (``estimator.assess_health`` over
    each chunk: states beyond the rig's physical bounds, growing innovations, aiding refused by
    the gate) and after a gap of ``gap_reset_s`` at the reference IMU D. The chunk in which it
    diverged is not passed on (its estimates are not the structure's); ``restarted_at_s`` tells
    the pipeline to hold the analysis back until the new filter settled. Health is "diverged"
    until the new filter ran, "recovering" until it ran ``confirm_s`` without a sign, then "ok".
    """

    def __init__(self, model: ImmsModel, topics: dict[str, tuple[str, str]], calibration_s: float,
                 calibration: RestCalibration | None, gap_reset_s: float = 5.0,
                 health: HealthConfig | None = None) -> None:
        self.model = model
        self.topics = topics  # topic -> (kind, name)
        self.calibration_s = calibration_s
        self.calibration = calibration
        self.gap_reset_s = gap_reset_s
        self.health_config = health or HealthConfig()
        self.bounds = physical_bounds(model.rig.beam.length, self.health_config)
        self.epoch_ns: int | None = None
        self.filter: ImmsFilter | None = None
        self.buffer: list[dict[str, tuple[np.ndarray, np.ndarray]]] = []
        self.buffer_span: tuple[int, int] | None = None
        self.last_d_ns: int | None = None
        self.dropped = 0  # samples dropped while the reference IMU D was silent
        self.resets = 0
        self.resets_by_reason: Counter = Counter()
        self.state = "calibrating"
        self.new_calibration = False
        self.health = "ok"
        self.health_reason: str | None = None
        self.restarted_at_s: float | None = None  # data time (s after the epoch) of the latest restart
        self._from_measurements = False  # the next filter starts from the measurements (after a divergence)
        self._counters: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.last_estimate: tuple[float, float, float, float] | None = None  # (UNIX s, d, φ, e)
        self._tip = model.tip_row()

    def _measurements(self, data: dict[str, tuple[np.ndarray, np.ndarray]]) -> Measurements:
        imu, tof, strain, bearing = {}, {}, {}, None
        epoch = self.epoch_ns
        for topic, (t, v) in data.items():
            kind, name = self.topics.get(topic, (None, None))
            ts = (t - epoch) * 1e-9
            if kind == "imu":
                imu[name] = SensorSeries(ts, v[:, IMU_PLANAR_COLUMNS])
            elif kind == "tof":
                tof[name] = SensorSeries(ts, v[:, :1])
            elif kind == "strain":
                strain[name] = SensorSeries(ts, v[:, :1])
            elif kind == "bearing":
                bearing = SensorSeries(ts, v[:, :1])
        return Measurements(imu=imu, tof=tof, strain=strain, bearing=bearing)

    def feed(self, data: dict[str, tuple[np.ndarray, np.ndarray]]) -> FilterOutput | None:
        data = {k: v for k, v in data.items() if k in self.topics and len(v[0])}
        if not data:
            return None
        if self.epoch_ns is None:
            first = min(int(v[0][0]) for v in data.values())
            self.epoch_ns = first - first % _NS
        if self.filter is None and self.calibration is None:
            self.buffer.append(data)
            lo = min(int(v[0][0]) for v in data.values())
            hi = max(int(v[0][-1]) for v in data.values())
            span = (lo, hi) if self.buffer_span is None else (min(lo, self.buffer_span[0]), max(hi, self.buffer_span[1]))
            self.buffer_span = span
            if span[1] - span[0] < self.calibration_s * _NS:
                return None
            merged: dict[str, tuple[np.ndarray, np.ndarray]] = {}
            for part in self.buffer:
                for topic, (t, v) in part.items():
                    if topic in merged:
                        merged[topic] = (np.concatenate([merged[topic][0], t]), np.concatenate([merged[topic][1], v]))
                    else:
                        merged[topic] = (t, v)
            self.buffer = []
            self.buffer_span = None
            if _D_TOPIC not in merged:
                self.state = "waiting for /imu/D"
                self.dropped += sum(len(v[0]) for v in merged.values())
                return None
            meas = self._measurements(merged)
            self.calibration = calibrate_at_rest(meas, self.model)
            self.new_calibration = True
            data = merged
        return self._run(data)

    def _restart(self, reason: str, kind: str, at_s: float) -> None:
        self.filter = None
        self._counters = None
        self.resets += 1
        self.resets_by_reason[kind] += 1
        self.restarted_at_s = at_s
        if kind != "gap":
            self.health, self.health_reason = "diverged", reason
            self._from_measurements = True
            if self.resets_by_reason[kind] <= 3 or self.resets % 100 == 0:
                log.warning("estimator diverged at %.1f s (%s): restarting from the current measurements", at_s, reason)

    def _run(self, data: dict[str, tuple[np.ndarray, np.ndarray]]) -> FilterOutput | None:
        d = data.get(_D_TOPIC)
        newest = max(int(v[0][-1]) for v in data.values())
        if d is None:
            if self.last_d_ns is None or newest - self.last_d_ns > self.gap_reset_s * _NS:
                self.dropped += sum(len(v[0]) for v in data.values())
                self.state = "stalled: /imu/D is silent"
                if self.filter is not None:  # restart at the next D sample
                    self._restart("/imu/D is silent", "gap", (newest - self.epoch_ns) / _NS)
                return None
        else:
            first_d = int(d[0][0])
            if self.filter is not None and self.last_d_ns is not None and first_d - self.last_d_ns > self.gap_reset_s * _NS:
                self._restart(f"a gap of {(first_d - self.last_d_ns) / _NS:.1f} s at /imu/D", "gap",
                              (first_d - self.epoch_ns) / _NS)
            self.last_d_ns = int(d[0][-1])
        meas = self._measurements(data)
        if self.filter is None:
            start = min(s.times[0] for s in meas.imu.values()) if meas.imu else min(int(v[0][0]) for v in data.values())
            self.filter = ImmsFilter(self.model, self.calibration, t0=float(start))
            if self._from_measurements:
                self.filter.state.x[:] = restart_state(meas, self.model, self.calibration)
                self._from_measurements = False
        self.state = "running"
        events = build_events(meas, self.model)
        if not len(events):
            return None
        events = events.slice(int(np.searchsorted(events.t, self.filter.t)), len(events))
        out = self.filter.process(events)
        return self._judge(out)

    def _judge(self, out: FilterOutput) -> FilterOutput | None:
        """The health check of one chunk: restart on a sign of divergence, else pass it on."""
        c = self.filter.counters
        now = (c.accepted.copy(), c.rejected.copy(), c.nis_sum.copy())
        window = None if self._counters is None else aiding_window(self.model.aiding_channels, self._counters, now)
        self._counters = now
        if not len(out.t):
            return out
        ix = self.model.state_layout.index
        b = out.x[:, ix.b:ix.b + self.model.gamma]
        phi = out.x[:, ix.phi] if ix.phi >= 0 else np.zeros(len(out.t))
        verdict = assess_health(window, out.x[:, ix.d], phi, b @ self._tip, self.bounds, self.health_config)
        if verdict.diverged:
            self._restart(verdict.reason or verdict.kind or "diverged", verdict.kind or "diverged", float(out.t[-1]))
            return None
        if self.health == "diverged":
            self.health = "recovering"
        elif self.health == "recovering" and self.restarted_at_s is not None \
                and out.t[-1] - self.restarted_at_s >= self.health_config.confirm_s:
            self.health, self.health_reason = "ok", None
        last = out.x[-1]
        self.last_estimate = (self.epoch_ns / _NS + float(out.t[-1]), float(last[ix.d]),
                              float(last[ix.phi]) if ix.phi >= 0 else 0.0, float(b[-1] @ self._tip))
        return out

    def flush(self) -> FilterOutput | None:
        if self.filter is None:
            return None
        return self.filter.flush()

    def health_problems(self) -> list[str]:
        if self.health == "ok":
            return []
        return [f"estimator {self.health}: {self.health_reason} ({self.resets} filter restarts so far)"]

    def diagnostics(self) -> EstimatorStatusDocument:
        diag = self.filter.diagnostics() if self.filter is not None else {}
        last = None
        if self.last_estimate is not None:
            t, d, phi, e = self.last_estimate
            last = LastEstimateDocument(t_s=t, d_m=d, phi_rad=phi, e_m=e)
        return EstimatorStatusDocument(
            state=self.state, dropped_samples=self.dropped, filter_restarts=self.resets,
            filter_restarts_by_reason=dict(self.resets_by_reason), health=self.health, health_reason=self.health_reason,
            last_estimate=last,
            rest_calibration=None if self.calibration is None else self.calibration.as_dict(), **diag)


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
                 raise_windows: int | None = None, clear_windows: int | None = None, archive: Archive | None = None, archive_raw: bool = False,
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
        topics = {s.topic: (s.kind, s.name) for s in self.rig.sensors if s.kind in ("imu", "tof", "strain", "bearing")}
        self.merger = _Merger(lateness_s)
        self.estimator = _Estimator(model, topics, calibration_s, calibration)
        # one alarm path: the engine's (the service's raise/clear counts, when set, are the engine's hysteresis)
        overrides = {k: v for k, v in (("hold_windows", raise_windows), ("clear_windows", clear_windows)) if v is not None}
        analysis = analysis.model_copy(update=overrides) if overrides else analysis
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
        self.clock = clock
        self.limits = limits
        self.rejected: Counter = Counter()  # samples rejected here, by reason
        self.stuck_after_ns = int(stuck_after_s * _NS)
        self._stuck: dict[str, tuple[np.ndarray, int, int]] = {}  # topic -> (last row, run start ns, last ns)
        self._refused_at: dict[str, int] = {}  # topic -> data time when a sample of it was last refused
        self._order: dict[str, int] = {}  # topic -> newest stamp handed on
        self.storage_error: str | None = None  # set while windows wait for the database
        self.storage_errors = 0  # commits that failed (and wait to be retried)
        self.trend_rows_dropped = 0  # rows of waiting windows dropped beyond max_pending_commits (their alarms kept)
        self.chunk_ns = int(chunk_s * _NS)
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
        self._pending_estimator: dict[str, list] = {}
        self._estimate_maps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._warmup_set = False
        # The analysis stage (windows, commits) in a thread of its own (``start_analysis``), so that
        # a window's analysis never holds up the estimator and the batches behind it; None: it
        # runs inline, within ``process`` (replays into a database, tests, benchmarks).
        self._analysis: queue.Queue | None = queue.Queue(maxsize=256) if analysis_thread else None
        self._analysis_thread: threading.Thread | None = None
        self._on_analysis_error = None
        self.analysis_error: str | None = None  # the last chunk's analysis error; None once one analyses fine

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
        for block in self._plausible(batch.blocks):
            if not len(block):
                continue
            self._watch_stuck(block)
            self.samples[block.topic] += len(block)
            last = int(block.log_time_ns[-1])
            self.last_time_ns[block.topic] = max(self.last_time_ns.get(block.topic, last), last)
            self.newest_ns = last if self.newest_ns is None else max(self.newest_ns, last)
            self.merger.add(block)
        for topic in batch.refused or ():
            self._refused_at[topic] = self.newest_ns if self.newest_ns is not None else 0
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

    def _plausible(self, blocks: list[FollowBlock]) -> list[FollowBlock]:
        """The samples of ``blocks`` on the source's clock and within the sensors' limits; the others
        are counted (``rejected``) and their clock jumps noted (``SourceClock``)."""
        if self.clock is None and self.limits is None:  # judged by the source (ingest)
            return blocks
        blocks = [b for b in blocks if len(b)]
        clock = self.clock
        mono = time.monotonic()
        whole = False
        if clock is not None and blocks:
            firsts = {b.topic: int(b.log_time_ns[0]) for b in blocks}
            whole = clock.source_jump(firsts, mono)
            # The first batch has no clock yet: the topics that agree with most others are taken
            # first, so one sensor stamped years off cannot become the source's time.
            median = float(np.median(list(firsts.values())))
            blocks = sorted(blocks, key=lambda b: abs(firsts[b.topic] - median))
        out = []
        for b in blocks:
            keep = None
            if clock is not None:
                ok, codes = clock.judge(b.topic, b.log_time_ns, mono=mono, whole_source=whole)
                if not ok.all():
                    self.rejected.update(clock.count(b.topic, codes, b.log_time_ns, mono=mono))
                    keep = ok
            if self.limits is not None and b.kind in ("imu", "tof", "strain", "bearing", "temperature") \
                    and not all_plausible(b.kind, b.values, self.limits):
                taken = np.ones(len(b), dtype=bool) if keep is None else keep
                nonfinite = ~np.all(np.isfinite(b.values.reshape(len(b), -1)), axis=1)
                bad = implausible_values(b.kind, b.values, self.limits) & ~nonfinite
                if nonfinite.any() or bad.any():
                    self.rejected["nonfinite"] += int(np.count_nonzero(nonfinite & taken))
                    self.rejected["implausible_value"] += int(np.count_nonzero(bad & taken))
                    keep = taken & ~bad & ~nonfinite
            if keep is not None:
                b = FollowBlock(b.topic, b.kind, b.name, b.log_time_ns[keep], b.publish_time_ns[keep], b.values[keep])
            # Each topic in time order whatever the source did (a sensor's clock stepping back):
            # samples stamped at or before the topic's previous one are dropped, counted.
            t = b.log_time_ns
            previous = self._order.get(b.topic)
            if len(t) and (previous is not None and t[0] <= previous or (len(t) > 1 and np.any(t[1:] <= t[:-1]))):
                running = np.maximum.accumulate(np.concatenate([[previous if previous is not None else t[0] - 1], t[:-1]]))
                ok = t > running
                self.rejected["duplicate"] += int(np.count_nonzero(t == running))
                self.rejected["backwards"] += int(np.count_nonzero(t < running))
                b = FollowBlock(b.topic, b.kind, b.name, t[ok], b.publish_time_ns[ok], b.values[ok])
                keep = np.zeros(1, dtype=bool)  # something was refused
            if keep is not None and not keep.all():
                # the sensor is degraded while its samples are being refused (data time of the refusal)
                self._refused_at[b.topic] = self.newest_ns if self.newest_ns is not None else 0
            if len(b):
                self._order[b.topic] = int(b.log_time_ns[-1])
            if clock is not None and len(b):
                clock.take(b.topic, int(b.log_time_ns[-1]), mono)
            out.append(b)
        if whole:
            clock.record(None, "source_jump", sum(len(b) for b in out), clock.offset_s(None, min(firsts.values()), mono))
        return out

    def _watch_stuck(self, block: FollowBlock) -> None:
        """Track how long an IMU's or a strain gauge's readings have not changed at all (their
        noise never lets a working one read the same value twice for long)."""
        if block.kind not in ("imu", "strain"):
            return
        v, t = block.values, block.log_time_ns
        previous = self._stuck.get(block.topic)
        same = np.all(v[1:] == v[:-1], axis=1) if len(v) > 1 else np.zeros(0, dtype=bool)
        changed = np.nonzero(~same)[0]
        if len(changed):
            start = int(t[changed[-1] + 1])
        elif previous is not None and np.array_equal(previous[0], v[0]):
            start = previous[1]
        else:
            start = int(t[0])
        self._stuck[block.topic] = (v[-1].copy(), start, int(t[-1]))

    def stuck_sensors(self) -> list[str]:
        """Topics whose readings have stayed exactly the same for ``stuck_after_s`` and more."""
        return sorted(topic for topic, (_, start, last) in self._stuck.items() if last - start >= self.stuck_after_ns)

    def _advance(self, released: dict[str, tuple[np.ndarray, np.ndarray]], final: bool = False) -> None:
        for topic, (t, v) in released.items():
            self._pending_estimator.setdefault(topic, []).append((t, v))
        if not self._pending_estimator:
            return
        lo = min(p[0][0][0] for p in self._pending_estimator.values() if p)
        hi = max(p[-1][0][-1] for p in self._pending_estimator.values() if p)
        if not final and hi - lo < self.chunk_ns:
            return
        data = {}
        for topic, parts in self._pending_estimator.items():
            if parts:
                data[topic] = (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
        self._pending_estimator = {}
        self.processed_ns = hi
        restarts = self.estimator.resets
        out = self.estimator.feed(data)
        if self.estimator.resets != restarts and self.estimator.restarted_at_s is not None and self.estimator.epoch_ns:
            # Windows that would hold the diverged filter's b (or the new one's first seconds) are not analysed.
            settle = self.estimator.epoch_ns + int(round((self.estimator.restarted_at_s + self.estimator.health_config.settle_s) * _NS))
            self._not_before(settle)
        if final:
            tail = self.estimator.flush()
            if tail is not None and out is not None:
                out = FilterOutput.concatenate([out, tail], self.model.state_size)
            elif tail is not None:
                out = tail
        self._emit(out, data.get(TEMPERATURE_TOPIC))

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
        inactive.update(self.stuck_sensors())
        if newest is not None:
            inactive.update(t for t, at in self._refused_at.items() if newest - at <= self.silent_after_ns)
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
