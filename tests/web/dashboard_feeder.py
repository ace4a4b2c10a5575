"""A demo feeder for the dashboard: the virtual rig's truth as "estimates", simple spectra and
analysis windows, and an in-memory DashboardService. No service needed (tests and development).

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
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    ThresholdsDocument,
    TrendRow,
)
from shm_service.rig_layouts import default_rig
from shm_service.virtual_rig import SimulationSettings, VirtualRig

TOKEN = "let-me-in"
#: The fake service's chart levels: not the analytics' defaults, so a test sees they are drawn from the service.
THRESHOLDS = ThresholdsDocument(frequency={"warning_sigma": 2.5, "alarm_sigma": 4.0},
                                curvature={"warning_sigma": 2.5, "alarm_sigma": 6.0}, clear_sigma=1.5)


def fake_status(*, started: float, paused: bool, sensors: dict[str, str], alarms: list[AlarmDocument], windows: int,
                thresholds: ThresholdsDocument = THRESHOLDS, layout: StateLayout | None = None) -> StatusDocument:
    """A complete status document of a running simulated source (the service's shape, made-up counts)."""
    active = [a for a in alarms if a.active]
    layout = layout or StateLayout("gyro", 4, 4)
    return StatusDocument.model_validate({
        "service": {"version": "0.1.0", "started_at": started, "uptime_s": time.time() - started, "paused": paused, "done": False},
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


class FakeService:
    """In-memory DashboardService with the HTTP API's acknowledge rules."""

    def __init__(self, *, token: str | None = TOKEN, history: list[TrendRow] | None = None, sensors: dict[str, str] | None = None):
        self.token = token
        self.lock = threading.Lock()
        self.paused_calls: list[bool] = []
        self.paused = False
        self._alarms: dict[int, AlarmDocument] = {}
        self._history = list(history or [])
        self.sensors = dict(sensors or {})
        self.started = time.time()

    def status(self) -> StatusDocument:
        with self.lock:
            return fake_status(started=self.started, paused=self.paused, sensors=self.sensors, alarms=list(self._alarms.values()),
                               windows=len({r.window_start_s for r in self._history}))

    def trends(self, from_s: float | None, to_s: float | None) -> list[TrendRow]:
        with self.lock:
            return [r for r in self._history
                    if (from_s is None or r.window_start_s >= from_s) and (to_s is None or r.window_start_s < to_s)]

    def alarms(self) -> list[AlarmDocument]:
        with self.lock:
            return sorted(self._alarms.values(), key=lambda a: -a.id)

    def add_alarm(self, alarm: AlarmDocument) -> AlarmDocument:
        with self.lock:
            self._alarms[alarm.id] = alarm
            return alarm

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        if self.token is None or not token or token != self.token:
            raise PermissionError("missing or wrong token")
        with self.lock:
            if alarm_id not in self._alarms:
                raise KeyError(alarm_id)
            alarm = self._alarms[alarm_id].model_copy(update={"acknowledged_at_s": time.time(), "acknowledged_by": by})
            self._alarms[alarm_id] = alarm
            return alarm

    def set_paused(self, paused: bool) -> None:
        with self.lock:
            self.paused = paused
            self.paused_calls.append(paused)


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


class DemoFeeder:
    """Pushes the simulated run into a dashboard in real time (looping), in its own thread."""

    def __init__(self, dashboard: Any, times: np.ndarray, states: np.ndarray, truth: np.ndarray,
                 sensor_states: dict[str, str], *, rate_hz: float = 20.0, spectra_every_s: float = 2.0, fs: float = 200.0):
        self.dashboard = dashboard
        self.times, self.states, self.truth = times, states, truth
        self.sensor_states = sensor_states
        self.rate_hz = rate_hz
        self.spectra_every_s = spectra_every_s
        self.fs = fs
        self.pushed = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="demo-feeder", daemon=True)
        gamma = dashboard.gamma
        self.expected = [float(f[-1]) for f in dashboard.units.frequencies_hz[:gamma]]

    def push_spectra(self, upto: int) -> None:
        n = min(upto, int(20 * self.fs))
        b = self.dashboard.layout.b_of(self.states[upto - n : upto])
        freqs, spec = spectra_of(b, self.fs)
        tracked = [[] if f is None else [f] for f in tracked_peaks(freqs, spec, self.expected)]
        self.dashboard.push_spectra(SpectrumDocument.from_arrays(
            source="virtual-rig", window_start_s=float(self.times[upto - n]), window_end_s=float(self.times[upto - 1]),
            frequencies_hz=freqs, amplitudes=spec, tracked_hz=tracked, baseline_hz=[[f] for f in self.expected]))

    def push_one(self, i: int) -> None:
        self.dashboard.push_estimate(float(self.times[i]), self.states[i], self.sensor_states, self.truth[i])
        self.pushed += 1

    def start(self) -> "DemoFeeder":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        step = max(1, int(round(self.fs / self.rate_hz)))
        i, last_spec = int(2 * self.fs), -1e9
        while not self._stop.is_set():
            if i >= len(self.times):
                i = int(2 * self.fs)
            self.push_one(i)
            if self.times[i] - last_spec >= self.spectra_every_s:
                last_spec = self.times[i]
                self.push_spectra(i)
            i += step
            self._stop.wait(1.0 / self.rate_hz)


def main() -> None:  # pragma: no cover - manual demo
    from web import Dashboard

    rig, units, layout, stations, times, states, truth = simulated_estimates(60.0)
    states_by_topic = {s.topic: "ok" for s in rig.sensors}
    states_by_topic["/tof/s3"] = "degraded"
    service = FakeService(history=history_rows(40, units), sensors=states_by_topic)
    dash = Dashboard(host="127.0.0.1", port=8080, rig=rig, units=units, layout=layout, stations=stations, service=service)
    print("dashboard at", dash.url, flush=True)
    feeder = DemoFeeder(dash, times, states, truth, states_by_topic).start()
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        feeder.stop()
        dash.stop()


if __name__ == "__main__":  # pragma: no cover
    main()
