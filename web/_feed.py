"""One structure as the dashboard draws it: its rig and model (how to draw it) and its newest
data (estimate, spectra, windows, alarms, status, loads), kept under a lock for the render thread.

The feeds are filled by the dashboard's poller (``web._poller``) from the service's port, only for
the structures some browser shows (a structure of one like a fleet's); their estimates arrive a
batch at a time and are played out at their data pace (``add_live``, ``play``), so the picture
moves smoothly even with seconds-long batches.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from contract import (
    SENSOR_STATES,
    AlarmDocument,
    BaselineModeDocument,
    LiveEstimatesDocument,
    ModeMap,
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    WindowDocument,
)

from ._data import LoadsRecord, SpectraRecord, WindowRecord, baseline_band, spectra_record, thresholds_of, window_record
from ._geometry import BeamState, parse_state

__all__ = ["Estimate", "Snapshot", "StructureFeed"]

MAX_WINDOWS = 20_000  # ≈ 7 days of 30 s windows
MAX_ALARMS = 500
MEAN_TAU_S = 60.0  # time constant of the running-mean ghost
#: Live estimates waiting to be drawn (a fleet's feed): ≈ a minute at 10 per second.
MAX_PENDING = 600


def _section_width(station: Any) -> float:
    """The across-beam size (m) drawn for a station: a tube's outer diameter, a rectangle's width,
    twice a table's fibre distance."""
    if station.shape == "tube":
        return float(station.outer_diameter)
    if station.shape == "rectangle":
        return float(station.width)
    if station.shape == "table":
        return 2.0 * float(station.fibre_distance)
    raise ValueError(f"section shape {station.shape!r} must be 'rectangle', 'tube' or 'table'")


def _widest_section(beam: Any) -> float:
    """The largest across-beam size (m) of the stations of ``beam.sections``."""
    sizes = [_section_width(station) for station in beam.sections or ()]
    if not sizes:
        raise ValueError("the rig's beam has neither a width nor sections")
    return float(max(sizes))


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
    loads: LoadsRecord | None = None
    loads_error: str | None = None
    loads_version: int = 0


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
        self.drawn_times: deque[float] = deque(maxlen=50)
        self.progress: deque[tuple[float, int, float]] = deque(maxlen=6)  # (monotonic s, estimates, processed data s)
        self.loads: LoadsRecord | None = None
        self.loads_error: str | None = None
        self.loads_version = 0

    def snapshot(self) -> Snapshot:
        with self.lock:
            if len(self.drawn_times) >= 2 and self.drawn_times[-1] > self.drawn_times[0]:
                rate = (len(self.drawn_times) - 1) / (self.drawn_times[-1] - self.drawn_times[0])
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
                self.loads, self.loads_error, self.loads_version,
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

    def set_status(self, now: float, status: Any, error: str | None) -> None:
        with self.lock:
            self.status = status if isinstance(status, StatusDocument) else self.status
            pipeline = getattr(status, "pipeline", None)
            if pipeline is not None and pipeline.processed_data_s is not None:
                self.progress.append((now, int(pipeline.estimates), float(pipeline.processed_data_s)))
            self.status_error = error
            self.status_version += 1


class StructureFeed:
    """One structure: how to draw it and its newest data.

    Parameters
    ----------
    rig : ``contract.RigDescription`` (beam length and width, reflector distance, sensors; support and
        orientation: a pin or a clamp at D, the beam hanging or standing upright).
    units : ``estimator.UnitDeformations`` (shape/slope of the Γ unit deformations; their
        ``modes`` label trends and spectra).
    layout : ``contract.StateLayout`` of the estimator's state vector.
    stations : η (m) of the curvature-change index (and of ``truth_deflection``).
    structure_id : the structure's id in a fleet (None: the service's one structure).
    units_xi : a beam that bends in two planes: the ξ plane's unit deformations (None: planar).

    Raises ValueError (TypeError for a layout of another type) naming what does not fit.
    """

    def __init__(self, *, rig: Any, units: Any, layout: StateLayout, stations: np.ndarray,
                 structure_id: str | None = None, units_xi: Any = None) -> None:
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
        # drawn width: the sheet's width, or the widest section of a beam described by sections
        # (a tube's outer diameter, a rectangle's width, twice a table's fibre distance)
        self.width = float(rig.beam.width) if rig.beam.width is not None else _widest_section(rig.beam)
        if not (self.length > 0 and self.width > 0):
            raise ValueError(f"rig beam length and width must be > 0, got {self.length}, {self.width}")
        # A rig without ToFs has no reflector (None): nothing is drawn for it.
        self.reflector_distance = None if rig.reflector_distance is None else float(rig.reflector_distance)
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
        self.id = structure_id
        self.rig = rig
        self.units = units
        self.layout = layout
        gamma_xi = int(getattr(units_xi, "count", 0)) if units_xi is not None else 0
        if gamma_xi != layout.gamma_xi:
            raise ValueError(f"layout has Γξ={layout.gamma_xi} ξ unit deformations, units_xi {gamma_xi}")
        # a beam that bends in two planes: drawn bending in both, with its tip's orbit
        self.units_xi = units_xi if gamma_xi else None
        self.biaxial = self.units_xi is not None
        self.mode_map = mode_map
        self.gamma = gamma
        self.stations = stations.copy()
        self.sensor_topics = {s.topic: s for s in rig.sensors}
        self.store = _Store()
        self._angles: dict[str, float] = {}  # hot spot -> the angle its live loads are evaluated at (biaxial)
        # live estimates: (t_s, state, true deflection) waiting for their turn, and the playout clock
        self._pending: deque[tuple[float, BeamState, np.ndarray | None]] = deque(maxlen=MAX_PENDING)
        self._sensors: dict[str, str] = {}
        self._arrivals: deque[tuple[float, float]] = deque(maxlen=8)  # (monotonic s, newest data t)
        self._clock: tuple[float, float, float] | None = None  # (wall0, data0, data s per wall s)
        self._newest_t = -math.inf

    def width_at(self, eta: np.ndarray) -> np.ndarray:
        """The drawn width (m) at arc lengths ``eta``: the sheet's width, or the section's size across
        the beam varying linearly along each taper (the section beyond a step at the step)."""
        eta = np.atleast_1d(np.asarray(eta, dtype=float))
        sections = self.rig.beam.sections
        if not sections:
            return np.full(eta.shape, self.width)
        positions = np.array([s.position for s in sections], dtype=float)
        sizes = np.array([_section_width(s) for s in sections], dtype=float)
        last = len(sections) - 1
        j = np.clip(np.searchsorted(positions, eta, side="right") - 1, 0, last)
        k = np.minimum(j + 1, last)
        span = positions[k] - positions[j]
        t = np.where(span > 0, (eta - positions[j]) / np.where(span > 0, span, 1.0), 0.0)
        return sizes[j] + np.clip(t, 0.0, 1.0) * (sizes[k] - sizes[j])
    def _set_estimate(self, est: Estimate) -> None:
        store = self.store
        with store.lock:
            prev = store.estimate
            t, state = est.t_s, est.state
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
            store.drawn_times.append(time.monotonic())

    def set_spectra(self, spectrum: SpectrumDocument) -> None:
        """The latest window's spectra. Raises ValueError for a spectrum of another Γ."""
        rec = spectra_record(spectrum, self.gamma)
        with self.store.lock:
            self.store.spectra = rec
            self.store.spectra_version += 1

    def add_window(self, window: WindowDocument) -> None:
        """A committed window's figures (its curvature profile along ``stations``): replaces the
        record the trend rows gave of the same window. Raises ValueError naming what does not fit."""
        rec = window_record(window, n_stations=self.stations.size)
        with self.store.lock:
            windows = self.store.windows
            if windows and any(w.start_s == rec.start_s for w in windows):
                kept = [rec if w.start_s == rec.start_s else w for w in windows]
                windows.clear()
                windows.extend(kept)
                self.store.windows_tuple = tuple(windows)
                self.store.windows_version += 1
                return
        self.add_windows([rec])

    def upsert_alarm(self, alarm: AlarmDocument) -> bool:
        """An alarm read (or acknowledged); True when it newly became active."""
        if not isinstance(alarm, AlarmDocument):
            raise ValueError(f"alarm must be a contract.AlarmDocument, got {type(alarm).__name__}")
        return self.store.upsert_alarm(alarm)

    def set_loads(self, loads: LoadsRecord | None, error: str | None = None) -> None:
        """The structure's fatigue (None with ``error``: it could not be read; the last one is kept)."""
        with self.store.lock:
            if loads is not None:
                self.store.loads = loads
            self.store.loads_error = error
            self.store.loads_version += 1

    def add_windows(self, records: list[WindowRecord]) -> None:
        store = self.store
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

    @property
    def last_window_start_s(self) -> float | None:
        with self.store.lock:
            return max((w.start_s for w in self.store.windows), default=None)

    # ------------------------------------------------------------------ live estimates
    def add_live(self, doc: LiveEstimatesDocument, now: float | None = None) -> None:
        """Estimates polled from the service (newest after the last seq): queued for ``play``.
        Raises ValueError when they are not in this feed's state layout."""
        if tuple(doc.state_names) != tuple(self.layout.names):
            raise ValueError(f"live estimates of {doc.source!r} have the states {doc.state_names}, the model drawn "
                             f"has {list(self.layout.names)}")
        _check_sensor_states(doc.sensors)
        now = time.monotonic() if now is None else now
        with self.store.lock:
            self._sensors = dict(doc.sensors)
            if doc.loads_angles_deg:  # a biaxial beam: the angle each hot spot is evaluated at
                self._angles = {n: float(a) for n, a in zip(doc.loads_station_names, doc.loads_angles_deg) if n}
            truths = doc.truth_deflection or [None] * len(doc.t_s)
            fresh = [(t, x, true) for t, x, true in zip(doc.t_s, doc.x, truths) if t > self._newest_t]
            for t, x, true in fresh:
                self._pending.append((float(t), parse_state(np.asarray(x, dtype=float), self.layout), self._truth(true)))
            if not fresh:
                return
            self._newest_t = fresh[-1][0]
            self._arrivals.append((now, self._newest_t))
            self._retime(now)

    def hot_spot_angles(self) -> dict[str, float]:
        """Per hot spot the angle around the section (degrees) the service evaluates its live loads
        at, an "all" one's worst found (a biaxial beam; empty until its live estimates came)."""
        with self.store.lock:
            return dict(self._angles)

    def _truth(self, values: list[float] | None) -> np.ndarray | None:
        """A simulation's true deflection at the stations (None: none, or not one per station)."""
        if values is None or len(values) != self.stations.size:
            return None
        return np.asarray(values, dtype=float)

    def _retime(self, now: float) -> None:
        """Play at the data's pace (data s per wall s, over the last arrivals), about one batch behind."""
        (w0, t0), (w1, t1) = self._arrivals[0], self._arrivals[-1]
        rate = (t1 - t0) / (w1 - w0) if w1 - w0 > 1.0 and t1 > t0 else 1.0
        rate = min(max(rate, 0.05), 1000.0)
        span = self._pending[-1][0] - self._pending[0][0] if self._pending else 0.0
        lead = max(0.5, min(span, 10.0 * rate))  # how far behind the newest estimate the picture plays
        if self._clock is None:
            self._clock = (now, t1 - lead, rate)
            return
        played = self._played_t(now)
        if not (t1 - 3 * lead <= played <= t1):  # fell far behind, or ran ahead of the data: start over
            self._clock = (now, t1 - lead, rate)
        elif abs(rate - self._clock[2]) > 0.05 * rate:
            self._clock = (now, played, rate)

    def _played_t(self, now: float) -> float:
        wall0, data0, rate = self._clock  # type: ignore[misc]
        return data0 + rate * (now - wall0)

    def play(self, now: float | None = None) -> None:
        """Draw the newest queued estimate whose data time has come."""
        now = time.monotonic() if now is None else now
        with self.store.lock:
            if self._clock is None or not self._pending:
                return
            due = self._played_t(now)
            item = None
            while self._pending and self._pending[0][0] <= due:
                item = self._pending.popleft()
            sensors = self._sensors
        if item is not None:
            self._set_estimate(Estimate(item[0], item[1], sensors, item[2]))

    # ------------------------------------------------------------------ reading
    def snapshot(self) -> Snapshot:
        return self.store.snapshot()

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


def _check_sensor_states(sensor_states: Any) -> None:
    if not isinstance(sensor_states, dict):
        raise ValueError(f"sensor_states must be a dict topic -> state, got {type(sensor_states).__name__}")
    for topic, value in sensor_states.items():
        if value not in SENSOR_STATES:
            raise ValueError(f"sensor_states[{topic!r}]={value!r} must be one of {SENSOR_STATES}")
