"""One browser's live plots of the structure shown: the spectra of b and the modal trends (uPlot)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ._data import frequencies_of, spectrum_plot
from ._html import SPECTRA_INTRO, message_html, trend_info_html

if TYPE_CHECKING:
    from ._context import ViewSettings
    from ._feed import Snapshot, StructureFeed

__all__ = ["SpectraPanel", "TrendsPanel", "scales_of", "threshold_lines", "threshold_series"]

MODE_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
MAX_TREND_POINTS = 2000
#: uPlot draws NaN as missing points (canvas ignores non-finite coordinates).
NAN = float("nan")


def colour(index: int) -> str:
    return MODE_COLOURS[(index - 1) % len(MODE_COLOURS)]


def arr(values: list[float | None]) -> np.ndarray:
    return np.array([NAN if v is None else v for v in values], dtype=float)


def threshold_series(levels: tuple[float, float] | None = None) -> tuple[dict, ...]:
    """The four level lines of a control chart; their legend names the levels (σ) in force."""
    warning, alarm = ("?", "?") if levels is None else (f"{levels[0]:g}", f"{levels[1]:g}")
    return (
        {"label": f"warning +{warning} σ", "stroke": "#ffaa00", "dash": (6, 4), "width": 1},
        {"label": f"warning −{warning} σ", "stroke": "#ffaa00", "dash": (6, 4), "width": 1},
        {"label": f"alarm +{alarm} σ", "stroke": "#dc2626", "dash": (6, 4), "width": 1.5},
        {"label": f"alarm −{alarm} σ", "stroke": "#dc2626", "dash": (6, 4), "width": 1.5},
    )


def threshold_lines(levels: tuple[float, float] | None, n: int) -> tuple[np.ndarray, ...]:
    """±warning, ±alarm as constant series (NaN, i.e. not drawn, while the levels are unknown)."""
    warning, alarm = levels if levels is not None else (NAN, NAN)
    ones = np.ones(n)
    return warning * ones, -warning * ones, alarm * ones, -alarm * ones


def scales_of(time_axis: bool, *ys: np.ndarray, log: bool = False) -> dict:
    """uPlot scales with the y range of the finite values of ``ys`` (5 % margin). uPlot's own
    autoscale takes NaN, the gap of a missing value, as a number and then draws nothing."""
    values = np.concatenate([np.asarray(y, dtype=float).ravel() for y in ys]) if ys else np.zeros(0)
    values = values[np.isfinite(values)]
    scales: dict = {"x": {"time": time_axis}}
    if values.size:
        lo, hi = float(values.min()), float(values.max())
        pad = 0.05 * (hi - lo) if hi > lo else max(abs(hi) * 0.05, 1e-12)
        scales["y"] = {"auto": False, "range": [lo - pad, hi + pad]}
    return scales


def set_scales(plot: Any, scales: dict) -> None:
    if plot.scales != scales:
        plot.scales = scales


def _plot(gui: Any, data: tuple, series: tuple, title: str, height: int, **kwargs: Any) -> Any:
    """A uPlot with a plain x axis and a legend that does not follow the cursor, hidden until drawn."""
    return gui.add_uplot(data=data, series=series, scales={"x": {"time": False}}, title=title, height=height,
                         visible=False, legend={"live": False}, **kwargs)


class SpectraPanel:
    """Amplitude spectra of b1..bΓ of the latest window with the tracked and baseline frequencies."""

    def __init__(self, gui: Any, feed: "StructureFeed") -> None:
        self.feed = feed
        gui.add_markdown(SPECTRA_INTRO)
        self.plots: dict[int, Any] = {}
        f = np.linspace(0.0, self.f_max(), 200)
        for unit in range(1, feed.gamma + 1):
            x, y, tr, bl = spectrum_plot(f, np.ones(f.size), None, self.model_freqs(unit))
            self.plots[unit] = gui.add_uplot(
                data=(x, y, tr, bl), series=self.series(unit, None, self.model_freqs(unit)),
                scales={"x": {"time": False}, "y": {"distr": 3}}, title=self.unit_label(unit), height=150,
                padding=(12, 16, 0, 0), axes=({"ticks": {"show": False}}, {"size": 52, "ticks": {"show": False}}),
                legend={"show": True, "live": False},
            )

    def unit_label(self, unit: int) -> str:
        """``b1 · mode 1+2 (0.30, 0.86 Hz model)``: the spectra's and the mode switches' label."""
        label = self.feed.mode_map.unit_label(unit)
        freqs = self.model_freqs(unit)
        return f"{label} ({', '.join(f'{f:.2f}' for f in freqs)} Hz model)" if freqs else label

    def model_freqs(self, unit: int) -> tuple[float, ...]:
        try:
            return tuple(float(f) for f in self.feed.units.frequencies_hz[unit - 1])
        except (AttributeError, IndexError, TypeError, ValueError):
            return ()

    def f_max(self) -> float:
        freqs = [fs[-1] for fs in (self.model_freqs(u) for u in range(1, self.feed.gamma + 1)) if fs]
        return 1.4 * max(freqs) if freqs else 10.0

    def series(self, unit: int, tracked: object, baseline: object) -> tuple:
        c = colour(unit)

        def label(values: object) -> str:
            fs = frequencies_of(values)
            return " / ".join(f"{f:.3f}" for f in fs) if fs else "–"

        return (
            {"label": "Hz"},
            {"label": f"|b{unit}| µm", "stroke": c, "width": 1.5, "fill": c + "22"},
            {"label": f"tracked {label(tracked)} Hz", "stroke": "#111111", "width": 1.5, "points": {"show": False}},
            {"label": f"baseline {label(baseline)} Hz", "stroke": "#2e8b57", "width": 1.5, "dash": (5, 4), "points": {"show": False}},
        )

    def show_units(self, units: set[int]) -> None:
        for unit, plot in self.plots.items():
            plot.visible = unit in units

    def render(self, snap: "Snapshot", units: set[int]) -> None:
        spec = snap.spectra
        if spec is None:
            return
        f_max = max(self.f_max(), 1.2 * max([f for fs in (*spec.tracked_hz, *spec.baseline_hz) for f in fs] or [0.0]))
        for unit, plot in self.plots.items():
            if unit not in units:
                continue
            tracked, baseline = spec.tracked_hz[unit - 1], spec.baseline_hz[unit - 1]
            plot.data = spectrum_plot(spec.frequencies_hz, 1e6 * spec.amplitudes[:, unit - 1], tracked, baseline, f_max=f_max)
            series = self.series(unit, tracked, baseline)
            if plot.series != series:
                plot.series = series


class TrendsPanel:
    """Eigenfrequencies with their baseline bands, damping, control charts, temperature and the
    curvature-change index (along the beam and over time), over the chosen trend window."""

    def __init__(self, gui: Any, feed: "StructureFeed") -> None:
        self.feed = feed
        self.drawn_thresholds: dict[str, tuple[float, float]] | None = None
        self.time_axis = False
        self.info = gui.add_html(message_html("Waiting for the first analysis window…"))
        mm, modes = feed.mode_map, feed.mode_map.modes
        x0, z = np.array([0.0, 1.0]), np.zeros(2)
        self.freq_plots = {mode: _plot(
            gui, (x0, z, z, z, z),
            ({"label": "time"}, {"label": f"f{mode} Hz", "stroke": colour(mode), "width": 2, "points": {"show": True, "size": 4}},
             {"label": "expected", "stroke": "#2e8b57", "width": 1, "dash": (6, 4)},
             {"label": "band −", "stroke": "rgba(46,139,87,0.4)", "width": 1},
             {"label": "band +", "stroke": "rgba(46,139,87,0.4)", "width": 1}),
            f"{mm.mode_label(mode)} eigenfrequency (Hz) with baseline band", 140,
            bands=({"series": (4, 3), "fill": "rgba(46,139,87,0.15)"},)) for mode in modes}
        self.damping = _plot(gui, (x0,) + (z,) * len(modes), ({"label": "time"},) + tuple(
            {"label": f"ζ {mm.mode_label(m)} %", "stroke": colour(m), "width": 1.5, "points": {"show": True, "size": 4}}
            for m in modes), "Damping ratio (%)", 150)
        self.score = _plot(gui, (x0,) + (z,) * (len(modes) + 4), ({"label": "time"},) + tuple(
            {"label": f"{mm.mode_label(m)} σ", "stroke": colour(m), "width": 1.5} for m in modes) + threshold_series(),
            "Frequency control charts: EWMA score (σ) and alarm thresholds", 170)
        self.temperature = _plot(gui, (x0, z), ({"label": "time"}, {"label": "T °C", "stroke": "#b45309", "width": 1.5}),
                                 "Temperature (°C)", 120)
        st = feed.stations
        self.curv_profile = _plot(gui, (st, np.zeros(st.size), np.zeros(st.size)), (
            {"label": "η m"}, {"label": "latest", "stroke": "#7c3aed", "width": 2, "points": {"show": True, "size": 5}},
            {"label": "max in range", "stroke": "#a78bfa", "width": 1, "dash": (4, 3)}),
            "Curvature-change index along the beam (η from the bearing, m)", 150)
        self.curv_trend = _plot(gui, (x0, z), ({"label": "time"}, {
            "label": "index (RMS)", "stroke": "#7c3aed", "width": 1.5, "points": {"show": True, "size": 4}}),
            "Curvature-change index over time", 120)
        self.curv_score = _plot(gui, (x0, z, z, z, z, z), ({"label": "time"}, {
            "label": "curvature σ", "stroke": "#7c3aed", "width": 1.5}) + threshold_series(),
            "Curvature control chart: score (σ) and alarm thresholds", 140)

    def render(self, snap: "Snapshot", settings: "ViewSettings") -> None:
        windows = snap.windows
        if not windows:
            return
        t_end = windows[-1].t_s
        shown = [w for w in windows if w.t_s >= t_end - settings.trend_window_s]
        if len(shown) > MAX_TREND_POINTS:  # keep the browser fast: thin evenly
            shown = shown[:: math.ceil(len(shown) / MAX_TREND_POINTS)]
        # trend x: UNIX seconds on a date axis; seconds since the start on a plain axis
        x = np.array([w.t_s for w in shown])
        self.time_axis = bool(x.size and x[-1] > 1e9)
        if x.size == 1:  # uPlot needs two x values to draw a range
            x = np.array([x[0] - 1.0, x[0]])
            shown = [shown[0], shown[0]]
        visible = {m for m in self.feed.mode_map.modes if self.feed.mode_map.unit_of(m) in settings.units_shown}
        th = self.drawn_thresholds = self.feed.thresholds(snap)
        self._render_modes(snap, shown, x, visible, th)
        self._render_curvature(shown, x, th)
        self.info.content = trend_info_html(windows[-1], len(windows), self.feed.mode_map)

    def _render_modes(self, snap: "Snapshot", shown: list, x: np.ndarray, visible: set[int],
                      th: dict[str, tuple[float, float]]) -> None:
        feed = self.feed
        for mode, plot in self.freq_plots.items():
            plot.visible = mode in visible
            if mode in visible:
                bands = [feed.band(snap, w, mode) for w in shown]
                plot.data = data = (x, arr([w.frequency_hz.get(mode) for w in shown]), arr([b[0] for b in bands]),
                                    arr([b[1] for b in bands]), arr([b[2] for b in bands]))
                set_scales(plot, scales_of(self.time_axis, *data[1:]))
        modes = feed.mode_map.modes
        damping = [arr([None if w.damping_ratio.get(m) is None else 100 * w.damping_ratio[m] for w in shown]) for m in modes]
        self.damping.data = (x, *damping)
        set_scales(self.damping, scales_of(self.time_axis, *damping))
        self.damping.visible = any(np.isfinite(d).any() for d in damping)
        scores = [arr([w.score_sigma.get(m) for w in shown]) for m in modes]
        levels_drawn = threshold_lines(th.get("frequency"), x.size)
        self.score.data = (x, *scores, *levels_drawn)
        set_scales(self.score, scales_of(self.time_axis, *scores, *levels_drawn))
        self.score.visible = any(np.isfinite(s).any() for s in scores)
        for plot, levels in ((self.damping, None), (self.score, th.get("frequency"))):
            series = list(plot.series)
            for i, m in enumerate(modes, start=1):
                if series[i].get("show", True) != (m in visible):
                    series[i] = {**series[i], "show": m in visible}
            if plot is self.score:
                series[len(modes) + 1:] = threshold_series(levels)
            if tuple(series) != tuple(plot.series):
                plot.series = tuple(series)
        temps = arr([w.temperature_c for w in shown])
        self.temperature.data = (x, temps)
        set_scales(self.temperature, scales_of(self.time_axis, temps))
        self.temperature.visible = bool(np.isfinite(temps).any())

    def _render_curvature(self, shown: list, x: np.ndarray, th: dict[str, tuple[float, float]]) -> None:
        totals = arr([w.curvature_total for w in shown])
        self.curv_trend.data = (x, totals)
        set_scales(self.curv_trend, scales_of(self.time_axis, totals))
        self.curv_trend.visible = bool(np.isfinite(totals).any())
        scores = arr([w.curvature_score_sigma for w in shown])
        self.curv_score.data = data = (x, scores, *threshold_lines(th.get("curvature"), x.size))
        set_scales(self.curv_score, scales_of(self.time_axis, *data[1:]))
        self.curv_score.visible = bool(np.isfinite(scores).any())
        series = (*self.curv_score.series[:2], *threshold_series(th.get("curvature")))
        if tuple(self.curv_score.series) != series:
            self.curv_score.series = series
        profiles = [w.curvature_profile for w in shown if w.curvature_profile is not None]
        if profiles:
            self.curv_profile.data = data = (self.feed.stations, profiles[-1], np.nanmax(np.array(profiles), axis=0))
            set_scales(self.curv_profile, scales_of(False, *data[1:]))
            self.curv_profile.visible = True
