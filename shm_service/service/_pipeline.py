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
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import orjson

from analytics import AnalysisConfig, Baseline, ModalMonitor, WindowResult, amplitude_spectrum, random_decrement
from contract import (
    BEARING_TOPIC,
    CURVATURE_CHART,
    IMU_PLANAR_COLUMNS,
    TEMPERATURE_TOPIC,
    AlarmDocument,
    ChartDocument,
    CurvatureDocument,
    EstimatorStatusDocument,
    FlagDocument,
    LocationDocument,
    ModeDocument,
    PipelineStatusDocument,
    SpectrumDocument,
    TrendRow,
    WindowDocument,
    chart_name,
    estimate_payloads,
)
from estimator import (
    FilterOutput,
    ImmsFilter,
    ImmsModel,
    Measurements,
    RestCalibration,
    SensorSeries,
    build_events,
    calibrate_at_rest,
    damage_signatures,
)

from ..recording import FollowBlock
from ._alarms import AlarmLogic
from ._archive import Archive
from ._sinks import SinkGuard
from ._storage import Storage, WindowCommit

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


class PipelineSink(Protocol):
    """Where the pipeline pushes live data (the dashboard adapter). ``x`` is a state vector in
    the model's ``StateLayout``. Whatever a sink raises is counted and never stops the pipeline."""

    def estimate(self, t_s: float, x: np.ndarray, truth_deflection: np.ndarray | None) -> None: ...
    def spectra(self, spectrum: SpectrumDocument) -> None: ...
    def window(self, window: WindowDocument) -> None: ...
    def alarm(self, alarm: AlarmDocument) -> None: ...


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
    """The IMMS filter over released samples. Times are s after ``epoch_ns``."""

    def __init__(self, model: ImmsModel, topics: dict[str, tuple[str, str]], calibration_s: float,
                 calibration: RestCalibration | None, gap_reset_s: float = 5.0) -> None:
        self.model = model
        self.topics = topics  # topic -> (kind, name)
        self.calibration_s = calibration_s
        self.calibration = calibration
        self.gap_reset_s = gap_reset_s
        self.epoch_ns: int | None = None
        self.filter: ImmsFilter | None = None
        self.buffer: list[dict[str, tuple[np.ndarray, np.ndarray]]] = []
        self.buffer_span: tuple[int, int] | None = None
        self.last_d_ns: int | None = None
        self.dropped = 0  # samples dropped while the reference IMU D was silent
        self.resets = 0
        self.state = "calibrating"
        self.new_calibration = False

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

    def _run(self, data: dict[str, tuple[np.ndarray, np.ndarray]]) -> FilterOutput | None:
        d = data.get(_D_TOPIC)
        newest = max(int(v[0][-1]) for v in data.values())
        if d is None:
            if self.last_d_ns is None or newest - self.last_d_ns > self.gap_reset_s * _NS:
                self.dropped += sum(len(v[0]) for v in data.values())
                self.state = "stalled: /imu/D is silent"
                if self.filter is not None:
                    self.filter = None  # restart at the next D sample
                    self.resets += 1
                return None
        else:
            first_d = int(d[0][0])
            if self.filter is not None and self.last_d_ns is not None and first_d - self.last_d_ns > self.gap_reset_s * _NS:
                self.filter = None
                self.resets += 1
            self.last_d_ns = int(d[0][-1])
        meas = self._measurements(data)
        if self.filter is None:
            start = min(s.times[0] for s in meas.imu.values()) if meas.imu else min(int(v[0][0]) for v in data.values())
            self.filter = ImmsFilter(self.model, self.calibration, t0=float(start))
        self.state = "running"
        events = build_events(meas, self.model)
        if not len(events):
            return None
        events = events.slice(int(np.searchsorted(events.t, self.filter.t)), len(events))
        return self.filter.process(events)

    def flush(self) -> FilterOutput | None:
        if self.filter is None:
            return None
        return self.filter.flush()

    def diagnostics(self) -> EstimatorStatusDocument:
        diag = self.filter.diagnostics() if self.filter is not None else {}
        return EstimatorStatusDocument(
            state=self.state, dropped_samples=self.dropped, filter_restarts=self.resets,
            rest_calibration=None if self.calibration is None else self.calibration.as_dict(), **diag)


# -- analytics --------------------------------------------------------------------------------


@dataclass
class WindowOutput:
    result: WindowResult
    rows: list[TrendRow]
    spectrum: SpectrumDocument
    start_s: float
    new_baseline: bool


class _Chunks:
    """Time-stamped chunks (t (n,), values (n, k)), trimmed from the front."""

    def __init__(self) -> None:
        self.parts: deque[tuple[np.ndarray, np.ndarray]] = deque()

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        if len(t):
            self.parts.append((t, v))

    def trim(self, before: float) -> None:
        while self.parts and self.parts[0][0][-1] < before:
            self.parts.popleft()

    def span(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray] | None:
        sel = [p for p in self.parts if p[0][-1] >= lo and p[0][0] < hi]
        if not sel:
            return None
        t = np.concatenate([p[0] for p in sel])
        v = np.concatenate([p[1] for p in sel])
        k0, k1 = np.searchsorted(t, [lo, hi])
        return t[k0:k1], v[k0:k1]

    @property
    def newest(self) -> float | None:
        return float(self.parts[-1][0][-1]) if self.parts else None

    def __len__(self) -> int:
        return sum(len(p[0]) for p in self.parts)


class _Analytics:
    """Windows aligned to multiples of the window step in UNIX time, so replaying a period
    gives the same windows (and the unique key of the trend rows holds)."""

    def __init__(self, model: ImmsModel, config: AnalysisConfig, monitor_state: dict | None, last_window_start: float | None,
                 source_id: str, min_coverage: float = 0.8, baseline: dict | None = None) -> None:
        self.model = model
        self.config = config
        self.source_id = source_id
        self.gamma = model.gamma
        self.window_s = config.window_s
        self.step_s = config.window_s * (1 - config.overlap)
        self.n = int(round(self.window_s * FS))
        self.min_coverage = min_coverage
        self.signatures = None
        self.monitor = self._monitor(monitor_state, baseline)
        self.b = _Chunks()
        self.temperature = _Chunks()
        self.bearing = _Chunks()
        self.next_start: float | None = None if last_window_start is None else last_window_start + self.step_s
        self.windows = 0
        self.skipped_incomplete = 0
        self.skipped_warmup = 0
        self.not_before: float | None = None  # windows starting earlier are not analysed (filter converging)
        self.latest_spectrum: SpectrumDocument | None = None
        self.learning_baseline = self.monitor.baseline is None

    def _monitor(self, state: dict | None, baseline: dict | None = None) -> ModalMonitor:
        m = self.model
        if self.signatures is None:
            # FE-predicted damage signatures of the rig: where along the beam a flag points.
            self.signatures = damage_signatures(m.rig, m.stations, gamma=m.gamma)
        if state is not None:
            try:
                monitor = ModalMonitor.from_state_dict(state)
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
            return ModalMonitor(m.units.frequencies_hz, m.units.curvature(m.stations), m.stations, fs=FS, config=self.config,
                                baseline=stored, beam_length=m.rig.beam.length, signatures=self.signatures)
        except ValueError as exc:  # a baseline of another model (modes)
            if stored is None:
                raise
            log.warning("stored baseline does not fit the model (%s); learning a new one", exc)
            return self._monitor(None)

    def reset(self) -> None:
        self.monitor = self._monitor(None)
        self.learning_baseline = True

    def add(self, t: np.ndarray, b: np.ndarray, temperature: tuple[np.ndarray, np.ndarray] | None,
            bearing: tuple[np.ndarray, np.ndarray] | None) -> list[WindowOutput]:
        self.b.add(t, b)
        if temperature is not None:
            self.temperature.add(*temperature)
        if bearing is not None:
            self.bearing.add(*bearing)
        newest = self.b.newest
        if newest is None:
            return []
        out: list[WindowOutput] = []
        if self.next_start is None:
            first = float(self.b.parts[0][0][0])
            self.next_start = math.ceil(first / self.step_s) * self.step_s
        while self.next_start + self.window_s <= newest:
            start = self.next_start
            self.next_start = start + self.step_s
            if self.not_before is not None and start < self.not_before:
                self.skipped_warmup += 1
                continue
            result = self._window(start)
            if result is not None:
                out.append(result)
        keep = self.next_start
        self.b.trim(keep)
        self.temperature.trim(keep - 60.0)
        self.bearing.trim(keep)
        return out

    def _per_unit(self, per_mode: list[float]) -> list[list[float]]:
        """Per-mode frequencies grouped by unit deformation (unit 1, the combimode, holds modes 1 and 2)."""
        gamma = self.monitor.S.shape[1]
        return [[f for f, u in zip(per_mode, self.monitor.units) if u == unit] for unit in range(gamma)]

    def _window(self, start: float) -> WindowOutput | None:
        end = start + self.window_s
        span = self.b.span(start, end)
        if span is None or len(span[0]) < self.min_coverage * self.n:
            self.skipped_incomplete += 1
            return None
        t, b = span
        grid = start + np.arange(self.n) / FS
        B = np.column_stack([np.interp(grid, t, b[:, k]) for k in range(self.gamma)])
        temp = self.temperature.span(start - 30.0, end)
        temperature = float(np.mean(temp[1][:, 0])) if temp is not None and len(temp[0]) else None
        br = self.bearing.span(start - 0.1, end + 0.1)
        bearing = np.interp(grid, br[0], br[1][:, 0]) if br is not None and len(br[0]) > 10 else None
        had_baseline = self.monitor.baseline is not None
        try:
            res = self.monitor.process_window(grid, B, temperature, bearing)
        except ValueError as exc:
            log.warning("window at %.1f s: analytics refused it (%s)", start, exc)
            self.skipped_incomplete += 1
            return None
        self.windows += 1
        self.learning_baseline = self.monitor.baseline is None
        rows = []
        for i, e in enumerate(res.estimates):
            damping = None
            if e.frequency_hz is not None and res.trusted:
                try:
                    damping = random_decrement(B[:, e.unit - 1], FS, e.frequency_hz).damping_ratio
                except (ValueError, FloatingPointError, np.linalg.LinAlgError):
                    damping = None
            score = res.frequency_scores[i] if i < len(res.frequency_scores) else None
            rows.append(TrendRow(
                source=self.source_id, window_start_s=start, window_end_s=end, mode=e.mode, unit=e.unit, kind=res.kind,
                frequency_hz=e.frequency_hz, damping_ratio=damping, amplitude=e.amplitude, confidence=e.confidence,
                temperature_c=res.temperature_c, curvature_index=None if res.curvature is None else res.curvature.total,
                score_sigma=score, level=res.levels.get(chart_name("frequency", e.mode)),
            ))
        spec = amplitude_spectrum(B, FS, pad_factor=1)
        keep = spec.frequencies <= 12.0
        baseline = self.monitor.baseline
        self.latest_spectrum = SpectrumDocument.from_arrays(
            source=self.source_id, window_start_s=start, window_end_s=end, frequencies_hz=spec.frequencies[keep],
            amplitudes=spec.amplitude[keep], tracked_hz=self._per_unit([float(f) for f in self.monitor.ref]),
            baseline_hz=None if baseline is None else self._per_unit([m.f_ref_hz for m in baseline.modes]),
        )
        return WindowOutput(res, rows, self.latest_spectrum, start, baseline is not None and not had_baseline)

    def charts(self, res: WindowResult) -> list[ChartDocument]:
        """The charts the window judged, with the levels they were judged against."""
        out: list[ChartDocument] = []
        warning, alarm = self.config.chart_levels("frequency")
        for i, e in enumerate(res.estimates):
            name = chart_name("frequency", e.mode)
            level = res.levels.get(name)
            if level is not None:
                score = res.frequency_scores[i] if i < len(res.frequency_scores) else None
                out.append(ChartDocument(name=name, kind="frequency", mode=e.mode, unit=e.unit, level=level, score_sigma=score,
                                         warning_sigma=warning, alarm_sigma=alarm))
        level = res.levels.get(CURVATURE_CHART)
        if level is not None:
            warning, alarm = self.config.chart_levels("curvature")
            out.append(ChartDocument(name=CURVATURE_CHART, kind="curvature", level=level, score_sigma=res.curvature_score,
                                     warning_sigma=warning, alarm_sigma=alarm))
        return out


# -- the pipeline -----------------------------------------------------------------------------


class Pipeline:
    """Runs the stages for one source. ``process(batch)`` and ``finish()`` are called from one
    thread; ``status()`` from any."""

    def __init__(self, *, model: ImmsModel, source_id: str, storage: Storage, analysis: AnalysisConfig,
                 calibration_s: float, chunk_s: float, lateness_s: float, silent_after_s: float,
                 raise_windows: int, clear_windows: int, archive: Archive | None = None, archive_raw: bool = False,
                 archive_estimates: bool = True, estimate_decimation: int = 1, sink: PipelineSink | None = None,
                 sink_guard: SinkGuard | None = None, sink_estimate_hz: float = 15.0, warmup_s: float = 120.0) -> None:
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
        # Without a monitor to resume, the source's active baseline (shm baseline learn) arms a new one.
        baseline = None if blob.get("monitor") else storage.active_baseline(source_id)
        self.analytics = _Analytics(model, analysis, blob.get("monitor"), stored.get("last_window_start_s"), source_id,
                                    baseline=baseline)
        self.alarms = AlarmLogic(raise_windows=raise_windows, clear_windows=clear_windows, state=blob.get("alarms"))
        self.chunk_ns = int(chunk_s * _NS)
        self.silent_after_ns = int(silent_after_s * _NS)
        self.archive = archive
        self.archive_raw = archive_raw and archive is not None
        self.archive_estimates = archive_estimates and archive is not None
        self.decimation = estimate_decimation
        self.sink = sink
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

    # -- control ----------------------------------------------------------------------------

    def request_baseline(self) -> None:
        """Learn a new baseline from the next windows (called from the API thread)."""
        self._reset_requested = True

    # -- data path --------------------------------------------------------------------------

    def process(self, batch: Batch) -> None:
        began = time.monotonic()
        for block in batch.blocks:
            if not len(block):
                continue
            self.samples[block.topic] += len(block)
            last = int(block.log_time_ns[-1])
            self.last_time_ns[block.topic] = max(self.last_time_ns.get(block.topic, last), last)
            self.newest_ns = last if self.newest_ns is None else max(self.newest_ns, last)
            self.merger.add(block)
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
        out = self.estimator.feed(data)
        if final:
            tail = self.estimator.flush()
            if tail is not None and out is not None:
                out = FilterOutput.concatenate([out, tail], self.model.state_size)
            elif tail is not None:
                out = tail
        temp = data.get(TEMPERATURE_TOPIC)
        bearing = data.get(BEARING_TOPIC)
        self._emit(out, temp, bearing)

    def _emit(self, out: FilterOutput | None, temp, bearing) -> None:
        epoch = self.estimator.epoch_ns
        if epoch is None:
            return
        epoch_s = epoch / _NS
        temperature = None if temp is None else (epoch_s + (temp[0] - epoch) * 1e-9, temp[1])
        bearing_abs = None if bearing is None else (epoch_s + (bearing[0] - epoch) * 1e-9, bearing[1])
        if out is None or not len(out.t):
            if temperature is not None:
                self.analytics.temperature.add(*temperature)
            return
        self.estimates += len(out.t)
        if self.analytics.not_before is None and self.estimator.calibration is not None:
            self.analytics.not_before = epoch_s + float(self.estimator.calibration.rest_end) + self.warmup_s
        t_abs = epoch_s + out.t
        b = self.model.state_layout.b_of(out.x)
        self.latest_x = out.x[-1]
        if self.archive_estimates:
            self._archive_estimates(out)
        self._push_estimates(t_abs, out)
        if self._reset_requested:
            self._reset_requested = False
            self.analytics.reset()
            active = [a for a in self.storage.alarms(state="active") if a.source == self.source_id]
            changes = self.alarms.clear_all(active, float(t_abs[0]))
            if changes:
                self._commit_alarm_only(changes, float(t_abs[0]))
        for window in self.analytics.add(t_abs, b, temperature, bearing_abs):
            self._commit(window)

    def _archive_estimates(self, out: FilterOutput) -> None:
        k = self.decimation
        t, x, P = out.t[::k], out.x[::k], out.P_diag[::k]
        if not len(t):
            return
        m = self.model
        layout = m.state_layout
        b = layout.b_of(x)
        rows = estimate_payloads(layout, x, P, b @ m.tip_row(), b @ m.units.shape(m.stations).T,
                                 b @ m.units.curvature(m.stations).T)
        stamps = (self.estimator.epoch_ns + np.round(t * 1e9).astype(np.int64)).tolist()
        dumps = orjson.dumps
        self.archive.write_estimates(stamps, [dumps(row) for row in rows])

    def _push_estimates(self, t_abs: np.ndarray, out: FilterOutput) -> None:
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

    def _commit_alarm_only(self, changes, at_s: float) -> None:
        commit = WindowCommit(self.source_id, self.analytics.next_start - self.analytics.step_s if self.analytics.next_start else at_s,
                              at_s, [], {"monitor": None, "alarms": self.alarms.state_dict()}, None, changes)
        self.storage.commit_window(commit)

    def _commit(self, window: WindowOutput) -> None:
        res = window.result
        charts = self.analytics.charts(res)
        changes = self.alarms.update(charts, res.end_s)
        baseline = self.analytics.monitor.baseline.to_dict() if window.new_baseline else None
        calibration = None
        if self.estimator.new_calibration and self.estimator.calibration is not None:
            calibration = calibration_to_dict(self.estimator.calibration)
            self.estimator.new_calibration = False
        document = window_document(self.source_id, res, window.rows, charts)
        commit = WindowCommit(
            source=self.source_id, window_start_s=window.start_s, data_time_s=res.end_s, rows=window.rows,
            monitor_state={"monitor": self.analytics.monitor.state_dict(), "alarms": self.alarms.state_dict()},
            calibration=calibration, alarm_changes=changes, baseline=baseline,
        )
        self.storage.commit_window(commit)
        self.windows_committed += 1
        self.last_window = document
        if self.sink is not None:
            guard = self.sink_guard
            guard.call("window", self.sink.window, self.last_window)
            guard.call("spectra", self.sink.spectra, window.spectrum)
            if changes:
                changed = {c.chart for c in changes}
                for alarm in self.storage.alarms(limit=len(changes) + 5):
                    if alarm.source == self.source_id and alarm.chart in changed:
                        guard.call("alarm", self.sink.alarm, alarm)

    def finish(self) -> None:
        """The source ended: release everything, flush the filter, close the recording."""
        self._advance(self.merger.release(final=True), final=True)
        if self.archive is not None:
            self.archive.close()

    # -- status -----------------------------------------------------------------------------

    def sensor_states(self) -> dict[str, str]:
        states: dict[str, str] = {}
        newest = self.newest_ns
        diag = self.estimator.filter.diagnostics() if self.estimator.filter is not None else {}
        inactive = {d["sensor"] for d in diag.get("degraded_imus", []) if not d.get("active", True)}
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
            active_alarms=self.alarms.active(),
        )


def window_document(source: str, res: WindowResult, rows: list[TrendRow] | tuple = (),
                    charts: list[ChartDocument] | tuple = ()) -> WindowDocument:
    """The window as the dashboard shows it: the analytics' result with each mode's damping
    (computed per window by the pipeline), its chart, and the curvature change along η."""
    damping = {row.mode: row.damping_ratio for row in rows}
    by_mode = {c.mode: c for c in charts if c.kind == "frequency"}
    modes = []
    for i, e in enumerate(res.estimates):
        chart = by_mode.get(e.mode)
        modes.append(ModeDocument(
            mode=e.mode, unit=e.unit, frequency_hz=e.frequency_hz, amplitude=e.amplitude, confidence=round(e.confidence, 4),
            damping_ratio=damping.get(e.mode), score_sigma=res.frequency_scores[i] if i < len(res.frequency_scores) else None,
            level=None if chart is None else chart.level,
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
