"""The viser dashboard: live deformed beam, spectra, trends, alarms and status.

Threads: the service calls the ``push_*`` methods from its own threads; they validate, copy and
store the newest data under a lock and return at once. One render thread of the dashboard draws
the newest data into every connected browser at ``render_hz`` (updates assigned to existing
handles, grouped per client in ``client.atomic()``; nothing is re-created per frame, so memory
stays flat). It also polls the service for its status and alarm list. viser runs its own thread
and asyncio loop; GUI callbacks run on viser's threads.

Every browser (client) gets its own GUI and its own copy of the live scene, so one operator's
pause, overscale, mode choice or token never changes what another sees. The scene's static
parts (rail, reflector, grid) are shared.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from contract import (
    SENSOR_STATES,
    AlarmDocument,
    BaselineModeDocument,
    ModeMap,
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    WindowDocument,
)

from ._data import (
    SpectraRecord,
    WindowRecord,
    baseline_band,
    spectra_record,
    thresholds_of,
    window_record,
    windows_from_trend_rows,
)
from ._gate import TokenGate
from ._geometry import BeamState, parse_state
from ._view import ClientView

__all__ = ["Dashboard", "SENSOR_STATES"]

log = logging.getLogger(__name__)
MAX_WINDOWS = 20_000  # ≈ 7 days of 30 s windows
MAX_ALARMS = 500
STATUS_POLL_S = 1.0
ALARM_POLL_S = 5.0
MEAN_TAU_S = 60.0  # time constant of the running-mean ghost


@dataclass(frozen=True)
class Estimate:
    t_s: float
    state: BeamState
    sensor_states: dict[str, str]
    truth_deflection: np.ndarray | None


@dataclass(frozen=True)
class Snapshot:
    """What the render thread hands to each view (immutable references, taken under the lock)."""

    estimate: Estimate | None
    estimate_version: int
    mean_state: BeamState | None
    spectra: SpectraRecord | None
    spectra_version: int
    windows: tuple[WindowRecord, ...]
    windows_version: int
    alarms: tuple[AlarmDocument, ...]  # newest first
    alarms_version: int
    status: StatusDocument | None
    status_error: str | None
    status_version: int
    estimate_rate_hz: float  # states pushed to the dashboard per wall second (what it can draw)
    # the estimator's own output: estimates per second of data (its sample rate) and data seconds per
    # wall second, from the service's status over the last polls (None until two polls saw progress)
    filter_rate_hz: float | None = None
    realtime_factor: float | None = None


class _Store:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.estimate: Estimate | None = None
        self.estimate_version = 0
        self.mean: BeamState | None = None
        self.spectra: SpectraRecord | None = None
        self.spectra_version = 0
        self.windows: deque[WindowRecord] = deque(maxlen=MAX_WINDOWS)
        self.windows_tuple: tuple[WindowRecord, ...] = ()
        self.windows_version = 0
        self.alarms: dict[int, AlarmDocument] = {}
        self.alarms_tuple: tuple[AlarmDocument, ...] = ()
        self.alarms_version = 0
        self.status: StatusDocument | None = None
        self.status_error: str | None = None
        self.status_version = 0
        self.notify: deque[AlarmDocument] = deque(maxlen=50)
        self.push_times: deque[float] = deque(maxlen=50)
        self.progress: deque[tuple[float, int, float]] = deque(maxlen=6)  # (monotonic s, estimates, processed data s)

    def snapshot(self) -> Snapshot:
        with self.lock:
            if len(self.push_times) >= 2 and self.push_times[-1] > self.push_times[0]:
                rate = (len(self.push_times) - 1) / (self.push_times[-1] - self.push_times[0])
            else:
                rate = 0.0
            filter_rate = realtime = None
            if len(self.progress) >= 2:
                (w0, n0, d0), (w1, n1, d1) = self.progress[0], self.progress[-1]
                if n1 > n0 and d1 > d0:
                    filter_rate, realtime = (n1 - n0) / (d1 - d0), (d1 - d0) / max(w1 - w0, 1e-9)
            return Snapshot(
                self.estimate, self.estimate_version, self.mean,
                self.spectra, self.spectra_version,
                self.windows_tuple, self.windows_version,
                self.alarms_tuple, self.alarms_version,
                self.status, self.status_error, self.status_version,
                rate, filter_rate, realtime,
            )

    def upsert_alarm(self, rec: AlarmDocument) -> bool:
        """Insert/update an alarm; True when it newly became active (worth a notification)."""
        with self.lock:
            old = self.alarms.get(rec.id)
            if old is not None and old == rec:
                return False
            self.alarms[rec.id] = rec
            if len(self.alarms) > MAX_ALARMS:  # forget the oldest cleared ones first
                for key in sorted(self.alarms, key=lambda k: (self.alarms[k].active, k))[: len(self.alarms) - MAX_ALARMS]:
                    del self.alarms[key]
            self.alarms_tuple = tuple(sorted(self.alarms.values(), key=lambda a: a.id, reverse=True))
            self.alarms_version += 1
            fresh = rec.active and (old is None or not old.active)
            cleared = (not rec.active) and old is not None and old.active
            if fresh or cleared:
                self.notify.append(rec)
            return fresh


class Dashboard:
    """The live SHM dashboard, served by viser at :attr:`url`.

    Parameters
    ----------
    host, port : where viser listens (``port=0`` picks a free port; a taken port is replaced by
        the next free one; :attr:`url` and :attr:`port` give the real one).
    rig : ``contract.RigDescription`` (beam length and width, reflector distance, sensors; support and
        orientation: a pin or a clamp at D, the beam hanging or standing upright).
    units : ``estimator.UnitDeformations`` (shape/slope of the Γ unit deformations; their
        ``modes`` label trends and spectra).
    layout : ``contract.StateLayout`` of the estimator's state vector (how ``push_estimate`` reads x).
    stations : η (m) of the curvature-change index (and of ``truth_deflection``).
    service : a ``DashboardService`` (status, trends, alarms, acknowledge, set_paused); duck typed.
    render_hz : frames per second drawn into each browser (10–60).
    token : the operator token. Required off loopback: viser then listens on a free loopback
        port and ``web._gate.TokenGate`` on ``host:port`` lets only requests with the token pass
        (a browser asks for it: the token as the password; ValueError without one).
    """

    def __init__(
        self,
        *,
        host: str,
        port: int,
        rig: Any,
        units: Any,
        layout: StateLayout,
        stations: np.ndarray,
        service: Any,
        render_hz: float = 20.0,
        label: str = "IMMS structural health monitor",
        token: str | None = None,
    ) -> None:
        off_loopback = not _is_loopback(host)
        if off_loopback and not token:
            raise ValueError(f"dashboard host {host!r} is not loopback: a token is required (server.token_file or "
                             "SHM_TOKEN); viser itself has no authentication")
        gamma = int(getattr(units, "count", 0))
        if gamma < 1:
            raise ValueError("units must provide at least one unit deformation (units.count >= 1)")
        if not isinstance(layout, StateLayout):
            raise TypeError(f"layout must be a contract.StateLayout, got {type(layout).__name__}")
        if layout.gamma != gamma:
            raise ValueError(f"layout has Γ={layout.gamma} unit deformations, units {gamma}")
        mode_map = ModeMap.of(getattr(units, "modes", ()))
        if mode_map.gamma != gamma:
            raise ValueError(f"units.modes names the modes of {mode_map.gamma} unit deformations, units.count is {gamma}")
        self.length = float(rig.beam.length)
        self.width = float(rig.beam.width)
        if not (self.length > 0 and self.width > 0):
            raise ValueError(f"rig beam length and width must be > 0, got {self.length}, {self.width}")
        self.reflector_distance = float(rig.reflector_distance)
        # How the beam is held and drawn: a pin or a clamp at D; hanging below it or standing up.
        support, orientation = getattr(rig, "support", "pinned"), getattr(rig, "orientation", "hanging")
        if support not in ("pinned", "clamped"):
            raise ValueError(f"rig support={support!r} must be 'pinned' or 'clamped'")
        if orientation not in ("hanging", "standing"):
            raise ValueError(f"rig orientation={orientation!r} must be 'hanging' or 'standing'")
        self.clamped = support == "clamped"
        self.standing = orientation == "standing"
        stations = np.asarray(stations, dtype=float)
        if stations.ndim != 1 or stations.size < 1 or not np.all(np.isfinite(stations)):
            raise ValueError(f"stations must be a non-empty 1-D array of finite η, got shape {stations.shape}")
        if np.any(stations < 0) or np.any(stations > self.length + 1e-9) or np.any(np.diff(stations) <= 0):
            raise ValueError(f"stations must increase strictly within the beam [0, {self.length}] m")
        for name in ("status", "trends", "alarms", "acknowledge", "set_paused"):
            if not callable(getattr(service, name, None)):
                raise TypeError(f"service must implement DashboardService: missing {name}()")
        if not 1.0 <= render_hz <= 60.0:
            raise ValueError(f"{render_hz=} must be within [1, 60]")
        self.rig = rig
        self.units = units
        self.layout = layout
        self.mode_map = mode_map
        self.gamma = gamma
        self.stations = stations.copy()
        self.service = service
        self.render_hz = float(render_hz)
        self.label = label
        self.sensor_topics = {s.topic: s for s in rig.sensors}
        self.frames = 0
        self.last_frame_s = 0.0
        self._store = _Store()
        self._views: dict[int, ClientView] = {}
        self._views_lock = threading.Lock()
        self._service_paused: bool | None = None
        self._stop = threading.Event()

        self.gate = None
        if off_loopback:
            # viser on a free loopback port; the token gate (web._gate) on the public address
            self.server = viser.ViserServer(host="127.0.0.1", port=0, label=label, verbose=False)
            try:
                self.gate = TokenGate(host=host, port=port, upstream_port=int(self.server.get_port()), token=token)
            except BaseException:
                self.server.stop()
                raise
            self.port = self.gate.port
        else:
            self.server = viser.ViserServer(host=host, port=port, label=label, verbose=False)
            self.port = int(self.server.get_port())
        shown_host = "localhost" if host in ("0.0.0.0", "::", "") else host
        self.url = f"http://{shown_host}:{self.port}/"
        try:
            ClientView.setup_shared(self)
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
            self._thread = threading.Thread(target=self._loop, name="shm-dashboard-render", daemon=True)
            self._thread.start()
        except BaseException:
            self.server.stop()
            if self.gate is not None:
                self.gate.stop()
            raise

    # ------------------------------------------------------------------ pushes (service side)
    def push_estimate(
        self,
        t_s: float,
        x: np.ndarray,
        sensor_states: dict[str, str],
        truth_deflection: np.ndarray | None = None,
    ) -> None:
        """The newest state estimate (called ≥ 10 Hz). Raises ValueError on malformed input."""
        t = _finite("t_s", t_s)
        state = parse_state(x, self.layout)
        if not isinstance(sensor_states, dict):
            raise ValueError(f"sensor_states must be a dict topic -> state, got {type(sensor_states).__name__}")
        for topic, value in sensor_states.items():
            if value not in SENSOR_STATES:
                raise ValueError(f"sensor_states[{topic!r}]={value!r} must be one of {SENSOR_STATES}")
        truth = None
        if truth_deflection is not None:
            truth = np.asarray(truth_deflection, dtype=float)
            if truth.shape != self.stations.shape:
                raise ValueError(f"truth_deflection must have shape {self.stations.shape} (one value per station), got {truth.shape}")
            if not np.all(np.isfinite(truth)):
                raise ValueError("truth_deflection has NaN or infinite values")
        est = Estimate(t, state, dict(sensor_states), truth)
        store = self._store
        with store.lock:
            prev = store.estimate
            if store.mean is None or prev is None or not t > prev.t_s:
                store.mean = state
            else:
                a = min(1.0, (t - prev.t_s) / MEAN_TAU_S)
                m = store.mean
                store.mean = BeamState(
                    m.d + a * (state.d - m.d), m.h + a * (state.h - m.h), m.phi + a * (state.phi - m.phi), m.b + a * (state.b - m.b)
                )
            store.estimate = est
            store.estimate_version += 1
            store.push_times.append(time.monotonic())

    def push_spectra(self, spectrum: SpectrumDocument) -> None:
        """Amplitude spectra (n_freq, Γ) of b1..bΓ of the latest window, with the tracked and
        baseline eigenfrequencies per unit deformation (before a baseline: tracked only)."""
        rec = spectra_record(spectrum, self.gamma)
        with self._store.lock:
            self._store.spectra = rec
            self._store.spectra_version += 1

    def push_window(self, window: WindowDocument) -> None:
        """One analysis window (its modes, charts and curvature change along ``stations``)."""
        rec = window_record(window, n_stations=self.stations.size)
        self._add_windows([rec])

    def push_alarm(self, alarm: AlarmDocument) -> None:
        """An alarm raised, updated, acknowledged or cleared; a raised alarm notifies every browser."""
        if not isinstance(alarm, AlarmDocument):
            raise ValueError(f"alarm must be a contract.AlarmDocument, got {type(alarm).__name__}")
        self._store.upsert_alarm(alarm)

    def stop(self) -> None:
        """Stop the render thread and the web server (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        if self.gate is not None:
            self.gate.stop()
        self.server.stop()

    def __enter__(self) -> "Dashboard":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ internals
    def _add_windows(self, records: list[WindowRecord]) -> None:
        store = self._store
        with store.lock:
            for rec in records:
                if store.windows and rec.t_s < store.windows[-1].t_s:  # history arriving late: keep order
                    merged = sorted([*store.windows, rec], key=lambda r: r.t_s)
                    store.windows.clear()
                    store.windows.extend(merged)
                else:
                    store.windows.append(rec)
            store.windows_tuple = tuple(store.windows)
            store.windows_version += 1

    def snapshot(self) -> Snapshot:
        return self._store.snapshot()

    @property
    def client_count(self) -> int:
        with self._views_lock:
            return len(self._views)

    def baseline_modes(self, snap: Snapshot) -> dict[int, BaselineModeDocument]:
        """The service's baseline per mode (empty while it learns one)."""
        if snap.status is None or snap.status.baseline.modes is None:
            return {}
        return {m.mode: m for m in snap.status.baseline.modes}

    def band(self, snap: Snapshot, rec: WindowRecord, mode: int) -> tuple[float | None, float | None, float | None]:
        """(expected, low, high) Hz of ``mode`` at ``rec`` from the baseline (None without one)."""
        entry = self.baseline_modes(snap).get(mode)
        if entry is None:
            return None, None, None
        return baseline_band(entry, rec.temperature_c)

    def thresholds(self, snap: Snapshot) -> dict[str, tuple[float, float]]:
        """(warning, alarm) σ of the frequency and curvature charts, as the service applies them."""
        return thresholds_of(None if snap.status is None else snap.status.thresholds, snap.windows)

    def set_view_paused(self) -> None:
        """Pause the service's pushes only when every connected browser is paused."""
        with self._views_lock:
            views = list(self._views.values())
        paused = bool(views) and all(v.paused for v in views)
        if paused != self._service_paused:
            try:
                self.service.set_paused(paused)
                self._service_paused = paused
            except Exception:  # the service's problem must not break the page
                log.exception("service.set_paused(%s) failed", paused)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        view = ClientView(self, client)
        with self._views_lock:
            self._views[client.client_id] = view
        client.add_notification(
            "Connected to the SHM dashboard",
            f"{self.label}: live beam, spectra, trends and alarms. Acknowledging an alarm needs the operator token.",
            auto_close_seconds=6.0,
            color="blue",
        )
        snap = self.snapshot()
        active = [a for a in snap.alarms if a.active and not a.acknowledged]
        if active:
            client.add_notification(
                f"{len(active)} active alarm(s)",
                "; ".join(f"#{a.id} {a.level}: {a.message}" for a in active[:3]),
                color="red" if any(a.level == "alarm" for a in active) else "yellow",
                auto_close_seconds=None,
            )
        self.set_view_paused()

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._views_lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            view.closed = True
        self.set_view_paused()

    def _poll(self, now: float, last: dict[str, float]) -> None:
        store = self._store
        if "history" not in last:  # once, at start: the stored trend history
            last["history"] = now
            try:
                records = windows_from_trend_rows(self.service.trends(None, None) or [])
                if records:
                    self._add_windows(records)
            except Exception as exc:
                log.warning("service.trends() failed: %s", exc)
        if now - last.get("status", -math.inf) >= STATUS_POLL_S:
            last["status"] = now
            try:
                status = self.service.status()
                error = None if isinstance(status, StatusDocument) else f"status() returned {type(status).__name__}"
            except Exception as exc:
                status, error = None, f"{type(exc).__name__}: {exc}"
            with store.lock:
                store.status = status if isinstance(status, StatusDocument) else store.status
                pipeline = getattr(status, "pipeline", None)
                if pipeline is not None and pipeline.processed_data_s is not None:
                    store.progress.append((now, int(pipeline.estimates), float(pipeline.processed_data_s)))
                store.status_error = error
                store.status_version += 1
        if now - last.get("alarms", -math.inf) >= ALARM_POLL_S:
            last["alarms"] = now
            try:
                for item in self.service.alarms() or []:
                    if isinstance(item, AlarmDocument):
                        store.upsert_alarm(item)
                    else:
                        log.warning("ignoring an alarm that is not a contract.AlarmDocument: %r", type(item).__name__)
            except Exception as exc:
                log.warning("service.alarms() failed: %s", exc)

    def _notify(self) -> None:
        store = self._store
        with store.lock:
            pending = list(store.notify)
            store.notify.clear()
        if not pending:
            return
        clients = list(self.server.get_clients().values())
        for rec in pending:
            mode = f" (mode {rec.mode})" if rec.mode is not None else ""
            if rec.active:
                title = f"{'ALARM' if rec.level == 'alarm' else 'Warning'} #{rec.id} raised{mode}"
                color = "red" if rec.level == "alarm" else "yellow"
                close = None if rec.level == "alarm" else 30.0
            else:
                title = f"Alarm #{rec.id} cleared{mode}"
                color, close = "green", 10.0
            for client in clients:
                try:
                    client.add_notification(title, rec.message or "-", color=color, auto_close_seconds=close)
                except Exception:
                    log.exception("notification to client %s failed", client.client_id)

    def _loop(self) -> None:
        period = 1.0 / self.render_hz
        last: dict[str, float] = {}
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                self._poll(now, last)
                self._notify()
                snap = self.snapshot()
                with self._views_lock:
                    views = list(self._views.values())
                t0 = time.perf_counter()
                for view in views:
                    try:
                        view.render(snap)
                    except UserWarning as exc:  # viser (as an error under -W error): the browser just left
                        log.debug("client %s: %s", view.client.client_id, exc)
                    except Exception:
                        if not view.closed:
                            log.exception("rendering for client %s failed", view.client.client_id)
                self.last_frame_s = time.perf_counter() - t0
                self.frames += 1
            except Exception:
                log.exception("dashboard render loop error")
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:
                next_t = time.monotonic()
                delay = 0.0
            self._stop.wait(delay)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(float(v))


def _finite(name: str, value: Any) -> float:
    if not _is_num(value):
        raise ValueError(f"{name}={value!r} must be a finite number")
    return float(value)


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
