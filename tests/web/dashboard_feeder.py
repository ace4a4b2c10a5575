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
from shm_service.rig_layouts import default_rig
from shm_service.virtual_rig import SimulationSettings, VirtualRig

TOKEN = "let-me-in"


class FakeService:
    """In-memory DashboardService with the HTTP API's acknowledge rules."""

    def __init__(self, *, token: str | None = TOKEN, history: list[dict] | None = None, sensors: dict[str, str] | None = None):
        self.token = token
        self.lock = threading.Lock()
        self.paused_calls: list[bool] = []
        self.paused = False
        self._alarms: dict[int, dict] = {}
        self._history = list(history or [])
        self.sensors = dict(sensors or {})
        self.started = time.time()

    def status(self) -> dict[str, Any]:
        with self.lock:
            active = [a for a in self._alarms.values() if a["state"] == "active"]
            return {
                "service": {"version": "0.1.0", "started_at": self.started, "uptime_s": time.time() - self.started, "paused": self.paused},
                "sources": [
                    {"id": "virtual-rig", "kind": "simulation", "state": "running", "messages": 123456, "rate_hz": 1866.7,
                     "latency_s": 0.012, "data_time_s": 42.0, "dropped": 3, "rejected": 1},
                ],
                "pipeline": {"estimator_hz": 200.0, "analytics_windows": len(self._history), "queue": 0},
                "degraded_sensors": [t for t, v in self.sensors.items() if v != "ok"],
                "sensors": dict(self.sensors),
                "baseline": {"state": "ready", "modes": [
                    {"mode": 1, "unit": 1, "f_ref_hz": 0.86, "temperature_ref_c": 20.0, "slope_per_k": 0.0, "sigma_rel": 0.004, "rho": 0.3, "windows": 12},
                    {"mode": 2, "unit": 2, "f_ref_hz": 1.906, "temperature_ref_c": 20.0, "slope_per_k": -1.5e-4, "sigma_rel": 0.002, "rho": 0.3, "windows": 12},
                ]},
                "alarms": {"warning": sum(a["level"] == "warning" for a in active), "alarm": sum(a["level"] == "alarm" for a in active)},
                "storage": {"db": "memory", "rows": len(self._history)},
            }

    def trends(self, from_s: float | None, to_s: float | None) -> list[dict[str, Any]]:
        with self.lock:
            return [r for r in self._history
                    if (from_s is None or r["window_start_s"] >= from_s) and (to_s is None or r["window_start_s"] < to_s)]

    def alarms(self) -> list[dict[str, Any]]:
        with self.lock:
            return [dict(a) for a in sorted(self._alarms.values(), key=lambda a: -a["id"])]

    def add_alarm(self, alarm: dict) -> dict:
        with self.lock:
            self._alarms[alarm["id"]] = dict(alarm)
            return dict(alarm)

    def acknowledge(self, alarm_id: int, token: str) -> dict[str, Any]:
        if self.token is None or not token or token != self.token:
            raise PermissionError("missing or wrong token")
        with self.lock:
            if alarm_id not in self._alarms:
                raise KeyError(alarm_id)
            alarm = self._alarms[alarm_id]
            alarm["acknowledged_at_s"] = time.time()
            alarm["acknowledged_by"] = "operator"
            return dict(alarm)

    def set_paused(self, paused: bool) -> None:
        with self.lock:
            self.paused = paused
            self.paused_calls.append(paused)


def simulated_estimates(seconds: float = 30.0, *, excitation: str = "ambient", seed: int = 1, gamma: int = 4):
    """(rig, units, stations, times (n,), states (n, 5+Γ+1), truth deflection (n, len(stations))) at 200 Hz."""
    rig = default_rig()
    units = estimator.unit_deformations(estimator.assemble_beam(rig), gamma)
    vr = VirtualRig(SimulationSettings(duration=seconds, excitation=excitation, rest=1.0, seed=seed))
    stations = np.asarray(vr.nominal_rig.truth_stations, dtype=float)
    S = units.shape(stations)
    times, xs, truth = [], [], []
    for block in vr.blocks(1.0):
        tr = block.truth
        b = np.linalg.lstsq(S, np.asarray(tr["deflection"]).T, rcond=None)[0].T
        x = np.zeros((len(block.times), 5 + gamma + 1))
        x[:, 0], x[:, 1], x[:, 4] = tr["d"], tr["h"], tr["phi"]
        x[:, 5 : 5 + gamma] = b
        times.append(block.times)
        xs.append(x)
        truth.append(np.asarray(tr["deflection"]))
    return rig, units, stations, np.concatenate(times), np.concatenate(xs), np.concatenate(truth)


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


def history_rows(n_windows: int, gamma: int, stations: np.ndarray, *, t0: float = -600.0, window_s: float = 30.0, seed: int = 3) -> list[dict]:
    """Trend rows (one per window and mode) of a healthy past with a slow drop of mode 2."""
    rng = np.random.default_rng(seed)
    base = [0.86, 1.906, 3.506, 5.644][:gamma] + [7.0] * max(0, gamma - 4)
    rows = []
    for i in range(n_windows):
        start = t0 + i * window_s
        temp = 20.0 + 2.0 * np.sin(i / 8)
        for m in range(1, gamma + 1):
            drift = -0.01 * max(0, i - n_windows + 6) if m == 2 else 0.0
            rows.append({
                "source": "virtual-rig", "window_start_s": start, "window_end_s": start + window_s, "mode": m,
                "frequency_hz": base[m - 1] * (1 + 0.002 * rng.standard_normal() + drift),
                "damping_ratio": 0.004 * (1 + 0.2 * rng.standard_normal()), "amplitude": 1e-3, "confidence": 0.9,
                "temperature_c": temp, "curvature_index": float(0.05 + 0.01 * rng.standard_normal() + (0.1 if drift else 0.0)),
                "score_sigma": float(rng.standard_normal() + (600 * drift if m == 2 else 0.0)),
                "flags": [],
            })
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
        b = self.states[upto - n : upto, 5 : 5 + self.dashboard.gamma]
        freqs, spec = spectra_of(b, self.fs)
        self.dashboard.push_spectra(freqs, spec, tracked_peaks(freqs, spec, self.expected), self.expected)

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

    rig, units, stations, times, states, truth = simulated_estimates(60.0)
    states_by_topic = {s.topic: "ok" for s in rig.sensors}
    states_by_topic["/tof/s3"] = "degraded"
    service = FakeService(history=history_rows(40, units.count, stations), sensors=states_by_topic)
    dash = Dashboard(host="127.0.0.1", port=8080, rig=rig, units=units, stations=stations, service=service)
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
