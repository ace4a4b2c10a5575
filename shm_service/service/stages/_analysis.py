"""The windowing and analysis stage of a structure's pipeline: the one engine over the estimator's
b(t) and d(t), and what the service makes of its windows (trend rows, spectra, alarm changes).
Its settings model is ``analytics.AnalysisConfig`` (the engine's, ``shm analyze`` reads the same)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import cast

import numpy as np

from analytics import AnalysisConfig, Baseline, EngineWindow, LoadsMonitor, ModalMonitor, MonitoringEngine, WindowResult, usability_document
from contract import LoadsWindowDocument, SpectrumDocument, TrendRow
from estimator import DamageSignatures, ImmsModel, damage_signatures

from ...processing.analysis import trend_rows
from ..alarms._changes import alarm_changes
from ..storage._storage import AlarmChange

__all__ = ["AnalysisStage", "LazySpectrum", "WindowOutput"]

log = logging.getLogger("shm.serve.pipeline")

FS = 200.0
_NS = 1_000_000_000


class LazySpectrum:
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
    spectrum: LazySpectrum
    start_s: float
    new_baseline: bool
    alarm_changes: list[AlarmChange]
    loads: LoadsWindowDocument | None = None  # the hot spots' loads of the window


def _monitor_stations(model) -> np.ndarray:
    """Where curvature is monitored: the rig's truth stations, else (``truth_stations: []``) 8 evenly
    spaced stations (damage_signatures' default)."""
    if len(model.stations):
        return np.asarray(model.stations, dtype=float)
    return np.linspace(0.0, model.rig.beam.length, 9)[1:]


class AnalysisStage:
    """The windowing and analysis stage: the one engine (``analytics.MonitoringEngine``, the same ``shm analyze`` runs) over the
    estimator's b(t) and support displacement d(t), and what the service makes of its windows:
    trend rows, spectra, alarm changes. Windows are aligned to multiples of the step in UNIX
    time, so replaying a period gives the same windows (and the unique key of the trend rows holds)."""

    def __init__(self, model: ImmsModel, config: AnalysisConfig, monitor_state: dict | None, last_window_start: float | None,
                 source_id: str, min_coverage: float = 0.8, baseline: dict | None = None, loads_state: dict | None = None) -> None:
        self.model = model
        self.config = config
        self.source_id = source_id
        self.gamma = model.gamma
        self.window_s = config.window_s
        self.step_s = config.window_s * (1 - config.overlap)
        self.min_coverage = min_coverage
        self.signatures: DamageSignatures | None = None
        self.monitor = self._monitor(monitor_state, baseline)
        # the hot spots' loads in the same engine; its state (the rainflow residue, the
        # damage) is committed with every window, so a restart continues the count exactly
        self.loads = self._loads(loads_state) if model.rig.hot_spots else None
        self.engine: MonitoringEngine | None = None
        self._next_start_ns = None if last_window_start is None else int(round(last_window_start * _NS)) + int(round(self.step_s * _NS))
        self.not_before_ns: int | None = None  # windows starting earlier are not analysed (filter converging)
        self._latest_spectrum: LazySpectrum | None = None
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

    def _loads(self, state: dict | None) -> LoadsMonitor:
        from ...processing.estimation import outside_shapes

        units = self.model.units
        beyond = outside_shapes(self.model.rig, units)  # the modes above the basis: the calibrated band
        try:
            return LoadsMonitor.from_rig(self.model.rig, units.curvature, state=state, gauges_in_sample=self._aiding_gauges(),
                                         outside_at=beyond)
        except ValueError as exc:
            if state is None:
                raise
            # never silently: the consumed life starts again from zero
            log.error("%s: stored loads state unusable (%s); the hot spots' damage is counted from zero", self.source_id, exc)
            return LoadsMonitor.from_rig(self.model.rig, units.curvature, gauges_in_sample=self._aiding_gauges(), outside_at=beyond)

    def _aiding_gauges(self) -> tuple[str, ...]:
        """The strain gauges the estimator uses (their discrepancy is in-sample: the band doubles it)."""
        return tuple(getattr(getattr(self.model, "selection", None), "gauges", ()) or ())

    def state(self) -> dict:
        """The engine state a window's commit persists: the monitor's and the loads' (the residue)."""
        out: dict = {"monitor": self.monitor.state_dict()}
        if self.loads is not None:
            out["loads"] = self.loads.state_dict()
        return out

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

    def usability(self) -> dict:
        """The engine's windows: usable, rejected by reason, and why none is usable (``analytics.usability_document``)."""
        return usability_document(0, {}) if self.engine is None else self.engine.usability()

    @property
    def next_start(self) -> float | None:
        ns = self._next_start_ns if self.engine is None else self.engine.next_start_ns
        return None if ns is None else ns / _NS

    def active(self) -> dict[str, str]:
        raised = self.monitor.alarms.raised()
        if self.loads is not None:
            raised.update(self.loads.alarms.raised())
        return raised

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
            temperature: tuple[np.ndarray, np.ndarray] | None, gauges: dict | None = None) -> list[WindowOutput]:
        """b (n, Γ) and the support displacement d (n,) at t (n,) s after ``epoch_ns``; temperature
        (times s after epoch_ns, °C) or None."""
        if self.engine is None:
            if temperature is not None:
                self._temperature.append(temperature)
            if not len(t):
                return []
            self.engine = MonitoringEngine(self.monitor, origin_ns=epoch_ns, time_zero_ns=0, not_before_ns=self.not_before_ns,
                                           next_start_ns=self._next_start_ns, min_coverage=self.min_coverage, loads=self.loads)
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
        for w in self.engine.add(t, b, support=d, temperature=temperature_now, gauges=gauges):
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
        assert spec is not None, "an engine window has its spectrum"
        pad = spec.pad_factor
        f, amp = spec.frequencies[::pad], spec.amplitude[::pad]  # the unpadded DFT bins of the window
        keep = f <= 12.0
        baseline = self.monitor.baseline
        self._latest_spectrum = spectrum = LazySpectrum(
            source=self.source_id, window_start_s=start, window_end_s=end, frequencies_hz=f[keep],
            amplitudes=amp[keep], tracked_hz=self._per_unit([float(x) for x in self.monitor.ref]),
            baseline_hz=None if baseline is None else self._per_unit([m.f_ref_hz for m in baseline.modes]),
        )
        return WindowOutput(res, rows, spectrum, start, baseline is not None and not had_baseline,
                            alarm_changes([*res.alarm_events, *w.loads_events]),
                            # the engine's loads are the hot spots' document (analytics types them as object)
                            cast("LoadsWindowDocument | None", w.loads))
