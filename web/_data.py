"""Data the dashboard shows, normalised from the service's JSON-like dicts (pure Python/numpy).

The service hands over plain dicts (``push_window``, ``push_alarm``, ``trends()``, ``alarms()``,
``status()``). They are read liberally (several spellings that the analytics and the HTTP API
use) but checked strictly where a wrong value would draw a wrong picture: a window needs a time,
an alarm needs an integer id, a spectrum needs matching shapes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from analytics import AnalysisConfig

__all__ = [
    "AlarmRecord",
    "DEFAULT_THRESHOLDS",
    "SpectraRecord",
    "WindowRecord",
    "baseline_band",
    "normalise_alarm",
    "normalise_spectra",
    "normalise_window",
    "spectrum_plot",
    "windows_from_trend_rows",
]

#: EWMA chart levels (σ of the EWMA) of ``analytics.AnalysisConfig`` when the service sends none.
DEFAULT_THRESHOLDS = AnalysisConfig().model_dump(include={"warning_sigma", "alarm_sigma", "curvature_alarm_sigma"})
#: Width of the baseline band drawn around the expected frequency, in σ of one window's estimate.
BAND_SIGMA = 2.0


def _num(value: Any) -> float | None:
    """A finite float or None (None, NaN, inf, non-numbers → None)."""
    if value is None or isinstance(value, bool):
        return None
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _first(d: dict, *keys: str) -> Any:
    for key in keys:
        if key in d and d[key] is not None:
            return d[key]
    return None


@dataclass
class WindowRecord:
    """One analysis window, per mode (1-based unit deformation χ) frequency, damping, score."""

    start_s: float
    end_s: float
    kind: str | None = None
    trusted: bool | None = None
    temperature_c: float | None = None
    frequency_hz: dict[int, float | None] = field(default_factory=dict)
    damping_ratio: dict[int, float | None] = field(default_factory=dict)
    score_sigma: dict[int, float | None] = field(default_factory=dict)
    expected_hz: dict[int, float | None] = field(default_factory=dict)
    band_hz: dict[int, tuple[float, float]] = field(default_factory=dict)
    curvature_total: float | None = None
    curvature_score_sigma: float | None = None
    curvature_profile: np.ndarray | None = None
    curvature_eta_m: float | None = None
    curvature_third: str | None = None
    levels: dict[str, str] = field(default_factory=dict)
    thresholds: dict[str, float] = field(default_factory=dict)

    @property
    def t_s(self) -> float:
        """The time the window is plotted at: its end (the instant its figures are known)."""
        return self.end_s


def _profile(value: Any, n_stations: int | None) -> np.ndarray | None:
    if value is None or np.isscalar(value):
        return None
    arr = np.asarray(value, dtype=float).ravel()
    if arr.size == 0:
        return None
    if n_stations is not None and arr.size != n_stations:
        raise ValueError(f"window curvature index has {arr.size} values, expected one per station ({n_stations})")
    return arr


def normalise_window(window: dict, *, n_stations: int | None = None) -> WindowRecord:
    """Read one window dict (``WindowResult.as_dict()`` style, or a trend row, or the service's
    per-window dict with ``modes`` entries) into a :class:`WindowRecord`."""
    if not isinstance(window, dict):
        raise ValueError(f"window must be a dict, got {type(window).__name__}")
    start = _num(_first(window, "start_s", "window_start_s"))
    end = _num(_first(window, "end_s", "window_end_s"))
    if start is None and end is None:
        raise ValueError("window needs a finite start_s or end_s (or window_start_s/window_end_s)")
    start = end if start is None else start
    end = start if end is None else end
    rec = WindowRecord(start_s=start, end_s=end)
    rec.kind = window.get("kind") if isinstance(window.get("kind"), str) else None
    rec.trusted = bool(window["trusted"]) if isinstance(window.get("trusted"), bool) else None
    rec.temperature_c = _num(_first(window, "temperature_c", "temperature"))

    entries: list[dict] = []
    if isinstance(window.get("modes"), (list, tuple)):
        entries = [m for m in window["modes"] if isinstance(m, dict)]
    elif "mode" in window:  # a trend row: one mode
        entries = [window]
    scores = window.get("frequency_scores_sigma")
    for position, entry in enumerate(entries):
        mode = _first(entry, "mode", "unit")
        if isinstance(mode, bool) or not isinstance(mode, (int, np.integer, float)) or int(mode) != mode or mode < 1:
            raise ValueError(f"window mode entry {position} has no valid 1-based 'mode': {mode!r}")
        mode = int(mode)
        rec.frequency_hz[mode] = _num(_first(entry, "frequency_hz", "frequency"))
        rec.damping_ratio[mode] = _num(_first(entry, "damping_ratio", "damping"))
        score = _first(entry, "score_sigma", "frequency_score_sigma", "score")
        if score is None and isinstance(scores, (list, tuple)) and position < len(scores):
            score = scores[position]
        rec.score_sigma[mode] = _num(score)
        rec.expected_hz[mode] = _num(_first(entry, "expected_hz", "baseline_hz", "f_expected_hz"))
        band = entry.get("band_hz")
        if isinstance(band, (list, tuple)) and len(band) == 2 and all(_num(v) is not None for v in band):
            rec.band_hz[mode] = (float(min(band)), float(max(band)))

    curvature = window.get("curvature")
    if isinstance(curvature, dict):
        rec.curvature_profile = _profile(_first(curvature, "index", "profile"), n_stations)
        rec.curvature_total = _num(curvature.get("total"))
        rec.curvature_eta_m = _num(curvature.get("eta_m"))
        third = curvature.get("third")
        rec.curvature_third = third if isinstance(third, str) else None
    index = window.get("curvature_index")
    if index is not None and not np.isscalar(index):
        rec.curvature_profile = _profile(index, n_stations)
    elif index is not None:
        rec.curvature_total = _num(index)
    profile = _first(window, "curvature_profile", "curvature_index_profile")
    if profile is not None:
        rec.curvature_profile = _profile(profile, n_stations)
    if rec.curvature_total is None and rec.curvature_profile is not None and np.all(np.isfinite(rec.curvature_profile)):
        rec.curvature_total = float(np.sqrt(np.mean(rec.curvature_profile**2)))
    rec.curvature_score_sigma = _num(window.get("curvature_score_sigma"))
    rec.curvature_eta_m = _num(window.get("curvature_eta_m")) if rec.curvature_eta_m is None else rec.curvature_eta_m
    third = window.get("curvature_third")
    if isinstance(third, str):
        rec.curvature_third = third
    if isinstance(window.get("levels"), dict):
        rec.levels = {str(k): str(v) for k, v in window["levels"].items()}
    if isinstance(window.get("thresholds"), dict):
        rec.thresholds = {str(k): float(v) for k, v in window["thresholds"].items() if _num(v) is not None}
    return rec


def windows_from_trend_rows(rows: Iterable[dict], *, n_stations: int | None = None) -> list[WindowRecord]:
    """Group trend rows (one per window and mode, as ``GET /api/trends``) into window records.

    Rows that cannot be read are skipped (history is best effort; live windows are strict)."""
    grouped: dict[tuple[Any, Any], WindowRecord] = {}
    for row in rows:
        try:
            rec = normalise_window(row, n_stations=n_stations)
        except ValueError:
            continue
        key = (row.get("source"), rec.start_s)
        if key not in grouped:
            grouped[key] = rec
            continue
        merged = grouped[key]
        for name in ("frequency_hz", "damping_ratio", "score_sigma", "expected_hz", "band_hz"):
            getattr(merged, name).update(getattr(rec, name))
        for name in ("temperature_c", "curvature_total", "curvature_profile", "curvature_eta_m", "curvature_third"):
            if getattr(merged, name) is None:
                setattr(merged, name, getattr(rec, name))
    return sorted(grouped.values(), key=lambda r: r.t_s)


def baseline_band(baseline_mode: dict, temperature_c: float | None, *, sigma: float = BAND_SIGMA) -> tuple[float, float, float] | None:
    """(expected, low, high) Hz of one mode from a baseline entry (``analytics.BaselineMode``
    fields): f = f_ref·(1 + slope·(T − T_ref)) ± sigma·sigma_rel·f_ref."""
    f_ref = _num(baseline_mode.get("f_ref_hz"))
    if f_ref is None:
        return None
    slope = _num(baseline_mode.get("slope_per_k")) or 0.0
    t_ref = _num(baseline_mode.get("temperature_ref_c"))
    sigma_rel = _num(baseline_mode.get("sigma_rel")) or 0.0
    expected = f_ref * (1.0 + slope * (temperature_c - t_ref)) if temperature_c is not None and t_ref is not None else f_ref
    half = sigma * sigma_rel * f_ref
    return expected, expected - half, expected + half


@dataclass
class AlarmRecord:
    id: int
    level: str
    state: str  # "active" | "cleared"
    acknowledged: bool
    mode: Any
    message: str
    since_s: float | None
    cleared_s: float | None
    raw: dict

    @property
    def active(self) -> bool:
        return self.state == "active"


def normalise_alarm(alarm: dict) -> AlarmRecord:
    """Read an alarm dict (push or ``alarms()`` item); raises ValueError without an integer id."""
    if not isinstance(alarm, dict):
        raise ValueError(f"alarm must be a dict, got {type(alarm).__name__}")
    alarm_id = alarm.get("id")
    if isinstance(alarm_id, bool) or not isinstance(alarm_id, (int, np.integer)):
        if isinstance(alarm_id, str) and alarm_id.strip().isdigit():
            alarm_id = int(alarm_id)
        else:
            raise ValueError(f"alarm needs an integer 'id', got {alarm_id!r}")
    level = str(alarm.get("level") or "alarm")
    if level not in ("warning", "alarm"):
        raise ValueError(f"alarm {alarm_id}: level must be 'warning' or 'alarm', got {level!r}")
    raw_state = str(alarm.get("state") or "active")
    if raw_state not in ("raised", "active", "cleared", "acknowledged"):
        raise ValueError(f"alarm {alarm_id}: unknown state {raw_state!r}")
    cleared_s = _num(alarm.get("cleared_at_s"))
    state = "cleared" if raw_state == "cleared" or cleared_s is not None else "active"
    acknowledged = raw_state == "acknowledged" or alarm.get("acknowledged_at_s") is not None
    message = alarm.get("message")
    return AlarmRecord(
        id=int(alarm_id),
        level=level,
        state=state,
        acknowledged=bool(acknowledged),
        mode=alarm.get("mode"),
        message=str(message) if message is not None else "",
        since_s=_num(_first(alarm, "since_s", "raised_at_s")),
        cleared_s=cleared_s,
        raw=dict(alarm),
    )


@dataclass(frozen=True)
class SpectraRecord:
    frequencies_hz: np.ndarray
    amplitudes: np.ndarray  # (n_freq, Γ)
    tracked_hz: tuple[tuple[float, ...], ...]  # per unit deformation: its modes' frequencies
    baseline_hz: tuple[tuple[float, ...], ...]


def frequencies_of(value: object) -> tuple[float, ...]:
    """One unit deformation's marker frequencies: None, a number, or several numbers (the
    combimode carries eigenmodes 1 and 2); non-finite entries are dropped."""
    if value is None:
        return ()
    items = value.tolist() if isinstance(value, np.ndarray) else value
    items = items if isinstance(items, (list, tuple)) else [items]
    out = []
    for item in items:
        f = _num(item)
        if f is not None:
            out.append(f)
    return tuple(out)


def normalise_spectra(frequencies_hz: object, amplitudes: object, tracked_hz: object, baseline_hz: object, gamma: int) -> SpectraRecord:
    """Check a spectra push: frequencies (n,) increasing, amplitudes (n, Γ), two lists of Γ."""
    f = np.asarray(frequencies_hz, dtype=float)
    a = np.asarray(amplitudes, dtype=float)
    if f.ndim != 1 or f.size < 2:
        raise ValueError(f"frequencies_hz must be 1-D with at least 2 values, got shape {f.shape}")
    if a.ndim == 1 and gamma == 1:
        a = a[:, None]
    if a.shape != (f.size, gamma):
        raise ValueError(f"amplitudes must have shape (len(frequencies_hz), Γ) = {(f.size, gamma)}, got {a.shape}")
    if not np.all(np.isfinite(f)) or np.any(np.diff(f) <= 0):
        raise ValueError("frequencies_hz must be finite and strictly increasing")
    lists = []
    for name, values in (("tracked_hz", tracked_hz), ("baseline_hz", baseline_hz)):
        if values is None:
            values = [None] * gamma
        if isinstance(values, np.ndarray):
            values = values.tolist()
        if not isinstance(values, (list, tuple)) or len(values) != gamma:
            raise ValueError(f"{name} must be a list of Γ={gamma} entries (a frequency, several, or None), got {values!r}")
        lists.append(tuple(frequencies_of(v) for v in values))
    a = np.where(np.isfinite(a), np.abs(a), 0.0)
    return SpectraRecord(f.copy(), a.copy(), lists[0], lists[1])


def spectrum_plot(
    frequencies_hz: np.ndarray,
    amplitude: np.ndarray,
    tracked_hz: object,
    baseline_hz: object,
    *,
    f_max: float | None = None,
    max_points: int = 1500,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """uPlot data (x, amplitude, tracked marker, baseline marker) for one mode.

    uPlot's aligned mode shares one x for all series, so the markers are drawn as narrow spikes:
    three x points f−ε, f, f+ε are inserted per marker, the marker series sits on the floor of the
    (log) scale everywhere except at f, where it reaches the top of the spectrum.
    """
    f = np.asarray(frequencies_hz, dtype=float)
    a = np.asarray(amplitude, dtype=float)
    if f_max is not None:
        keep = f <= f_max
        if keep.sum() >= 2:
            f, a = f[keep], a[keep]
    if f.size > max_points:  # decimate by taking the max in blocks: keeps the peaks
        block = int(math.ceil(f.size / max_points))
        n = (f.size // block) * block
        idx = np.arange(n).reshape(-1, block)
        best = idx[np.arange(idx.shape[0]), np.argmax(a[:n].reshape(-1, block), axis=1)]
        f, a = f[best], a[best]
    positive = a[a > 0]
    top = float(positive.max()) if positive.size else 1.0
    floor = max(float(positive.min()) if positive.size else top * 1e-4, top * 1e-4)
    a = np.maximum(a, floor)
    step = float(np.min(np.diff(f))) if f.size > 1 else 1.0
    eps = 0.05 * step
    tracked, baseline = frequencies_of(tracked_hz), frequencies_of(baseline_hz)
    markers = [m for m in (*tracked, *baseline) if f[0] <= m <= f[-1]]
    extra = np.array([m + o for m in markers for o in (-eps, 0.0, eps)], dtype=float)
    x = np.union1d(f, extra) if extra.size else f
    y = np.exp(np.interp(x, f, np.log(a)))

    def spike(ms: tuple[float, ...], height: float) -> np.ndarray:
        s = np.full(x.shape, floor)
        for m in ms:
            if f[0] <= m <= f[-1]:
                s[np.argmin(np.abs(x - m))] = height
        return s

    return x, y, spike(tracked, top * 1.5), spike(baseline, top * 1.2)
