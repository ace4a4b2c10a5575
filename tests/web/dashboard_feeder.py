"""A stand-in service for the dashboard: an in-memory ``contract.ServicePort`` of one structure
that serves the virtual rig's truth as live "estimates" (10 per second, as the service's live ring
keeps them), simple spectra, a window, stored trend rows and alarms. No service needed (tests of
the dashboard's parts and development; the real service's tests use the real one).

Run ``PYTHONPATH=. .venv/bin/python tests/web/dashboard_feeder.py`` to look at the dashboard.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

import estimator
from contract import (
    AlarmDocument,
    BaselineModeDocument,
    LiveEstimatesDocument,
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    ThresholdsDocument,
    StructureModel,
    StructuresDocument,
    TrendRow,
    WindowDocument,
)
from shm_service.rig_layouts import default_rig
from shm_service.virtual_rig import SimulationSettings, VirtualRig

TOKEN = "let-me-in"
ID = "virtual-rig"
#: The fake service's chart levels: not the analytics' defaults, so a test sees they are drawn from the service.
THRESHOLDS = ThresholdsDocument(frequency={"warning_sigma": 2.5, "alarm_sigma": 4.0},
                                curvature={"warning_sigma": 2.5, "alarm_sigma": 6.0}, clear_sigma=1.5)


def fake_status(*, started: float, sensors: dict[str, str], alarms: list[AlarmDocument], windows: int,
                thresholds: ThresholdsDocument = THRESHOLDS, layout: StateLayout | None = None) -> StatusDocument:
    """A complete status document of a running simulated source (the service's shape, made-up counts)."""
    active = [a for a in alarms if a.active]
    layout = layout or StateLayout("gyro", 4, 4)
    return StatusDocument.model_validate({
        "service": {"version": "0.1.0", "started_at": started, "uptime_s": time.time() - started, "done": False},
        "sources": [{"id": "virtual-rig", "kind": "sim", "state": "running", "messages": 123456, "rate_hz": 1866.7,
                     "latency_s": 0.012, "data_time_s": 42.0, "dropped": 3, "rejected": 1, "rejected_by_reason": {"nonfinite": 1},
                     "problems": []}],
        "pipeline": {"queue_depth": 0, "queue_capacity": 64, "samples": 123456, "samples_by_topic": {}, "late_samples": 0,
                     "late_by_topic": {}, "estimates": 8000, "estimator": {"state": "running", "dropped_samples": 0, "filter_restarts": 0},
                     "windows": windows, "windows_committed": windows, "windows_skipped_incomplete": 0, "windows_skipped_warmup": 2,
                     "baseline": "active", "pipeline_latency_s": 0.01, "busy_fraction": 0.2, "active_alarms": {}},
        "degraded_sensors": sorted(t for t, v in sensors.items() if v != "ok"),
        "sensors": dict(sensors),
        "baseline": {"state": "active", "modes": [
            BaselineModeDocument(mode=1, unit=1, f_ref_hz=0.301, temperature_ref_c=20.0, slope_per_k=0.0, sigma_rel=0.004),
            BaselineModeDocument(mode=2, unit=1, f_ref_hz=0.86, temperature_ref_c=20.0, slope_per_k=-1.5e-4, sigma_rel=0.002),
        ]},
        "alarms": {"active": {"warning": sum(a.level == "warning" for a in active), "alarm": sum(a.level == "alarm" for a in active)}},
        "notifications": {"sent_this_run": 0, "failed_attempts_this_run": 0},
        "storage": {"db": "memory", "schema_version": 2, "trend_rows": windows, "archive": None},
        "sinks": {"dashboard": {}, "notifier": {}},
        "thresholds": thresholds,
        "model": {"peripheral": layout.peripheral, "support": "pinned", "gamma": layout.gamma, "state_names": list(layout.names),
                  "unit_modes": [[1, 2]] + [[k + 2] for k in range(1, layout.gamma)]},
    })


def alarm(alarm_id: int, *, mode: int | None = 2, level: str = "alarm", state: str = "active", raised_at_s: float = 25.0,
          message: str = "mode 2 frequency 1.1 % below baseline (6.2 σ)") -> AlarmDocument:
    kind = "frequency" if mode is not None else "curvature"
    return AlarmDocument(id=alarm_id, source="virtual-rig", chart=f"mode{mode}" if mode is not None else "curvature", kind=kind,
                         mode=mode, level=level, state=state, raised_at_s=raised_at_s, value=-6.2, threshold=4.0, message=message)


class FakePort:
    """One structure (``ID``) behind an in-memory ``contract.ServicePort``, with the HTTP API's
    acknowledge rules. Its live estimates replay ``states`` (a copy of each 20th sample, 10 per
    wall second, looping) with data times that keep increasing; ``served`` counts them."""

    fleet = False

    def __init__(self, model: StructureModel, times: np.ndarray, states: np.ndarray, truth: np.ndarray | None, *,
                 token: str | None = TOKEN, history: list[TrendRow] | None = None, sensors: dict[str, str] | None = None,
                 spectrum: SpectrumDocument | None = None, window: WindowDocument | None = None,
                 fatigue: Any = None, live_hz: float = 10.0) -> None:
        self.model, self.times, self.states, self.truth = model, times, states, truth
        self.token = token
        self.lock = threading.Lock()
        self._alarms: dict[int, AlarmDocument] = {}
        self._history = list(history or [])
        self.sensors = dict(sensors or {})
        self.spectrum, self.window, self.fatigue = spectrum, window, fatigue
        self.live_hz = live_hz
        self.started = time.time()
        self._t0 = time.monotonic()
        self.served = 0

    def _check(self, structure_id: str) -> None:
        if structure_id != self.model.id:
            raise KeyError(f"no structure {structure_id!r}")

    def structures_document(self) -> StructuresDocument:
        with self.lock:
            active = {a.chart: a.level for a in self._alarms.values() if a.active}
            windows = len({r.window_start_s for r in self._history}) + (self.window is not None)
        return StructuresDocument(structures=[{"id": self.model.id, "kind": "sim", "state": "running", "lag_s": 0.1,
                                               "windows": windows, "active_alarms": active}])

    def structure_model(self, structure_id: str) -> StructureModel:
        self._check(structure_id)
        return self.model

    def structure_status(self, structure_id: str) -> StatusDocument:
        self._check(structure_id)
        with self.lock:
            return fake_status(started=self.started, sensors=self.sensors, alarms=list(self._alarms.values()),
                               windows=len({r.window_start_s for r in self._history}), layout=self.model.layout)

    def structure_trends(self, structure_id: str, from_s: float | None, to_s: float | None, mode: int | None = None,
                         limit: int = 100_000) -> list[TrendRow]:
        self._check(structure_id)
        with self.lock:
            return [r for r in self._history
                    if (from_s is None or r.window_start_s >= from_s) and (to_s is None or r.window_start_s < to_s)][:limit]

    def structure_alarms(self, structure_id: str, state: str | None = None) -> list[AlarmDocument]:
        self._check(structure_id)
        with self.lock:
            return sorted((a for a in self._alarms.values() if state is None or a.state == state), key=lambda a: -a.id)

    def structure_window(self, structure_id: str) -> WindowDocument | None:
        self._check(structure_id)
        return self.window

    def structure_spectra(self, structure_id: str) -> SpectrumDocument | None:
        self._check(structure_id)
        return self.spectrum

    def structure_fatigue(self, structure_id: str, from_s: float | None = None, to_s: float | None = None,
                          limit: int = 100_000) -> Any:
        self._check(structure_id)
        if self.fatigue is None:
            raise LookupError(f"structure {structure_id!r} has no hot spots")
        return self.fatigue

    def live(self, structure_id: str, after: int = 0) -> LiveEstimatesDocument:
        self._check(structure_id)
        newest = int((time.monotonic() - self._t0) * self.live_hz)
        seqs = list(range(max(after + 1, newest - 59), newest + 1))
        step = max(1, int(round(200.0 / self.live_hz)))
        rows = [(2 * 200 + k * step) % len(self.times) for k in seqs]
        with self.lock:
            self.served += len(seqs)
        return LiveEstimatesDocument(
            source=structure_id, seq=newest, state_names=list(self.model.layout.names),
            t_s=[1000.0 + k / self.live_hz for k in seqs], x=[self.states[r].tolist() for r in rows],
            sensors=self.sensors, watch_s=20.0,
            truth_deflection=None if self.truth is None else [self.truth[r].tolist() for r in rows])

    def add_alarm(self, alarm: AlarmDocument) -> AlarmDocument:
        with self.lock:
            self._alarms[alarm.id] = alarm
            return alarm

    def alarms(self, state: str | None = None) -> list[AlarmDocument]:
        return self.structure_alarms(self.model.id, state)

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        if self.token is None or not token or token != self.token:
            raise PermissionError("missing or wrong token")
        with self.lock:
            if alarm_id not in self._alarms:
                raise KeyError(alarm_id)
            alarm = self._alarms[alarm_id].model_copy(update={"acknowledged_at_s": time.time(), "acknowledged_by": by})
            self._alarms[alarm_id] = alarm
            return alarm


def demo_spectrum(layout: StateLayout, units: Any, times: np.ndarray, states: np.ndarray, fs: float = 200.0) -> SpectrumDocument:
    """The spectra of the last 20 s of ``states`` with the tracked peaks near the model's frequencies."""
    gamma = layout.gamma
    expected = [float(f[-1]) for f in units.frequencies_hz[:gamma]]
    n = min(len(times), int(20 * fs))
    freqs, spec = spectra_of(layout.b_of(states[-n:]), fs)
    tracked = [[] if f is None else [f] for f in tracked_peaks(freqs, spec, expected)]
    return SpectrumDocument.from_arrays(source=ID, window_start_s=float(times[-n]), window_end_s=float(times[-1]),
                                        frequencies_hz=freqs, amplitudes=spec, tracked_hz=tracked,
                                        baseline_hz=[[f] for f in expected])


def simulated_estimates(seconds: float = 30.0, *, excitation: str = "ambient", seed: int = 1, gamma: int = 4,
                        layout: StateLayout | None = None):
    """(rig, units, layout, stations, times (n,), states (n, layout.size), truth deflection (n, len(stations))) at 200 Hz:
    the virtual rig's truth written into the estimator's state layout (gyro, Γ, four peripheral IMUs by default)."""
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), gamma)
    layout = layout or StateLayout("gyro", gamma, 4)
    vr = VirtualRig(SimulationSettings(duration=seconds, excitation=excitation, rest=1.0, seed=seed))
    stations = np.asarray(vr.nominal_rig.truth_stations, dtype=float)
    S = units.shape(stations)
    times, xs, truth = [], [], []
    for block in vr.blocks(1.0):
        tr = block.truth
        b = np.linalg.lstsq(S, np.asarray(tr["deflection"]).T, rcond=None)[0].T
        x = np.zeros((len(block.times), layout.size))
        x[:, layout.d], x[:, layout.h], x[:, layout.phi] = tr["d"], tr["h"], tr["phi"]
        x[:, layout.b] = b
        times.append(block.times)
        xs.append(x)
        truth.append(np.asarray(tr["deflection"]))
    return rig, units, layout, stations, np.concatenate(times), np.concatenate(xs), np.concatenate(truth)


def spectra_of(b: np.ndarray, fs: float = 200.0) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectra (Hann window) of each column of b."""
    n = b.shape[0]
    w = np.hanning(n)
    spec = np.abs(np.fft.rfft((b - b.mean(axis=0)) * w[:, None], axis=0)) * 2.0 / w.sum()
    return np.fft.rfftfreq(n, 1.0 / fs), spec


def tracked_peaks(freqs: np.ndarray, spec: np.ndarray, expected: list[float], rel: float = 0.15) -> list[float | None]:
    out: list[float | None] = []
    for k, f0 in enumerate(expected):
        band = (freqs > f0 * (1 - rel)) & (freqs < f0 * (1 + rel))
        out.append(float(freqs[band][np.argmax(spec[band, k])]) if band.any() else None)
    return out


def history_rows(n_windows: int, units: Any, *, t0: float = -600.0, window_s: float = 30.0, seed: int = 3) -> list[TrendRow]:
    """Trend rows (one per window and eigenmode of ``units``) of a healthy past with a slow drop of mode 2."""
    rng = np.random.default_rng(seed)
    modes = [(m, unit) for unit, group in enumerate(units.modes, start=1) for m in group]
    base = [f for group in units.frequencies_hz for f in group]
    rows = []
    for i in range(n_windows):
        start = t0 + i * window_s
        temp = 20.0 + 2.0 * np.sin(i / 8)
        for (m, unit), f in zip(modes, base):
            drift = -0.01 * max(0, i - n_windows + 6) if m == 2 else 0.0
            rows.append(TrendRow(
                source="virtual-rig", window_start_s=start, window_end_s=start + window_s, mode=m, unit=unit, kind="ambient",
                frequency_hz=f * (1 + 0.002 * rng.standard_normal() + drift),
                damping_ratio=0.004 * (1 + 0.2 * rng.standard_normal()), amplitude=1e-3, confidence=0.9,
                temperature_c=temp, curvature_index=float(0.05 + 0.01 * rng.standard_normal() + (0.1 if drift else 0.0)),
                score_sigma=float(rng.standard_normal() + (600 * drift if m == 2 else 0.0)), level="ok",
            ))
    return rows


def main() -> None:  # pragma: no cover - manual demo
    from web import Dashboard

    rig, units, layout, stations, times, states, truth = simulated_estimates(60.0)
    states_by_topic = {s.topic: "ok" for s in rig.sensors}
    states_by_topic["/tof/s3"] = "degraded"
    model = StructureModel(id=ID, rig=rig, units=units, layout=layout, stations=stations)
    service = FakePort(model, times, states, truth, history=history_rows(40, units), sensors=states_by_topic,
                       spectrum=demo_spectrum(layout, units, times, states))
    dash = Dashboard(host="127.0.0.1", port=8080, service=service)
    print("dashboard at", dash.url, flush=True)
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        dash.stop()


if __name__ == "__main__":  # pragma: no cover
    main()
