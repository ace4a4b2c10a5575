"""ModalMonitor: window-by-window classification, tracking, curvature, baseline and control charts."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from contract import CURVATURE_CHART, chart_name

from ._chart import EwmaChart
from ._config import AnalysisConfig
from ._curvature import CurvatureChange, curvature_change, curvature_shape
from ._location import DamageLocation, locate_damage
from ._damping import _moving
from ._peaks import find_peaks
from ._spectrum import Spectrum, amplitude_spectrum, cross_spectra
from ._validate import as_signal, as_times, check_fs

__all__ = ["Baseline", "BaselineMode", "ModeEstimate", "WindowResult", "ModalMonitor", "fit_temperature_model"]

WINDOW_KINDS = ("forced", "free_decay", "ambient", "quiet")


def _none(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


@dataclass(frozen=True)
class ModeEstimate:
    """One mode in one window: frequency_hz (Hz, None if no peak), amplitude (unit of b), confidence 0..1."""

    mode: int
    unit: int
    frequency_hz: float | None
    amplitude: float | None
    confidence: float


@dataclass(frozen=True)
class BaselineMode:
    """Healthy reference of one mode: f = f_ref·(1 + slope·(T − T_ref)) ± sigma_rel·f_ref.

    f_ref_hz (Hz), temperature_ref_c (°C), slope_per_k (1/K, relative), sigma_rel (relative 1σ
    scatter of one window's estimate), rho (lag-1 correlation of successive windows' residuals).
    """

    mode: int
    unit: int
    f_ref_hz: float
    temperature_ref_c: float
    slope_per_k: float
    sigma_rel: float
    rho: float
    windows: int


@dataclass(frozen=True)
class Baseline:
    """A healthy baseline; ``to_dict``/``from_dict`` give a JSON-safe round trip for storage.

    modes : per mode the temperature model; curvature_shapes : (modes, len(η)) normalised
    operational curvature shapes (dimensionless); curvature_index_mean/std : the curvature
    statistic's healthy mean and std (1 and √(2/p) of the χ²/p statistic, p its degrees of
    freedom); curvature_index_rho : lag-1 correlation of successive windows' shape deviations;
    curvature_shape_std : (modes,) 1σ of one window's unit-RMS shape per station (pooled over
    η); curvature_windows : windows behind the baseline shapes; start_s/end_s : the learnt period (s).
    """

    modes: tuple[BaselineMode, ...]
    curvature_shapes: np.ndarray
    curvature_index_mean: float
    curvature_index_std: float
    curvature_index_rho: float
    start_s: float
    end_s: float
    curvature_shape_std: tuple[float, ...] = ()
    curvature_windows: int = 0

    def to_dict(self) -> dict:
        return {
            "modes": [vars(m) | {} for m in self.modes],
            "curvature_shapes": np.asarray(self.curvature_shapes).tolist(),
            "curvature_index_mean": self.curvature_index_mean,
            "curvature_index_std": self.curvature_index_std,
            "curvature_index_rho": self.curvature_index_rho,
            "start_s": self.start_s,
            "end_s": self.end_s,
            "curvature_shape_std": list(self.curvature_shape_std),
            "curvature_windows": self.curvature_windows,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Baseline":
        if not isinstance(d, dict):
            raise ValueError(f"baseline must be a dict, got {type(d).__name__}")
        try:
            return cls(
                tuple(BaselineMode(**m) for m in d["modes"]),
                np.asarray(d["curvature_shapes"], dtype=float),
                float(d["curvature_index_mean"]),
                float(d["curvature_index_std"]),
                float(d["curvature_index_rho"]),
                float(d["start_s"]),
                float(d["end_s"]),
                tuple(float(x) for x in d.get("curvature_shape_std", ())),
                int(d.get("curvature_windows", 0)),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"baseline dict is malformed: {exc}") from exc


@dataclass(frozen=True)
class WindowResult:
    """The figures of one analysis window.

    start_s/end_s (s), kind ("forced" | "free_decay" | "ambient" | "quiet"), trusted (used for
    eigenfrequencies), temperature_c (°C or None), estimates per mode, frequency_scores (EWMA
    score in σ per mode, None before a baseline), curvature (change against the baseline or
    None), curvature_score (σ), levels (chart name → "ok"/"warning"/"alarm"), flags (raised now),
    location (the model-assisted damage location of the change since the baseline, when damage
    signatures were given, else None).
    """

    start_s: float
    end_s: float
    kind: str
    trusted: bool
    temperature_c: float | None
    estimates: tuple[ModeEstimate, ...]
    frequency_scores: tuple[float | None, ...]
    curvature: CurvatureChange | None
    curvature_score: float | None
    levels: dict
    flags: tuple[dict, ...]
    location: DamageLocation | None = None

    def as_dict(self) -> dict:
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "kind": self.kind,
            "trusted": self.trusted,
            "temperature_c": _none(self.temperature_c),
            "modes": [
                {"mode": e.mode, "unit": e.unit, "frequency_hz": _none(e.frequency_hz), "amplitude": _none(e.amplitude), "confidence": round(e.confidence, 4)}
                for e in self.estimates
            ],
            "frequency_scores_sigma": [_none(s) for s in self.frequency_scores],
            "curvature_index": None if self.curvature is None else _none(self.curvature.total),
            "curvature_score_sigma": _none(self.curvature_score),
            "curvature_eta_m": None if self.curvature is None else self.curvature.eta_m,
            "curvature_third": None if self.curvature is None else self.curvature.third,
            "levels": dict(self.levels),
            "flags": [dict(f) for f in self.flags],
            "location": None if self.location is None else self.location.as_dict(),
        }


def fit_temperature_model(
    rel: np.ndarray, temperature: np.ndarray, prior_slope: float, prior_std: float
) -> tuple[float, float, float, float]:
    """MAP fit of rel = a + c·(T − T̄) with a Gaussian prior c ~ N(prior_slope, prior_std²) (1/K).

    rel (n,) relative frequency deviations, temperature (n,) °C. Returns (a, c, T̄, residual σ).
    The prior keeps the slope physical when the baseline spans a narrow temperature range.
    """
    r = as_signal("rel", rel, min_len=3, ndim=(1,))
    T = as_signal("temperature", temperature, min_len=3, ndim=(1,))
    if r.size != T.size:
        raise ValueError(f"rel ({r.size}) and temperature ({T.size}) must have equal length")
    if not prior_std > 0:
        raise ValueError(f"{prior_std=} must be > 0")
    tm = float(T.mean())
    dT = T - tm
    s2 = float(np.var(r)) or 1e-12
    for _ in range(3):
        c = (float(dT @ (r - r.mean())) / s2 + prior_slope / prior_std**2) / (float(dT @ dT) / s2 + 1 / prior_std**2)
        a = float(np.mean(r - c * dT))
        res = r - a - c * dT
        s2 = max(float(res @ res) / max(1, r.size - 1), 1e-14)
    return a, c, tm, math.sqrt(s2)


def _lag1(x: np.ndarray) -> float:
    if x.size < 4:
        return 0.0
    x = x - x.mean()
    den = float(x @ x)
    return float(np.clip((x[:-1] @ x[1:]) / den, 0.0, 0.95)) if den > 0 else 0.0


@dataclass
class _Record:
    t_mid: float
    temperature: float | None
    freqs: list
    confs: list


class ModalMonitor:
    """Incremental modal analytics, one window at a time.

    expected_hz : per unit deformation the expected eigenfrequencies (Hz), e.g.
        ((0.301, 0.859), (1.906,), (3.49,), (5.6,)); modes are numbered 1.. in this order.
    curvature_shapes : (len(η), Γ) s''_χ at stations_eta (1/m²); stations_eta (len(η),) m from the bearing.
    fs : sample rate of b (Hz); baseline : a stored Baseline, else one is learnt from the first
    ``config.baseline_s`` seconds of trusted windows; beam_length : m (default max(stations_eta));
    signatures : predicted damage signatures (``estimator.damage_signatures`` or an object/dict
    with eta, kind, frequency_shift (M, modes), curvature_change (M, modes, len(η)) at
    stations_eta) for the model-assisted location of a change; None: the model-free curvature
    index locates it.

    Per trusted window the mode frequencies are the peaks of the power spectra averaged over the
    last ``config.spectrum_memory_windows`` windows (EWMA), curvature shapes come from the cross
    spectra averaged over ``config.curvature_memory_windows``. The curvature chart watches
    Q = mean over modes and stations of (Δshape/σ)², Δshape the averaged shapes' change against
    the baseline's, σ its healthy scatter (a delete-one jackknife over the baseline's windows,
    scaled to the average's memory, floored by ``config.curvature_min_std``): Q ~ χ²_p/p for a
    healthy structure, charted as (Q − 1)/√(2/p) without further smoothing (hold and hysteresis
    as the frequency charts). Curvature shapes use stationary ('ambient') windows only.
    """

    def __init__(
        self,
        expected_hz: object,
        curvature_shapes: object,
        stations_eta: object,
        *,
        fs: float = 200.0,
        config: AnalysisConfig | None = None,
        baseline: Baseline | None = None,
        beam_length: float | None = None,
        signatures: object | None = None,
    ):
        self.fs = check_fs(fs)
        self.config = config or AnalysisConfig()
        if not isinstance(self.config, AnalysisConfig):
            raise ValueError(f"config must be an AnalysisConfig, got {type(self.config).__name__}")
        self.S = as_signal("curvature_shapes", curvature_shapes, min_len=2, ndim=(2,))
        self.eta = as_signal("stations_eta", stations_eta, min_len=2, ndim=(1,))
        if self.eta.size != self.S.shape[0]:
            raise ValueError(f"stations_eta has {self.eta.size} entries, curvature_shapes {self.S.shape[0]} rows")
        self.gamma = self.S.shape[1]
        self.length = float(beam_length if beam_length is not None else self.eta.max())
        if not self.length > 0:
            raise ValueError(f"beam_length={beam_length!r} must be > 0")
        self.units: list[int] = []
        self.f0: list[float] = []
        if expected_hz is not None:
            try:
                groups = [tuple(float(f) for f in g) for g in expected_hz]
            except TypeError as exc:
                raise ValueError(f"expected_hz={expected_hz!r} must be a sequence of sequences of Hz") from exc
            if len(groups) > self.gamma or any(not g for g in groups):
                raise ValueError(f"expected_hz has {len(groups)} groups for Γ={self.gamma} unit deformations (each non-empty)")
            for u, g in enumerate(groups):
                for f in g:
                    if not (math.isfinite(f) and 0 < f < self.fs / 2):
                        raise ValueError(f"expected_hz entry {f} Hz must be in (0, fs/2)")
                    self.units.append(u)
                    self.f0.append(f)
        self.ref = list(self.f0)
        self.baseline = baseline
        if baseline is not None and expected_hz is not None and len(baseline.modes) != len(self.f0):
            raise ValueError(f"baseline has {len(baseline.modes)} modes, expected_hz gives {len(self.f0)}")
        self._records: list[_Record] = []
        self._first_trusted: float | None = None
        self._cross = None  # (modes, Γ) complex EWMA of cross spectra
        self._cross_sum = None
        self._cross_windows = 0  # ambient windows in the EWMA (its scatter settles after the memory)
        self._ci_hist: list[float] = []
        self._charts: list[EwmaChart] = []
        self._ci_chart: EwmaChart | None = None
        self._alarms: dict = {}
        self._power = None  # EWMA of the trusted windows' power spectra
        self.signatures = signatures
        if signatures is not None:
            sc = signatures.get("curvature_change") if isinstance(signatures, dict) else getattr(signatures, "curvature_change", None)
            if sc is not None and np.shape(sc)[-1] != self.eta.size:
                raise ValueError(f"signatures.curvature_change has {np.shape(sc)[-1]} stations, stations_eta {self.eta.size}")
        if baseline is not None:
            self._arm(baseline)

    # -- set-up ----------------------------------------------------------------------------
    @property
    def n_modes(self) -> int:
        return len(self.ref)

    def _chart(self, inflation: float) -> EwmaChart:
        c = self.config
        warning, alarm = c.chart_levels("frequency")
        return EwmaChart(c.ewma_lambda, warning, alarm, c.clear_sigma, c.hold_windows, inflation)

    def _arm(self, baseline: Baseline) -> None:
        if not self.ref:
            self.units = [m.unit for m in baseline.modes]
            self.f0 = [m.f_ref_hz for m in baseline.modes]
            self.ref = list(self.f0)
        self._charts = [self._chart(math.sqrt((1 + m.rho) / (1 - m.rho))) for m in baseline.modes]
        c = self.config
        # the statistic already averages (cross spectra over curvature_memory_windows): no second EWMA
        warning, alarm = c.chart_levels("curvature")
        self._ci_chart = EwmaChart(1.0, warning, alarm, c.clear_sigma, c.hold_windows, 1.0)

    def _init_modes(self, spec) -> None:
        for u in range(self.gamma):
            pk = find_peaks(spec, column=u, fmin=2.0 / (spec.n_samples / self.fs) + 0.05, min_prominence=self.config.min_prominence)
            if pk:
                self.units.append(u)
                self.f0.append(pk[0].frequency_hz)
        self.ref = list(self.f0)

    # -- one window ------------------------------------------------------------------------
    def _classify(self, b: np.ndarray, bearing: np.ndarray | None) -> str:
        c = self.config
        rms = float(np.sqrt(np.mean((b - b.mean(axis=0)) ** 2)))
        if rms <= c.quiet_rms:
            return "quiet"
        if bearing is not None and np.mean(_moving(bearing, self.fs, c.bearing_threshold_m)) > c.forced_fraction:
            return "forced"
        q = b.shape[0] // 4
        x = b - b.mean(axis=0)
        e = [float(np.sqrt(np.mean(x[k * q : (k + 1) * q] ** 2))) for k in range(4)]
        steady = all(e[k + 1] < e[k] for k in range(3))
        return "free_decay" if e[0] > 0 and steady and e[3] / e[0] < c.decay_ratio else "ambient"

    def _estimate(self, spec) -> list[ModeEstimate]:
        c = self.config
        out: list[ModeEstimate | None] = [None] * self.n_modes
        for u in sorted(set(self.units)):
            idx = [i for i, uu in enumerate(self.units) if uu == u]
            lo = min(self.ref[i] for i in idx) * (1 - c.search_rel)
            hi = max(self.ref[i] for i in idx) * (1 + c.search_rel)
            peaks = [p for p in find_peaks(spec, column=u, fmin=max(lo, 0.0), fmax=min(hi, self.fs / 2), min_prominence=c.min_prominence, max_peaks=12)]
            if peaks:
                cost = np.full((len(idx), len(peaks)), 1e6)
                for a, i in enumerate(idx):
                    for k, p in enumerate(peaks):
                        dev = abs(math.log(p.frequency_hz / self.ref[i])) / c.search_rel
                        if dev <= 1:
                            cost[a, k] = dev**2 - 0.1 * math.log(p.amplitude / peaks[0].amplitude)
                rows, cols = linear_sum_assignment(cost)
                for a, k in zip(rows, cols):
                    if cost[a, k] >= 1e6:
                        continue
                    i, p = idx[a], peaks[k]
                    dev = abs(math.log(p.frequency_hz / self.ref[i])) / c.search_rel
                    rivals = [q.amplitude for q in peaks if q is not p and abs(math.log(q.frequency_hz / p.frequency_hz)) < 0.5 * c.search_rel]
                    coupling = 1.0 - (max(rivals) / p.amplitude if rivals else 0.0)
                    conf = (1 - 1 / p.prominence) * max(0.0, coupling) * math.exp(-(dev**2))
                    out[i] = ModeEstimate(i + 1, u + 1, p.frequency_hz, p.amplitude, float(np.clip(conf, 0, 1)))
        return [e if e is not None else ModeEstimate(i + 1, self.units[i] + 1, None, None, 0.0) for i, e in enumerate(out)]

    def process_window(self, times: object, b: object, temperature: object | None = None, bearing: object | None = None) -> WindowResult:
        """Analyse one window: times (n,) s, b (n, Γ) m, temperature °C (scalar or (n,)) or None,
        bearing displacement (n,) m or None. Returns the window's WindowResult."""
        B = as_signal("b", b, min_len=16, ndim=(2,))
        if B.shape[1] != self.gamma:
            raise ValueError(f"b has {B.shape[1]} columns, curvature_shapes has Γ={self.gamma}")
        t = as_times("times", times, B.shape[0])
        d = None if bearing is None else as_signal("bearing", bearing, min_len=B.shape[0], ndim=(1,))
        if d is not None and d.size != B.shape[0]:
            raise ValueError(f"bearing has {d.size} samples, b has {B.shape[0]}")
        T = None
        if temperature is not None:
            T = float(np.mean(as_signal("temperature", np.atleast_1d(np.asarray(temperature, dtype=float)), min_len=1, ndim=(1,))))
        c = self.config
        kind = self._classify(B, d)
        trusted = kind in ("free_decay", "ambient")
        spec = amplitude_spectrum(B, self.fs, pad_factor=c.pad_factor, window=c.window)
        if trusted and c.spectrum_memory_windows > 1:
            p = spec.amplitude**2
            a = 1.0 / c.spectrum_memory_windows
            self._power = p if self._power is None or self._power.shape != p.shape else (1 - a) * self._power + a * p
            spec = Spectrum(spec.frequencies, np.sqrt(self._power), spec.resolution_hz, spec.bin_spacing_hz, spec.coherent_gain,
                            spec.enbw_bins, spec.enbw_hz, spec.window, spec.n_samples, spec.pad_factor, spec.averages)
        if trusted and not self.ref:
            self._init_modes(spec)
        est = self._estimate(spec) if (trusted and self.ref) else [ModeEstimate(i + 1, self.units[i] + 1, None, None, 0.0) for i in range(self.n_modes)]
        t0, t1 = float(t[0]), float(t[-1] + 1 / self.fs)
        tmid = 0.5 * (t0 + t1)
        for i, e in enumerate(est):
            if e.frequency_hz is not None and e.confidence >= c.min_confidence:
                self.ref[i] += c.track_gain * (e.frequency_hz - self.ref[i])
        # curvature cross spectra at the tracked frequencies
        change = None
        # curvature shapes from stationary (ambient) windows only: a free decay's modal mix and
        # amplitude change within the window, so its cross spectra are not comparable
        G = None
        if kind == "ambient" and self.ref:
            C = cross_spectra(B, self.fs, self.ref, window=c.window)  # (modes, Γ)
            G = np.array([C[i] * np.conj(C[i, self.units[i]]) for i in range(self.n_modes)])
            a = 1.0 / c.curvature_memory_windows
            self._cross = G if self._cross is None else (1 - a) * self._cross + a * G
            self._cross_sum = G if self._cross_sum is None else self._cross_sum + G
            self._cross_windows += 1
        flags: list[dict] = []
        location = None
        scores: list[float | None] = [None] * self.n_modes
        ci_score = None
        levels: dict = {}
        if trusted and self._first_trusted is None:
            self._first_trusted = t0
        if self.baseline is None and trusted and self.ref:
            self._records.append(_Record(tmid, T, [e.frequency_hz for e in est], [e.confidence for e in est]))
            if G is not None:
                self._ci_hist.append(G.copy())
            if t1 - self._first_trusted >= c.baseline_s:
                self.baseline = self._fit_baseline(t1)
                if self.baseline is not None:
                    self._arm(self.baseline)
        elif self.baseline is not None and trusted:
            bl = self.baseline
            shapes = self._shapes(self._cross) if kind == "ambient" else None
            delta = dsd = None
            if shapes is not None:
                change = curvature_change(shapes, bl.curvature_shapes, self.eta, self.length)
                sign = np.sign(np.sum(shapes * bl.curvature_shapes, axis=1, keepdims=True))
                sign[sign == 0] = 1
                delta = shapes * sign - bl.curvature_shapes
                dsd = self._shape_change_std()
                # The baseline's scatter is that of a settled average: with a baseline given from
                # another record, the first windows' average is noisier and would look like change.
                if dsd is not None and self._cross_windows >= c.curvature_memory_windows:
                    q = float(np.mean((delta / dsd[:, None]) ** 2))
                    # One-sided: less shape change than in the healthy period is no damage.
                    z = max((q - bl.curvature_index_mean) / bl.curvature_index_std, 0.0)
                    ci_score, lvl = self._ci_chart.update(z, tmid)
                    levels[CURVATURE_CHART] = lvl
            for i, (e, m) in enumerate(zip(est, bl.modes)):
                if e.frequency_hz is None or e.confidence < c.min_confidence or m.windows < c.baseline_min_windows:
                    continue
                if m.f_ref_hz * (t1 - t0) < c.chart_min_cycles:
                    continue
                Tw = m.temperature_ref_c if T is None else T
                expected = m.f_ref_hz * (1 + m.slope_per_k * (Tw - m.temperature_ref_c))
                rel = e.frequency_hz / expected - 1
                scores[i], levels[chart_name("frequency", m.mode)] = self._charts[i].update(rel / m.sigma_rel, tmid)
            location = self._locate(delta, dsd)
            flags = self._flags(change, scores, ci_score, location)
        return WindowResult(t0, t1, kind, trusted, T, tuple(est), tuple(scores), change, ci_score, levels, tuple(flags), location)

    def _shapes(self, G: np.ndarray | None) -> np.ndarray | None:
        if G is None:
            return None
        try:
            return np.array([curvature_shape(G[i], self.units[i], self.S) for i in range(self.n_modes)])
        except ValueError:
            return None

    def _model_slope(self, i: int) -> float | None:
        sig = self.signatures
        slope = None if sig is None else (sig.get("temperature_slope") if isinstance(sig, dict) else getattr(sig, "temperature_slope", None))
        if slope is None or i >= len(slope) or not math.isfinite(float(slope[i])):
            return None
        return float(slope[i])

    def _shape_change_std(self) -> np.ndarray | None:
        """1σ per mode of (averaged shape − baseline shape) per station for a healthy structure."""
        bl = self.baseline
        if bl.curvature_windows < 1:  # a baseline stored before this statistic existed
            return None
        # too few baseline windows for a jackknife: the floor alone (a very short baseline)
        own = bl.curvature_shape_std if len(bl.curvature_shape_std) == self.n_modes else (0.0,) * self.n_modes
        a = 1.0 / self.config.curvature_memory_windows
        r = min(max(bl.curvature_index_rho, 0.0), 0.95)
        ewma = a / (2 - a) * (1 + r * (1 - a)) / (1 - r * (1 - a))
        n_eff = max(1.0, bl.curvature_windows * (1 - r) / (1 + r))
        std = np.maximum(np.asarray(own, dtype=float), self.config.curvature_min_std)
        return std * math.sqrt(ewma + 1.0 / n_eff)

    def _locate(self, delta: np.ndarray | None, dsd: np.ndarray | None) -> DamageLocation | None:
        """Model-assisted location of the present change (EWMA of the charts) against the signatures."""
        if self.signatures is None or not self._charts:
            return None
        bl = self.baseline
        shift = np.zeros(self.n_modes)
        std = np.full(self.n_modes, np.inf)
        for i, (ch, m) in enumerate(zip(self._charts, bl.modes)):
            if ch.state.n > 0 and m.windows >= self.config.baseline_min_windows:
                shift[i] = ch.state.ewma * m.sigma_rel
                std[i] = ch.sigma() * m.sigma_rel
        if not np.any(np.isfinite(std)):
            return None
        try:
            return locate_damage(shift, std, self.signatures, shape_change=None if dsd is None else delta,
                                 shape_std=dsd, length=self.length)
        except ValueError:
            return None

    def _flags(self, change: CurvatureChange | None, scores: list, ci_score: float | None, location: DamageLocation | None = None) -> list[dict]:
        out = []
        if location is not None:
            where = {"eta_m": location.eta_m, "third": location.third, "damage_kind": location.kind_best,
                     "location_match": round(location.best_match, 3), "located_by": "signatures"}
        else:
            where = {"eta_m": None, "third": None} if change is None else {"eta_m": change.eta_m, "third": change.third, "located_by": "curvature"}
        for i, ch in enumerate(self._charts):
            st = ch.state
            if st.level == "alarm":
                m = self.baseline.modes[i]
                score = scores[i] if scores[i] is not None else st.ewma / ch.sigma()
                out.append({
                    "kind": "frequency", "mode": m.mode, "unit": m.unit + 1, "level": "alarm",
                    "sigma": round(float(score), 2), "percent": round(100 * st.ewma * m.sigma_rel, 4),
                    "since_s": st.since_s, **where,
                })
        if self._ci_chart is not None and self._ci_chart.state.level == "alarm" and change is not None:
            st = self._ci_chart.state
            out.append({
                "kind": "curvature", "mode": None, "unit": None, "level": "alarm",
                "sigma": None if ci_score is None else round(float(ci_score), 2),
                "percent": round(100 * change.total, 2),
                "since_s": st.since_s, **where,
            })
        return out

    def _fit_baseline(self, t_end: float) -> Baseline | None:
        c = self.config
        recs = self._records
        modes = []
        for i in range(self.n_modes):
            sel = [(r.freqs[i], r.temperature) for r in recs if r.freqs[i] is not None and r.confs[i] >= c.min_confidence]
            if len(sel) < c.baseline_min_windows:
                modes.append(BaselineMode(i + 1, self.units[i], self.ref[i], 20.0, 0.0, 1.0, 0.0, len(sel)))
                continue
            f = np.array([s[0] for s in sel])
            T = np.array([s[1] if s[1] is not None else 20.0 for s in sel])
            fref0 = float(np.median(f))
            gravity = fref0 < c.gravity_mode_below_hz
            half = 0.5 * c.youngs_temperature_coefficient
            prior = 0.0 if gravity else half * c.slope_prior_fraction
            prior_std = abs(half) * c.slope_prior_std_fraction * (0.3 if gravity else 1.0) or 1e-9
            model_slope = self._model_slope(i)
            if model_slope is not None:  # the FE model's d ln f/dT: a tight prior (E(T) is known, the rest is not)
                prior, prior_std = model_slope, max(0.2 * abs(model_slope), 0.05 * abs(half), 1e-9)
            a, slope, tm, sig = fit_temperature_model(f / fref0 - 1, T, prior, prior_std)
            res = f / (fref0 * (1 + a)) - 1 - slope * (T - tm)
            modes.append(BaselineMode(i + 1, self.units[i], fref0 * (1 + a), tm, slope, max(sig, c.min_sigma_rel), _lag1(res), len(sel)))
        base_shapes = self._shapes(self._cross_sum)
        if base_shapes is None:
            return None
        # the baseline shape is the normalised sum of n windows' cross spectra: its scatter comes
        # from a delete-one jackknife over those windows, expressed per window (× n)
        hist = list(self._ci_hist)
        n = len(hist)
        shape_std, rho = (), 0.0
        if n >= 3:
            total = np.sum(hist, axis=0)
            jack = []
            for G in hist:
                sh = self._shapes(total - G)
                if sh is None:
                    jack = []
                    break
                sign = np.sign(np.sum(sh * base_shapes, axis=1, keepdims=True))
                sign[sign == 0] = 1
                jack.append(sh * sign)
            if jack:
                J = np.array(jack)  # (n, modes, η)
                var_mean = (n - 1) / n * np.sum((J - J.mean(axis=0)) ** 2, axis=0)  # variance of the n-window shape
                shape_std = tuple(float(x) for x in np.sqrt(n * np.mean(var_mean, axis=1)))
                x = (J - J.mean(axis=0)).reshape(n, -1)  # influence of each window (sign flipped)
                den = float(np.sum(x[:-1] ** 2))
                rho = float(np.clip(np.sum(x[:-1] * x[1:]) / den, 0.0, 0.95)) if den > 0 else 0.0
        # Q = mean (Δ/σ)² is ~χ²_p/p; p: the shape of a mode spans Γ − 1 directions once normalised
        p = max(1, self.n_modes * min(self.gamma - 1, self.eta.size))
        return Baseline(tuple(modes), base_shapes, 1.0, math.sqrt(2.0 / p), rho, float(self._first_trusted), float(t_end), shape_std, n)

    # -- persistence -----------------------------------------------------------------------
    def state_dict(self) -> dict:
        """JSON-safe state for a restart (tracker, baseline or its learning data, charts)."""
        cx = lambda G: None if G is None else {"re": np.real(G).tolist(), "im": np.imag(G).tolist()}  # noqa: E731
        return {
            "fs": self.fs, "config": self.config.model_dump(), "curvature_shapes": self.S.tolist(), "stations_eta": self.eta.tolist(),
            "length": self.length, "units": self.units, "f0": self.f0, "ref": self.ref,
            "baseline": None if self.baseline is None else self.baseline.to_dict(),
            "records": [vars(r) for r in self._records], "first_trusted": self._first_trusted,
            "cross": cx(self._cross), "cross_sum": cx(self._cross_sum), "cross_windows": self._cross_windows,
            "ci_hist": [cx(G) for G in self._ci_hist],
            "power": None if self._power is None else self._power.tolist(),
            "charts": [ch.state_dict() for ch in self._charts],
            "ci_chart": None if self._ci_chart is None else self._ci_chart.state_dict(),
        }

    @classmethod
    def from_state_dict(cls, d: dict) -> "ModalMonitor":
        if not isinstance(d, dict):
            raise ValueError(f"state must be a dict, got {type(d).__name__}")
        ux = lambda g: None if g is None else np.asarray(g["re"]) + 1j * np.asarray(g["im"])  # noqa: E731
        try:
            m = cls(None, d["curvature_shapes"], d["stations_eta"], fs=d["fs"], config=AnalysisConfig(**d["config"]), beam_length=d["length"])
            m.units, m.f0, m.ref = list(d["units"]), list(d["f0"]), list(d["ref"])
            m.baseline = None if d["baseline"] is None else Baseline.from_dict(d["baseline"])
            m._records = [_Record(**r) for r in d["records"]]
            m._first_trusted = d["first_trusted"]
            m._cross, m._cross_sum = ux(d["cross"]), ux(d["cross_sum"])
            # States stored before the counter existed had a settled average.
            m._cross_windows = int(d.get("cross_windows", m.config.curvature_memory_windows))
            m._ci_hist = [ux(g) for g in d["ci_hist"]]
            m._power = None if d.get("power") is None else np.asarray(d["power"], dtype=float)
            m._charts = [EwmaChart.from_state_dict(c) for c in d["charts"]]
            m._ci_chart = None if d["ci_chart"] is None else EwmaChart.from_state_dict(d["ci_chart"])
        except KeyError as exc:
            raise ValueError(f"state dict lacks {exc}") from exc
        return m
