"""The streaming estimator: the IMMS filter over samples as they arrive, with the policy every
entry point shares — rest calibration on the first ``calibration_s`` of data, divergence
detection, a reset after a gap at the reference IMU D, and a restart from the measurements.

``estimate()``, ``shm estimate``, ``shm analyze`` and ``shm serve`` all run this class, so the same
raw recording gives the same b(t) through each, faults included: the filter runs over chunks on a
fixed grid of data time (``chunk_s`` from the epoch), whatever pieces the samples arrive in, and
the health check judges each chunk.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from contract import IMU_BIAXIAL_COLUMNS, IMU_PLANAR_COLUMNS, EstimatorStatusDocument, LastEstimateDocument

from ._filter import (
    EstimateResult,
    FilterConfig,
    FilterOutput,
    ImmsFilter,
    ImmsModel,
    Measurements,
    RestCalibration,
    SensorSeries,
    build_events,
    calibrate_at_rest,
    support_position_problem,
)
from ._health import (
    HealthConfig,
    aiding_window,
    assess_health,
    gauge_disagreement,
    gauges_beyond_basis,
    physical_bounds,
    restart_state,
)

__all__ = ["REFERENCE_IMU_TOPIC", "StreamingEstimator", "StreamingSettings", "TopicSamples", "estimate", "estimate_stream",
           "rig_topics"]

log = logging.getLogger("estimator.streaming")

_NS = 1_000_000_000
#: the topic of the reference IMU D (at the bearing): the filter's clock
REFERENCE_IMU_TOPIC = "/imu/D"
#: samples per topic: (log times in ns, int64 of shape (n,); values of shape (n, columns))
TopicSamples = Mapping[str, tuple[np.ndarray, np.ndarray]]


class StreamingSettings(BaseModel):
    """How the streaming estimator runs: calibration, chunking and its restart policy."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    calibration_s: float = Field(60.0, gt=0, le=3600, description="data gathered for the rest calibration before filtering, s")
    chunk_s: float = Field(2.0, gt=0, le=60, description="data per filter call and health check (a grid from the epoch), s")
    gap_reset_s: float = Field(5.0, gt=0, description="a silence of the reference IMU D this long restarts the filter, s")
    health: HealthConfig = Field(default_factory=HealthConfig, description="when the filter counts as diverged")
    filter: FilterConfig = Field(default_factory=FilterConfig, description="the EKF's tuning")


def rig_topics(model: ImmsModel) -> dict[str, tuple[str, str]]:
    """The topics the estimator reads from the rig: ``{topic: (kind, name)}``."""
    return {s.topic: (s.kind, s.name) for s in model.rig.sensors if s.kind in ("imu", "tof", "strain", "bearing")}


def _concatenate(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    if len(parts) == 1:
        return parts[0]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


class StreamingEstimator:
    """The IMMS filter over samples fed in time order. Times of its outputs are s after ``epoch_ns``
    (the first sample's whole UNIX second).

    ``feed(samples)`` takes samples of the rig's topics; after a feed, every sample older than the
    newest one fed must have been fed (a merged stream, as the service's merge releases it, or a
    whole recording). It returns the estimates of the chunks that became complete. ``finish()``
    runs the rest.

    Restart policy: the filter restarts (a new one, from the current measurements, with the rest
    calibration kept) when its health check finds it diverged (``assess_health`` over each chunk:
    states beyond the rig's physical bounds, growing innovations, aiding refused by the gate) and
    after a silence of ``gap_reset_s`` at the reference IMU D. The chunk in which it diverged is
    not passed on (its estimates are not the structure's); ``restarted_at_s`` says when the latest
    restart was. Health is "diverged" until the new filter ran, "recovering" until it ran
    ``health.confirm_s`` without a sign, then "ok".

    Parameters
    ----------
    model : ImmsModel
    settings : StreamingSettings
    calibration : RestCalibration, optional
        A calibration to keep (a resumed service's); None: learnt from the first ``calibration_s``.
    topics : mapping, optional
        ``{topic: (kind, name)}`` (default: the rig's, ``rig_topics(model)``).

    Examples
    --------
    >>> est = StreamingEstimator(model, StreamingSettings(chunk_s=1.0))  # doctest: +SKIP
    >>> out = est.feed({"/imu/D": (t_ns, values)})                       # doctest: +SKIP
    """

    def __init__(self, model: ImmsModel, settings: StreamingSettings | None = None, calibration: RestCalibration | None = None,
                 topics: Mapping[str, tuple[str, str]] | None = None, epoch_ns: int | None = None) -> None:
        self.model = model
        self.settings = settings or StreamingSettings()
        self.topics = dict(rig_topics(model) if topics is None else topics)
        self.calibration = calibration
        self.health_config = self.settings.health
        self.bounds = physical_bounds(model.rig.beam.length, self.health_config)
        self._chunk_ns = int(round(self.settings.chunk_s * _NS))
        self._gap_ns = int(round(self.settings.gap_reset_s * _NS))
        self.epoch_ns: int | None = epoch_ns
        self.filter: ImmsFilter | None = None
        self._rejected_before = 0  # aiding updates refused by the filters before the latest restart
        self._pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self._first_ns: int | None = None  # the oldest sample not yet handed on (calibration's start)
        self._newest_ns: int | None = None
        self.last_d_ns: int | None = None
        self.dropped = 0  # samples dropped while the reference IMU D was silent
        self.resets = 0
        self.resets_by_reason: Counter[str] = Counter()
        self.state = "calibrating"
        self.new_calibration = False
        self.health = "ok"
        self.health_reason: str | None = None
        self.restarted_at_s: float | None = None  # data time (s after the epoch) of the latest restart
        self._from_measurements = False  # the next filter starts from the measurements (after a divergence)
        self._counters: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.last_estimate: tuple[float, float, float, float] | None = None  # (UNIX s, d, φ, e)
        self._tip = model.tip_row()
        # each gauge's variance as the filters see it, once raised (the strain outside the unit
        # deformations); kept across restarts, the filters' own from the calibration until then
        self._gauge_var: np.ndarray | None = None
        self.gauge_error_raised = 0
        self.gauge_note: str | None = None

    # -- feeding ---------------------------------------------------------------------------------

    def feed(self, samples: TopicSamples) -> FilterOutput | None:
        """Take ``samples`` (the rig's topics; others are ignored) and return the estimates of the
        chunks they completed (None: none)."""
        data = {k: v for k, v in samples.items() if k in self.topics and len(v[0])}
        if not data:
            return None
        first = min(int(v[0][0]) for v in data.values())
        if self.epoch_ns is None:
            self.epoch_ns = first - first % _NS
        if self._first_ns is None:
            self._first_ns = first
        for topic, (t, v) in data.items():
            self._pending.setdefault(topic, []).append((np.asarray(t, dtype=np.int64), np.asarray(v)))
        newest = max(int(v[0][-1]) for v in data.values())
        self._newest_ns = newest if self._newest_ns is None else max(self._newest_ns, newest)
        # every sample before the newest one has been fed: what lies before newest + 1 is complete
        return self._advance(self._newest_ns + 1)

    def finish(self) -> FilterOutput | None:
        """Run what is left (the last, partial chunk) and the filter's tail."""
        outputs = []
        if self._newest_ns is not None:
            out = self._advance(self._newest_ns + 1, final=True)
            if out is not None:
                outputs.append(out)
        if self.filter is not None:
            outputs.append(self.filter.flush())
        outputs = [o for o in outputs if o is not None]
        if not outputs:
            return None
        return outputs[0] if len(outputs) == 1 else FilterOutput.concatenate(outputs, self.model.state_size)

    def _take(self, before_ns: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The pending samples older than ``before_ns`` (removed from the pending ones)."""
        out = {}
        for topic, parts in self._pending.items():
            if not parts:
                continue
            t, v = _concatenate(parts)
            k = int(np.searchsorted(t, before_ns))
            if k:
                out[topic] = (t[:k], v[:k])
            parts[:] = [(t[k:], v[k:])] if k < len(t) else []
        return out

    def _oldest_pending(self) -> int | None:
        firsts = [int(parts[0][0][0]) for parts in self._pending.values() if parts and len(parts[0][0])]
        return min(firsts) if firsts else None

    def _advance(self, complete_to: int, final: bool = False) -> FilterOutput | None:
        if self.filter is None and self.calibration is None and not self._calibrate(complete_to, final):
            return None
        assert self.epoch_ns is not None
        outputs = []
        while True:
            oldest = self._oldest_pending()
            if oldest is None:
                break
            end = self.epoch_ns + ((oldest - self.epoch_ns) // self._chunk_ns + 1) * self._chunk_ns
            if end > complete_to and not final:
                break
            out = self._run(self._take(end if not final or end <= complete_to else complete_to))
            if out is not None and len(out.t):
                outputs.append(out)
        if not outputs:
            return None
        return outputs[0] if len(outputs) == 1 else FilterOutput.concatenate(outputs, self.model.state_size)

    def _calibrate(self, complete_to: int, final: bool) -> bool:
        """Learn the rest calibration once ``calibration_s`` of data is in (all of it at ``final``)."""
        assert self._first_ns is not None
        end = self._first_ns + int(round(self.settings.calibration_s * _NS))
        if complete_to < end and not final:
            return False
        part = {topic: _concatenate(parts) for topic, parts in self._pending.items() if parts}
        part = {k: (t[t < end], v[t < end]) for k, (t, v) in part.items()}
        part = {k: tv for k, tv in part.items() if len(tv[0])}
        if REFERENCE_IMU_TOPIC not in part:
            self.state = "waiting for /imu/D"
            self.dropped += sum(len(tv[0]) for tv in part.values())
            self._take(end)
            self._first_ns = self._oldest_pending()
            return False
        self.calibration = calibrate_at_rest(self._measurements(part), self.model, self.settings.filter)
        self.new_calibration = True
        return True

    # -- the filter over one chunk ------------------------------------------------------------------

    def _measurements(self, data: TopicSamples) -> Measurements:
        imu: dict[str, SensorSeries] = {}
        tof: dict[str, SensorSeries] = {}
        strain: dict[str, SensorSeries] = {}
        bearing: SensorSeries | None = None
        epoch = self.epoch_ns
        assert epoch is not None
        columns = IMU_BIAXIAL_COLUMNS if self.model.biaxial else IMU_PLANAR_COLUMNS
        for topic, (t, v) in data.items():
            kind, name = self.topics.get(topic, ("", ""))
            ts = (t - epoch) * 1e-9
            if kind == "imu":
                imu[name] = SensorSeries(ts, v[:, columns])
            elif kind == "tof":
                tof[name] = SensorSeries(ts, v[:, :1])
            elif kind == "strain":
                strain[name] = SensorSeries(ts, v[:, :1])
            elif kind == "bearing":
                bearing = SensorSeries(ts, v[:, :1])
            else:
                raise ValueError(f"topic {topic!r} of kind {kind!r}: the estimator reads imu, tof, strain and bearing")
        return Measurements(imu=imu, tof=tof, strain=strain, bearing=bearing)

    def _restart(self, reason: str, kind: str, at_s: float) -> None:
        if self.filter is not None:
            self._rejected_before += int(self.filter.rejected.sum())
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
        if not data:
            return None
        assert self.epoch_ns is not None and self.calibration is not None
        d = data.get(REFERENCE_IMU_TOPIC)
        newest = max(int(v[0][-1]) for v in data.values())
        if d is None:
            if self.last_d_ns is None or newest - self.last_d_ns > self._gap_ns:
                self.dropped += sum(len(v[0]) for v in data.values())
                self.state = "stalled: /imu/D is silent"
                if self.filter is not None:  # restart at the next D sample
                    self._restart("/imu/D is silent", "gap", (newest - self.epoch_ns) / _NS)
                return None
        else:
            first_d = int(d[0][0])
            if self.filter is not None and self.last_d_ns is not None and first_d - self.last_d_ns > self._gap_ns:
                self._restart(f"a gap of {(first_d - self.last_d_ns) / _NS:.1f} s at /imu/D", "gap",
                              (first_d - self.epoch_ns) / _NS)
            self.last_d_ns = int(d[0][-1])
        meas = self._measurements(data)
        if self.filter is None:
            start = min(s.times[0] for s in meas.imu.values()) if meas.imu else min(int(v[0][0]) for v in data.values())
            self.filter = ImmsFilter(self.model, self.calibration, self.settings.filter, t0=float(start))
            if self._gauge_var is not None:
                self.filter.arrays.strain_var[:] = self._gauge_var
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

    def _raise_gauge_error(self, window: Any, gauges: tuple[str, ...]) -> str:
        """Raise the variance of each of ``gauges`` in the running filter (and the ones after it) by
        what it saw beyond the filter's expectation; the words that say so (empty when none could
        be raised: none disagreed, or each is at ``gauge_error_max`` already).

        A gauge that reads strain outside the unit deformations disagrees with any state; a restart
        would disagree the same way, so the filter goes on with that gauge trusted less. Its
        variance grows by its disagreement k (times the variance expected; at least
        ``gauge_error_growth``² times), at once: raised by too little, the gate refuses it and the
        estimate drifts without a sign to restart on."""
        if not gauges or self.filter is None:
            return ""
        hc = self.health_config
        names = [f"/strain/{g}" for g in self.model.selection.gauges]
        var = self.filter.arrays.strain_var
        cap = hc.gauge_error_max**2
        changed = []
        for channel in gauges:
            j = names.index(channel)
            k = gauge_disagreement(window, (channel,), self.settings.filter.gate)
            new = min(cap, var[j] * max(k, hc.gauge_error_growth**2))
            if new > var[j]:
                var[j] = new
                changed.append(f"{channel.rsplit('/', 1)[-1]} to {math.sqrt(new) * 1e6:.3g} µε")
        if not changed:
            return ""
        self._gauge_var = var.copy()
        self.gauge_error_raised += 1
        words = (f"strain outside the {self.model.gamma} unit deformations at the gauges: their noise raised "
                 f"({', '.join(changed)}); more unit deformations (--modes) or more IMUs would carry that motion")
        if self.gauge_error_raised <= 3 or self.gauge_error_raised % 100 == 0:
            log.warning("estimator: %s", words)
        self.gauge_note = words
        return words

    def _judge(self, out: FilterOutput) -> FilterOutput | None:
        """The health check of one chunk: restart on a sign of divergence, else pass it on."""
        assert self.filter is not None and self.epoch_ns is not None
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
        raised = self._raise_gauge_error(window, gauges_beyond_basis(window, self.health_config)) if window is not None else ""
        if verdict.diverged and not (raised and verdict.kind in ("nis", "rejections")):
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

    # -- what it reports ------------------------------------------------------------------------------

    @property
    def buffer_span(self) -> tuple[int, int] | None:
        """(oldest, newest) stamp, ns, of the data gathered for the rest calibration so far (None:
        nothing gathered, or calibrated)."""
        if self.calibration is not None or self._first_ns is None or self._newest_ns is None:
            return None
        return (self._first_ns, self._newest_ns)

    def result_diagnostics(self) -> dict[str, Any]:
        """The filter's diagnostics (``ImmsFilter.diagnostics``) with the restarts: ``rejected``
        counts the refused updates of every filter of the run."""
        diag: dict[str, Any] = self.filter.diagnostics() if self.filter is not None else {"aiding": {}, "rejected": 0,
                                                                                            "degraded_imus": []}
        diag["rejected"] = int(diag["rejected"]) + self._rejected_before
        diag.update(filter_restarts=self.resets, filter_restarts_by_reason=dict(self.resets_by_reason),
                    dropped_samples=self.dropped, gauge_error_raised=self.gauge_error_raised,
                    gauge_std={g: math.sqrt(float(v)) for g, v in zip(self.model.selection.gauges, self._gauge_var)}
                    if self._gauge_var is not None else None, gauge_note=self.gauge_note)
        return diag

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
            last_estimate=last, gauge_note=self.gauge_note,
            gauge_std=None if self._gauge_var is None else {g: math.sqrt(float(v)) for g, v in zip(self.model.selection.gauges,
                                                                                                    self._gauge_var)},
            rest_calibration=None if self.calibration is None else self.calibration.as_dict(), **diag)


# -- whole recordings ------------------------------------------------------------------------------


def estimate_stream(samples: TopicSamples, model: ImmsModel, settings: StreamingSettings | None = None, *,
                    epoch_ns: int | None = None, topics: Mapping[str, tuple[str, str]] | None = None) -> EstimateResult:
    """Run the streaming estimator over all of ``samples`` (a whole recording's topics).

    Parameters
    ----------
    samples : mapping
        ``{topic: (log times in ns, values)}`` of the rig's sensors, each topic in time order.
    model : ImmsModel
    settings : StreamingSettings, optional
    epoch_ns : int, optional
        Time zero of the result's ``t`` (default: the first sample's whole second, as the service).
    topics : mapping, optional
        ``{topic: (kind, name)}`` (default: the rig's).

    Returns
    -------
    EstimateResult
        ``t`` in s after ``epoch_ns``; ``diagnostics`` with the restarts and dropped samples.

    Raises
    ------
    ValueError
        No samples of the reference IMU D within the calibration (nothing could be estimated).
    """
    import time

    est = StreamingEstimator(model, settings, topics=topics, epoch_ns=epoch_ns)
    started = time.perf_counter()
    outputs = [est.feed(samples), est.finish()]
    elapsed = time.perf_counter() - started
    if est.calibration is None:
        raise ValueError(f"no samples of the reference IMU D ({REFERENCE_IMU_TOPIC}) to calibrate on: nothing estimated")
    parts = [o for o in outputs if o is not None]
    out = FilterOutput.concatenate(parts, model.state_size) if parts else FilterOutput.concatenate([], model.state_size)
    diagnostics = est.result_diagnostics()
    bearing_samples = [v for topic, v in samples.items() if (topics or rig_topics(model)).get(topic, ("", ""))[0] == "bearing"]
    problem = support_position_problem(
        None if not bearing_samples else SensorSeries(bearing_samples[0][0] * 1e-9, bearing_samples[0][1][:, :1]), model)
    if problem:
        diagnostics["problems"] = [problem]
    return EstimateResult(model, est.calibration, out.t, out.x, out.P_diag, out.var_e, diagnostics, elapsed)


def estimate(meas: Measurements, model: ImmsModel, config: FilterConfig = FilterConfig(), *,
             settings: StreamingSettings | None = None) -> EstimateResult:
    """Run the streaming estimator (rest calibration, the filter, its restart policy) over ``meas``.

    The same policy as ``shm serve``: the rest calibration on the first ``calibration_s``, the
    filter over ``chunk_s`` chunks, each judged; a restart on divergence or a gap at IMU D.

    Parameters
    ----------
    meas : Measurements
        Planar measurements, times in s (the result's ``t`` are on the same axis).
    model : ImmsModel
    config : FilterConfig
        The EKF's tuning (``settings.filter`` when ``settings`` is given).
    settings : StreamingSettings, optional

    Raises
    ------
    ValueError
        ``meas`` has no IMU 'D', or a sensor that is not in the rig.
    """
    if "D" not in meas.imu:
        raise ValueError("measurements have no IMU 'D' (the IMU at the bearing)")
    settings = settings or StreamingSettings(filter=config)
    by_name: dict[tuple[str, str], str] = {(s.kind, s.name): s.topic for s in model.rig.sensors}
    imu_columns = list(IMU_BIAXIAL_COLUMNS if model.biaxial else IMU_PLANAR_COLUMNS)
    width = max(IMU_BIAXIAL_COLUMNS) + 1
    samples: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    topics: dict[str, tuple[str, str]] = {}

    def put(kind: str, name: str, series: SensorSeries, columns: list[int] | None) -> None:
        topic = by_name.get((kind, name), f"/{kind}/{name}")
        values = np.asarray(series.values, dtype=float)
        if columns is not None:  # the model's columns back where the raw IMU payload has them
            raw = np.zeros((len(values), width))
            raw[:, columns] = values
            values = raw
        samples[topic] = (np.round(np.asarray(series.times, dtype=float) * 1e9).astype(np.int64), values)
        topics[topic] = (kind, name)

    for name, s in meas.imu.items():
        put("imu", name, s, imu_columns[:s.values.shape[1]])
    for name, s in meas.tof.items():
        put("tof", name, s, None)
    for name, s in meas.strain.items():
        put("strain", name, s, None)
    if meas.bearing is not None:
        put("bearing", "bearing", meas.bearing, None)
    return estimate_stream(samples, model, settings, epoch_ns=0, topics=topics)
