"""Data the dashboard shows, read from the contract's documents (pure Python/numpy).

The service hands over typed documents (``contract.WindowDocument``, ``SpectrumDocument``,
``AlarmDocument``, ``TrendRow``, ``StatusDocument``): one spelling per key. Here they become the
per-mode records the plots draw, and are checked where a wrong value would draw a wrong picture
(a spectrum of another Γ, a curvature profile of another station count).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from contract import (
    BaselineModeDocument,
    FatigueDocument,
    HotSpotLoadsDocument,
    SpectrumDocument,
    ThresholdsDocument,
    TrendRow,
    WindowDocument,
)

__all__ = [
    "BAND_SIGMA",
    "LoadsRecord",
    "SpectraRecord",
    "WindowRecord",
    "baseline_band",
    "frequencies_of",
    "loads_record",
    "spectra_record",
    "spectrum_plot",
    "thresholds_of",
    "window_record",
    "windows_from_trend_rows",
]

#: Width of the baseline band drawn around the expected frequency, in σ of one window's estimate.
BAND_SIGMA = 2.0


@dataclass
class WindowRecord:
    """One analysis window, per eigenmode (1-based mode number) frequency, damping, score, level."""

    start_s: float
    end_s: float
    kind: str | None = None
    trusted: bool | None = None
    temperature_c: float | None = None
    frequency_hz: dict[int, float | None] = field(default_factory=dict)
    damping_ratio: dict[int, float | None] = field(default_factory=dict)
    score_sigma: dict[int, float | None] = field(default_factory=dict)
    level: dict[int, str | None] = field(default_factory=dict)
    curvature_total: float | None = None
    curvature_score_sigma: float | None = None
    curvature_level: str | None = None
    curvature_profile: np.ndarray | None = None
    curvature_eta_m: float | None = None
    curvature_third: str | None = None
    #: (warning, alarm) σ of the charts this window judged, by chart kind ("frequency", "curvature")
    levels_sigma: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def t_s(self) -> float:
        """The time the window is plotted at: its end (the instant its figures are known)."""
        return self.end_s


def window_record(window: WindowDocument, *, n_stations: int | None = None) -> WindowRecord:
    """A live window. Raises ValueError when its curvature profile does not have one value per
    station (``n_stations``)."""
    if not isinstance(window, WindowDocument):
        raise ValueError(f"window must be a contract.WindowDocument, got {type(window).__name__}")
    rec = WindowRecord(start_s=window.start_s, end_s=window.end_s, kind=window.kind, trusted=window.trusted,
                       temperature_c=window.temperature_c)
    for m in window.modes:
        rec.frequency_hz[m.mode] = m.frequency_hz
        rec.damping_ratio[m.mode] = m.damping_ratio
        rec.score_sigma[m.mode] = m.score_sigma
        rec.level[m.mode] = m.level
    c = window.curvature
    if c is not None:
        profile = np.array([np.nan if v is None else v for v in c.index], dtype=float)
        if n_stations is not None and profile.size != n_stations:
            raise ValueError(f"window curvature index has {profile.size} values, expected one per station ({n_stations})")
        rec.curvature_profile = profile if profile.size else None
        rec.curvature_total = c.total
        rec.curvature_score_sigma = c.score_sigma
        rec.curvature_eta_m = c.eta_m
        rec.curvature_third = c.third
    for chart in window.charts:
        if chart.kind == "curvature":
            rec.curvature_level = chart.level
        rec.levels_sigma.setdefault(chart.kind, (chart.warning_sigma, chart.alarm_sigma))
    return rec


def windows_from_trend_rows(rows: Iterable[TrendRow]) -> list[WindowRecord]:
    """Group trend rows (one per window and mode, as ``GET /api/trends``) into window records."""
    grouped: dict[tuple[str, float], WindowRecord] = {}
    for row in rows:
        key = (row.source, row.window_start_s)
        rec = grouped.get(key)
        if rec is None:
            rec = grouped[key] = WindowRecord(start_s=row.window_start_s, end_s=row.window_end_s, kind=row.kind,
                                              temperature_c=row.temperature_c, curvature_total=row.curvature_index)
        rec.frequency_hz[row.mode] = row.frequency_hz
        rec.damping_ratio[row.mode] = row.damping_ratio
        rec.score_sigma[row.mode] = row.score_sigma
        rec.level[row.mode] = row.level
        if rec.temperature_c is None:
            rec.temperature_c = row.temperature_c
        if rec.curvature_total is None:
            rec.curvature_total = row.curvature_index
    return sorted(grouped.values(), key=lambda r: r.t_s)


def thresholds_of(status_thresholds: ThresholdsDocument | None, windows: tuple[WindowRecord, ...]) -> dict[str, tuple[float, float]]:
    """(warning, alarm) σ to draw per chart kind: the service's configured levels, else those
    the latest live windows were judged against. A kind missing from both is absent (no line is
    drawn rather than a made-up one)."""
    if status_thresholds is not None:
        return {kind: (status_thresholds.of(kind).warning_sigma, status_thresholds.of(kind).alarm_sigma)
                for kind in ("frequency", "curvature")}
    out: dict[str, tuple[float, float]] = {}
    for rec in reversed(windows):
        for kind, levels in rec.levels_sigma.items():
            out.setdefault(kind, levels)
        if len(out) == 2:
            break
    return out


def baseline_band(mode: BaselineModeDocument, temperature_c: float | None, *, sigma: float = BAND_SIGMA) -> tuple[float, float, float]:
    """(expected, low, high) Hz of one mode: f = f_ref·(1 + slope·(T − T_ref)) ± sigma·sigma_rel·f_ref."""
    f_ref = mode.f_ref_hz
    expected = f_ref * (1.0 + mode.slope_per_k * (temperature_c - mode.temperature_ref_c)) if temperature_c is not None else f_ref
    half = sigma * mode.sigma_rel * f_ref
    return expected, expected - half, expected + half


@dataclass(frozen=True)
class SpectraRecord:
    frequencies_hz: np.ndarray
    amplitudes: np.ndarray  # (n_freq, Γ), |a| with undefined values 0
    tracked_hz: tuple[tuple[float, ...], ...]  # per unit deformation: its modes' frequencies
    baseline_hz: tuple[tuple[float, ...], ...]  # empty tuples before a baseline


def spectra_record(spectrum: SpectrumDocument, gamma: int) -> SpectraRecord:
    """A spectrum push for Γ = ``gamma`` unit deformations; ValueError for another Γ."""
    if not isinstance(spectrum, SpectrumDocument):
        raise ValueError(f"spectrum must be a contract.SpectrumDocument, got {type(spectrum).__name__}")
    f, a = spectrum.arrays()
    if a.shape[1] != gamma:
        raise ValueError(f"amplitudes must have shape (len(frequencies_hz), Γ) = {(f.size, gamma)}, got {a.shape}")
    baseline = spectrum.baseline_hz if spectrum.baseline_hz is not None else [[] for _ in range(gamma)]
    return SpectraRecord(f, np.where(np.isfinite(a), np.abs(a), 0.0), tuple(tuple(g) for g in spectrum.tracked_hz),
                         tuple(tuple(g) for g in baseline))


def frequencies_of(value: object) -> tuple[float, ...]:
    """One unit deformation's marker frequencies: None, a number, or several numbers (the
    combimode carries eigenmodes 1 and 2); non-finite entries are dropped."""
    if value is None:
        return ()
    items = value.tolist() if isinstance(value, np.ndarray) else value
    items = items if isinstance(items, (list, tuple)) else [items]
    out = []
    for item in items:
        if isinstance(item, (int, float, np.integer, np.floating)) and not isinstance(item, bool) and math.isfinite(float(item)):
            out.append(float(item))
    return tuple(out)


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


@dataclass(frozen=True)
class LoadsRecord:
    """A structure's fatigue as the Loads tab draws it (from a ``contract.FatigueDocument``).

    hot_spots : each hot spot's latest state (consumed life, rate, remaining life and verdict).
    positions_m, stress_range_max_pa, strain_range_max, strain_rms : the envelope along the beam
        (NaN where the service gave none).
    t_s : end of each counted window (UNIX s), oldest first.
    dels_pa : per Wöhler exponent (``"3"``, ``"5"``) and hot spot name, the window's DEL (Pa, NaN: none).
    consumed : per hot spot name, the consumed life D after each window.
    windows, truncated : the windows counted, and whether older ones were left out.
    """

    design_life_years: float | None
    hot_spots: tuple[HotSpotLoadsDocument, ...]
    positions_m: np.ndarray
    stress_range_max_pa: np.ndarray
    strain_range_max: np.ndarray
    strain_rms: np.ndarray
    t_s: np.ndarray
    dels_pa: dict[str, dict[str, np.ndarray]]
    consumed: dict[str, np.ndarray]
    windows: int
    truncated: bool


def _num(v: object) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(float(v)) else math.nan


def loads_record(doc: FatigueDocument) -> LoadsRecord:
    """The Loads tab's record of a structure's ``contract.FatigueDocument`` (its envelope sorted
    along the beam). Raises ValueError for anything else."""
    if not isinstance(doc, FatigueDocument):
        raise ValueError(f"fatigue must be a contract.FatigueDocument, got {type(doc).__name__}")
    envelope = sorted(doc.envelope, key=lambda e: e.position_m)
    windows, hot_spots = list(doc.windows), tuple(doc.hot_spots)
    design, total, truncated = doc.design_life_years, doc.total, doc.truncated
    names = [h.name for h in hot_spots]
    exponents = sorted({m for w in windows for h in w.hot_spots for m in h.del_pa}, key=float)
    dels = {m: {n: np.full(len(windows), math.nan) for n in names} for m in exponents}
    consumed = {n: np.full(len(windows), math.nan) for n in names}
    for k, w in enumerate(windows):
        for h in w.hot_spots:
            if h.name not in consumed:
                continue
            consumed[h.name][k] = _num(h.consumed)
            for m, v in h.del_pa.items():
                dels[m][h.name][k] = _num(v)
    return LoadsRecord(
        design_life_years=design, hot_spots=hot_spots,
        positions_m=np.array([_num(e.position_m) for e in envelope]),
        stress_range_max_pa=np.array([_num(e.stress_range_max_pa) for e in envelope]),
        strain_range_max=np.array([_num(e.strain_range_max) for e in envelope]),
        strain_rms=np.array([_num(e.strain_rms) for e in envelope]),
        t_s=np.array([_num(w.start_s) + _num(w.duration_s) for w in windows]),
        dels_pa=dels, consumed=consumed, windows=int(total), truncated=bool(truncated),
    )
