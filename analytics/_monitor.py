"""ModalMonitor: one window at a time — excitation class, identification (SSI-cov cross-checked
against the amplitude spectra), mode tracking, curvature, baseline, control charts and alarms."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from contract import CURVATURE_CHART, ChartDocument, chart_name

from ._alarms import AlarmEvent, AlarmLogic
from ._chart import EwmaChart
from ._config import AnalysisConfig
from ._curvature import CurvatureChange, CurvatureStatistic, curvature_change, curvature_statistic, mode_shape_curvature
from ._damping import _moving
from ._frf import ExcitationClass, classify_excitation
from ._location import DamageLocation, locate_damage
from ._oma import IdentifiedMode, ModalIdentification, OmaConfig, identify_modes
from ._peaks import Peak, find_peaks
from ._tracks import ModeTracker
from ._spectrum import Spectrum, amplitude_spectrum
from ._ssi import modal_assurance
from ._validate import as_signal, as_times, check_fs

__all__ = ["Baseline", "BaselineError", "BaselineMode", "ModeEstimate", "WindowResult", "ModalMonitor", "fit_temperature_model",
           "support_acceleration"]

WINDOW_KINDS = ("forced", "free_decay", "ambient", "quiet")


def _none(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _round(x: float | None, digits: int = 6) -> float | None:
    x = _none(x)
    return None if x is None else round(x, digits)


@dataclass(frozen=True)
class ModeEstimate:
    """One tracked mode in one window.

    frequency_hz : Hz (None if the window shows no such mode); method : "ssi" (a pole cluster of
    the subspace identification, cross-checked against the spectrum) or "spectrum" (no subspace
    mode in the band: the amplitude spectrum's peak, reported but neither charted nor learnt).
    amplitude : the unit deformation's spectral amplitude there (unit of b); confidence 0..1.
    frequency_std_hz, damping_ratio, damping_std : the subspace estimate and its 1σ (jackknife
    over data segments and the scatter across model orders). mpc : modal phase collinearity of
    the shape; mac : MAC of the shape against the baseline's (None before one); shape : (Γ,) real
    shape over the unit deformations (unit norm). spectral_hz : the amplitude spectrum's peak
    nearest the estimate (the cross-check; None if it shows none); confirmed : the two agree
    within the spectrum's resolution (or 3σ). track : id of the subspace mode's track across
    windows (:class:`analytics.ModeTracker`, the same as ``shm oma``'s; None without a subspace mode).
    """

    mode: int
    unit: int
    frequency_hz: float | None
    amplitude: float | None
    confidence: float
    frequency_std_hz: float | None = None
    damping_ratio: float | None = None
    damping_std: float | None = None
    mpc: float | None = None
    mac: float | None = None
    shape: tuple[float, ...] | None = None
    spectral_hz: float | None = None
    confirmed: bool = False
    method: str | None = None
    track: int | None = None

    def as_dict(self) -> dict:
        return {
            "mode": self.mode, "unit": self.unit, "track": self.track, "frequency_hz": _none(self.frequency_hz), "amplitude": _none(self.amplitude),
            "confidence": round(self.confidence, 4), "method": self.method,
            "frequency_std_hz": _none(self.frequency_std_hz), "damping_ratio": _none(self.damping_ratio),
            "damping_std": _none(self.damping_std), "damping_method": "ssi" if self.method == "ssi" and self.damping_ratio is not None else None,
            "mpc": _round(self.mpc, 4), "mac": _round(self.mac, 4), "spectral_hz": _none(self.spectral_hz), "confirmed": self.confirmed,
        }


@dataclass(frozen=True)
class BaselineMode:
    """Healthy reference of one mode: f = f_ref·(1 + slope·(T − T_ref)) ± sigma_rel·f_ref.

    f_ref_hz (Hz), temperature_ref_c (°C), slope_per_k (1/K, relative), sigma_rel (relative 1σ
    scatter of one window's estimate), rho (lag-1 correlation of successive windows' residuals),
    windows (windows behind it), shape ((Γ,) mean real shape over the unit deformations, unit
    norm; () when none was learnt).
    """

    mode: int
    unit: int
    f_ref_hz: float
    temperature_ref_c: float
    slope_per_k: float
    sigma_rel: float
    rho: float
    windows: int
    shape: tuple[float, ...] = ()


@dataclass(frozen=True)
class Baseline:
    """A healthy baseline; ``to_dict``/``from_dict`` give a JSON-safe round trip for storage.

    modes : per mode the temperature model; curvature_shapes : (modes, len(η)) the modes'
    mode-shape curvatures (:func:`analytics.mode_shape_curvature` of the identified shapes,
    averaged over the baseline's windows; unit RMS, dimensionless; a zero row for a mode without
    one); curvature_covariance : (modes, len(η), len(η)) covariance of one window's curvature
    shape about that average (dimensionless², learnt from the baseline's windows; None for a
    baseline stored before the index was built from mode shapes: no curvature chart);
    curvature_mode_windows : (modes,) windows behind each mode's curvature;
    curvature_index_mean/std : the curvature statistic's healthy mean (1) and std for a settled
    average; curvature_index_rho : lag-1 correlation of successive windows' shape deviations;
    curvature_shape_std : (modes,) 1σ of one window's unit-RMS curvature shape per station (pooled
    over η); curvature_windows : windows with at least one mode's shape; start_s/end_s : the learnt
    period (s); trusted_windows, window_s : the trusted windows it was learnt from and their length (s).
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
    trusted_windows: int = 0
    window_s: float = 0.0
    curvature_covariance: np.ndarray | None = None
    curvature_mode_windows: tuple[int, ...] = ()

    def to_dict(self) -> dict:
        return {
            "modes": [{**vars(m), "shape": list(m.shape)} for m in self.modes],
            "curvature_shapes": np.asarray(self.curvature_shapes).tolist(),
            "curvature_index_mean": self.curvature_index_mean,
            "curvature_index_std": self.curvature_index_std,
            "curvature_index_rho": self.curvature_index_rho,
            "start_s": self.start_s,
            "end_s": self.end_s,
            "curvature_shape_std": list(self.curvature_shape_std),
            "curvature_windows": self.curvature_windows,
            "trusted_windows": self.trusted_windows,
            "window_s": self.window_s,
            "curvature_index": "mode_shape",
            "curvature_covariance": None if self.curvature_covariance is None else np.asarray(self.curvature_covariance).tolist(),
            "curvature_mode_windows": list(self.curvature_mode_windows),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Baseline":
        if not isinstance(d, dict):
            raise ValueError(f"baseline must be a dict, got {type(d).__name__}")
        try:
            modes = tuple(BaselineMode(**{**m, "shape": tuple(float(v) for v in m.get("shape", ()))}) for m in d["modes"])
            # a baseline stored before the index was built from identified mode shapes holds
            # operational-deflection shapes: it arms the frequency charts only
            mode_shape = d.get("curvature_index") == "mode_shape" and d.get("curvature_covariance") is not None
            return cls(
                modes,
                np.asarray(d["curvature_shapes"], dtype=float),
                float(d["curvature_index_mean"]),
                float(d["curvature_index_std"]),
                float(d["curvature_index_rho"]),
                float(d["start_s"]),
                float(d["end_s"]),
                tuple(float(x) for x in d.get("curvature_shape_std", ())),
                int(d.get("curvature_windows", 0)),
                int(d.get("trusted_windows", 0)),
                float(d.get("window_s", 0.0)),
                np.asarray(d["curvature_covariance"], dtype=float) if mode_shape else None,
                tuple(int(x) for x in d.get("curvature_mode_windows", ())) if mode_shape else (),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"baseline dict is malformed: {exc}") from exc

    def problems(self, config: AnalysisConfig) -> dict[int, str]:
        """Mode → why it is not charted by this baseline (too few windows with an estimate, too
        few cycles per window); modes that are charted are absent."""
        out = {}
        minutes = self.trusted_windows * self.window_s * (1 - config.overlap) / 60.0 if self.window_s else 0.0
        for m in self.modes:
            why = []
            if m.windows < config.baseline_min_windows:
                why.append(f"{m.windows} windows with a subspace estimate of {self.trusted_windows} trusted "
                           f"({minutes:.1f} minutes of trusted data), {config.baseline_min_windows} needed")
            cycles = m.f_ref_hz * self.window_s if self.window_s else float("inf")
            if cycles < config.chart_min_cycles:
                why.append(f"{cycles:.0f} cycles per {self.window_s:g} s window, {config.chart_min_cycles:g} needed to chart it")
            if why:
                out[m.mode] = "; ".join(why)
        return out


class BaselineError(ValueError):
    """No baseline could be learnt; the message names each mode and what it lacked."""


@dataclass(frozen=True)
class WindowResult:
    """The figures of one analysis window.

    start_s/end_s (s), kind ("forced" | "free_decay" | "ambient" | "quiet"), trusted (used for
    eigenfrequencies), temperature_c (°C or None), estimates per mode, frequency_scores (EWMA
    score in σ per mode, None before a baseline), curvature (change against the baseline or
    None), curvature_score (σ), levels (chart name → "ok"/"warning"/"alarm" this window), flags
    (charts in alarm now), location (the model-assisted damage location of the change since the
    baseline, when damage signatures were given, else None), excitation (the measured input's
    class, None without one), charts (the charts judged, as contract documents), alarm_events
    (alarms raised, escalated or cleared by this window), spectrum (the window's Hamming-windowed,
    zero-padded amplitude spectra of b: the cross-check and the dashboard's).
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
    excitation: ExcitationClass | None = None
    charts: tuple[ChartDocument, ...] = ()
    alarm_events: tuple[AlarmEvent, ...] = ()
    spectrum: Spectrum | None = field(default=None, repr=False, compare=False)
    identified: tuple[IdentifiedMode, ...] = ()

    def as_dict(self) -> dict:
        exc = self.excitation
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "kind": self.kind,
            "trusted": self.trusted,
            "temperature_c": _none(self.temperature_c),
            "excitation": None if exc is None else {"kind": exc.kind, "line_hz": _none(exc.line_hz),
                                                    "line_fraction": _round(exc.line_fraction, 4),
                                                    "nearest_mode_hz": _none(exc.nearest_mode_hz)},
            "modes": [e.as_dict() for e in self.estimates],
            "frequency_scores_sigma": [_none(s) for s in self.frequency_scores],
            "curvature_index": None if self.curvature is None else _none(self.curvature.total),
            "curvature_score_sigma": _none(self.curvature_score),
            "curvature_eta_m": None if self.curvature is None else self.curvature.eta_m,
            "curvature_third": None if self.curvature is None else self.curvature.third,
            "levels": dict(self.levels),
            "flags": [dict(f) for f in self.flags],
            "alarm_events": [{"action": e.action, "chart": e.chart, "level": e.level, "at_s": e.at_s, "since_s": e.since_s,
                              "score_sigma": _none(e.score_sigma), "threshold_sigma": e.threshold_sigma} for e in self.alarm_events],
            "location": None if self.location is None else self.location.as_dict(),
            "identified_modes": [{k: (_none(v) if isinstance(v, float) else v) for k, v in m.as_dict().items()} for m in self.identified],
        }


def support_acceleration(displacement: object, fs: float) -> np.ndarray:
    """The support's acceleration (m/s²) from its displacement d(t) (N,) in m at fs Hz: the second
    central difference (the ends repeat their neighbours). Its gain is sinc²(f/fs) of the exact
    d̈, 0.995 at fs/27: the band the identification uses is far below."""
    fs = check_fs(fs)
    d = as_signal("displacement", displacement, min_len=3, ndim=(1,))
    a = np.empty_like(d)
    a[1:-1] = (d[2:] - 2 * d[1:-1] + d[:-2]) * fs * fs
    a[0], a[-1] = a[1], a[-2]
    return a


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
    shapes: list = field(default_factory=list)
    stds: list = field(default_factory=list)


class ModalMonitor:
    """Incremental modal analytics, one window at a time.

    expected_hz : per unit deformation the expected eigenfrequencies (Hz), e.g.
        ((0.301, 0.859), (1.906,), (3.49,), (5.6,)) (the model's ``UnitDeformations.frequencies_hz``);
        modes are numbered 1.. in this order (the contract's ``ModeMap``).
    curvature_shapes : (len(η), Γ) s''_χ at stations_eta (1/m²); stations_eta (len(η),) m from the bearing.
    fs : sample rate of b (Hz); baseline : a stored Baseline, else one is learnt from the first
    ``config.baseline_s`` seconds of trusted windows (``learn="record"``: from every window until
    :meth:`fit_baseline` is called); beam_length : m (default max(stations_eta)); signatures :
    predicted damage signatures (``estimator.damage_signatures`` or an object/dict with eta, kind,
    frequency_shift (M, modes), curvature_change (M, modes, len(η)) at stations_eta) for the
    model-assisted location of a change; None: the model-free curvature index locates it.

    Per window: the excitation class from the measured support motion (``bearing``: a window is
    *forced*, so not trusted, only when its input is deterministic with a line at or near a
    tracked mode — a randomly moving support is operational data and an input), then in trusted
    windows a covariance-driven SSI of b (band around the tracked modes, automated pole selection
    and clustering, the support acceleration as a measured input for the FRF cross-check), the
    subspace modes assigned to the tracked modes by frequency and shape (MAC against the baseline's
    shapes once there is one) and cross-checked against the Hamming-windowed, zero-padded
    amplitude spectra of b. The curvature (damage-location) index is built from the identified
    mode shapes, not from operational deflection shapes (whose estimator error shifts with the
    excitation's balance): each window's subspace shape of a mode, over the unit deformations,
    gives its mode-shape curvature κ = Σ φ_χ s''_χ (Pandey et al. 1991; unit RMS, signed against
    the baseline's), used when its MAC with the baseline shape reaches
    ``config.curvature_mac_min`` and averaged over ``config.curvature_memory_windows`` windows.
    The curvature chart watches Q = mean over modes and stations of (Δκ/σ)², Δκ the averages'
    change against the baseline's, σ² the average's healthy variance (one window's covariance
    learnt from the baseline's windows, scaled to the average) plus ``config.curvature_min_std``²
    (what the baseline cannot show); Q has mean 1 and its std from the same covariance
    (:func:`analytics.curvature_statistic`), charted as (Q − 1)/std without further smoothing. The
    charts' levels become alarms in :class:`analytics.AlarmLogic` (the one alarm path).
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
        learn: str = "period",
    ):
        self.fs = check_fs(fs)
        self.config = config or AnalysisConfig()
        if not isinstance(self.config, AnalysisConfig):
            raise ValueError(f"config must be an AnalysisConfig, got {type(self.config).__name__}")
        if learn not in ("period", "record"):
            raise ValueError(f"{learn=} must be 'period' (the first config.baseline_s of trusted windows) or 'record' (all)")
        self.learn = learn
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
        # a baseline learnt here, from this record's first trusted windows; a given one is another
        # record's, against which the curvature chart warns but never alarms (see _curvature_level)
        self._own_baseline = False
        if baseline is not None and expected_hz is not None and len(baseline.modes) != len(self.f0):
            raise ValueError(f"baseline has {len(baseline.modes)} modes, expected_hz gives {len(self.f0)}")
        self._records: list[_Record] = []
        self.tracker = ModeTracker()
        self._first_trusted: float | None = None
        self._trusted = 0  # trusted windows seen while learning
        # per mode the EWMA of the windows' mode-shape curvatures (unit RMS), the EWMA's Σ w² (the
        # share of one window's scatter the average keeps) and the windows in it
        self._kappa: np.ndarray | None = None  # (modes, len(η))
        self._kappa_share: np.ndarray | None = None  # (modes,)
        self._kappa_n: np.ndarray | None = None  # (modes,) int
        # (modes, len(η)) EWMA of one window's squared deviation from the average before it: the
        # present scatter of a window's shape (the excitation's balance sets it, not the baseline's)
        self._kappa_var: np.ndarray | None = None
        # stations where some unit deformation bends (a free end's curvature is zero by construction)
        self._bending = np.max(np.abs(self.S), axis=1) > 1e-9 * float(np.max(np.abs(self.S)))
        self._charts: list[EwmaChart] = []
        self._ci_chart: EwmaChart | None = None
        c = self.config
        self.alarms = AlarmLogic(raise_windows=c.hold_windows, clear_windows=c.clear_windows, clear_sigma=c.clear_sigma)
        self._power = None  # EWMA of the trusted windows' power spectra (the spectral fallback)
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

    @property
    def oma_config(self) -> OmaConfig | None:
        """The SSI settings of a window: the band around the tracked modes (None before there are modes)."""
        if not self.f0:
            return None
        c = self.config
        lo = c.band_low_fraction * min(self.f0)
        hi = min(c.band_high_fraction * max(self.f0), 0.45 * self.fs)
        order = c.max_order or min(40, max(16, 4 * len(self.f0) + 4))
        # a mode's change within a monitoring window is followed across windows by the charts;
        # the sub-window split (shm oma's short windows of a moving support) stays off here, where
        # its 1 % departure test would trade a window's subspace estimate for a noisier one
        return OmaConfig(fmin_hz=lo, fmax_hz=hi, max_order=order, moving_modes=False)

    def _chart(self, inflation: float) -> EwmaChart:
        warning, alarm = self.config.chart_levels("frequency")
        return EwmaChart(self.config.ewma_lambda, warning, alarm, inflation)

    def _arm(self, baseline: Baseline) -> None:
        if not self.ref:
            self.units = [m.unit for m in baseline.modes]
            self.f0 = [m.f_ref_hz for m in baseline.modes]
            self.ref = list(self.f0)
        self._charts = [self._chart(math.sqrt((1 + m.rho) / (1 - m.rho))) for m in baseline.modes]
        self._ci_chart = None
        if any(self._curvature_charted(i) for i in range(len(baseline.modes))):
            # the statistic already averages (shapes over curvature_memory_windows): no second EWMA
            warning, alarm = self.config.chart_levels("curvature")
            self._ci_chart = EwmaChart(1.0, warning, alarm, 1.0)

    def _curvature_level(self, level: str) -> str:
        """The curvature chart's level as the alarms see it: against a baseline from another record at
        most "warning". Across records of one healthy structure the identified shapes move with the
        excitation's spatial balance (another realisation of the distributed load) far more than with
        a local damage: measured on the lab sheet with a 20 K swing, 33–45 σ on a healthy record
        against another's baseline, 15–29 σ for a tip mass; within a record the chart stays calm
        when healthy. A frequency chart, whose temperature model holds across records, still alarms."""
        if self._own_baseline or level != "alarm":
            return level
        return "warning"

    def _curvature_charted(self, i: int) -> bool:
        """Mode i (0-based) has a curvature baseline learnt from enough windows."""
        bl = self.baseline
        return (bl is not None and bl.curvature_covariance is not None and i < len(bl.curvature_mode_windows)
                and bl.curvature_mode_windows[i] >= self.config.baseline_min_windows)

    def _init_modes(self, spec) -> None:
        for u in range(self.gamma):
            pk = find_peaks(spec, column=u, fmin=2.0 / (spec.n_samples / self.fs) + 0.05, min_prominence=self.config.min_prominence)
            if pk:
                self.units.append(u)
                self.f0.append(pk[0].frequency_hz)
        self.ref = list(self.f0)

    def _baseline_shapes(self) -> list[np.ndarray | None]:
        if self.baseline is None:
            return [None] * self.n_modes
        return [np.asarray(m.shape, dtype=float) if len(m.shape) == self.gamma else None for m in self.baseline.modes]

    # -- one window ------------------------------------------------------------------------
    def _classify(self, b: np.ndarray, support: np.ndarray | None, acc: np.ndarray | None) -> tuple[str, ExcitationClass | None]:
        c = self.config
        rms = float(np.sqrt(np.mean((b - b.mean(axis=0)) ** 2)))
        exc = None
        if acc is not None and self.ref:
            exc = classify_excitation(acc, self.fs, self.ref, tolerance=c.excitation_tolerance, floor_ratio=c.excitation_floor_ratio)
        if rms <= c.quiet_rms:
            return "quiet", exc
        if exc is not None and exc.kind == "deterministic_near_mode":
            return "forced", exc
        q = b.shape[0] // 4
        x = b - b.mean(axis=0)
        e = [float(np.sqrt(np.mean(x[k * q : (k + 1) * q] ** 2))) for k in range(4)]
        steady = all(e[k + 1] < e[k] for k in range(3))
        still = support is None or float(np.mean(_moving(support, self.fs, c.bearing_threshold_m))) <= c.forced_fraction
        return ("free_decay" if e[0] > 0 and steady and e[3] / e[0] < c.decay_ratio and still else "ambient"), exc

    def _identify(self, b: np.ndarray, acc: np.ndarray | None) -> ModalIdentification | None:
        cfg = self.oma_config
        if cfg is None:
            return None
        try:
            return identify_modes(b, self.fs, config=cfg, inputs=acc, tracked_hz=self.ref, frf_uncertainty=False)
        except (ValueError, np.linalg.LinAlgError):
            return None

    def _spectral(self, spec: Spectrum) -> list[ModeEstimate | None]:
        """Per tracked mode the peak of its unit deformation's amplitude spectrum (assigned by
        frequency, peaks of one unit shared out to its modes), or None."""
        c = self.config
        out: list[ModeEstimate | None] = [None] * self.n_modes
        for u in sorted(set(self.units)):
            idx = [i for i, uu in enumerate(self.units) if uu == u]
            lo = min(self.ref[i] for i in idx) * (1 - c.search_rel)
            hi = max(self.ref[i] for i in idx) * (1 + c.search_rel)
            peaks = list(find_peaks(spec, column=u, fmin=max(lo, 0.0), fmax=min(hi, self.fs / 2), min_prominence=c.min_prominence, max_peaks=12))
            if not peaks:
                continue
            cost = np.full((len(idx), len(peaks)), 1e6)
            for a, i in enumerate(idx):
                for k, p in enumerate(peaks):
                    dev = abs(math.log(p.frequency_hz / self.ref[i])) / c.search_rel
                    if dev <= 1:
                        cost[a, k] = dev**2 - 0.1 * math.log(p.amplitude / peaks[0].amplitude)
            rows, cols = linear_sum_assignment(cost)
            for a, k in zip(rows.tolist(), cols.tolist()):
                if cost[a, k] >= 1e6:
                    continue
                i, p = idx[a], peaks[k]
                dev = abs(math.log(p.frequency_hz / self.ref[i])) / c.search_rel
                rivals = [q.amplitude for q in peaks if q is not p and abs(math.log(q.frequency_hz / p.frequency_hz)) < 0.5 * c.search_rel]
                coupling = 1.0 - (max(rivals) / p.amplitude if rivals else 0.0)
                conf = (1 - 1 / p.prominence) * max(0.0, coupling) * math.exp(-(dev**2))
                out[i] = ModeEstimate(i + 1, u + 1, p.frequency_hz, p.amplitude, float(np.clip(conf, 0, 1)), method="spectrum")
        return out

    def _estimate(self, ident: ModalIdentification | None, spec: Spectrum) -> list[ModeEstimate]:
        """The subspace modes assigned to the tracked modes and cross-checked against the spectra."""
        c = self.config
        modes: tuple[IdentifiedMode, ...] = () if ident is None else ident.modes
        refs = self._baseline_shapes()
        n_samples = spec.n_samples
        resolution = self.fs / n_samples  # Hz, of the window
        peaks_of: dict[int, tuple[Peak, ...]] = {}
        out: list[ModeEstimate | None] = [None] * self.n_modes
        if modes:
            cost = np.full((self.n_modes, len(modes)), 1e6)
            for i in range(self.n_modes):
                u = self.units[i]
                for j, m in enumerate(modes):
                    dev = abs(math.log(m.frequency_hz / self.ref[i])) / c.search_rel
                    if dev > 1:
                        continue
                    shape = np.asarray(m.shape)
                    sim = float(modal_assurance(shape[None], refs[i][None])[0, 0]) if refs[i] is not None else float(shape[u] ** 2 / (shape @ shape))
                    if sim < c.track_similarity_min:
                        continue
                    cost[i, j] = dev**2 + (1 - sim) - 0.1 * m.contribution
            rows, cols = linear_sum_assignment(cost)
            for i, j in zip(rows.tolist(), cols.tolist()):
                if cost[i, j] >= 1e6:
                    continue
                m, u = modes[j], self.units[i]
                if u not in peaks_of:
                    idx = [k for k, uu in enumerate(self.units) if uu == u]
                    lo = min(self.ref[k] for k in idx) * (1 - c.search_rel)
                    hi = max(self.ref[k] for k in idx) * (1 + c.search_rel)
                    peaks_of[u] = find_peaks(spec, column=u, fmin=max(lo, 0.0), fmax=min(hi, self.fs / 2), min_prominence=c.min_prominence,
                                             max_peaks=12)
                near = min(peaks_of[u], key=lambda p: abs(p.frequency_hz - m.frequency_hz), default=None)
                tol = max(c.cross_check_bins * resolution, 3 * m.frequency_std_hz if m.frequency_std_hz is not None else 0.0)
                confirmed = near is not None and abs(near.frequency_hz - m.frequency_hz) <= tol
                amp = near.amplitude if confirmed else float(np.interp(m.frequency_hz, spec.frequencies, spec.amplitude[:, u]))
                dev = abs(math.log(m.frequency_hz / self.ref[i])) / c.search_rel
                conf = float(np.clip(m.mpc, 0.0, 1.0)) * math.exp(-(dev**2)) * (1.0 if confirmed else 0.5)
                mac = None if refs[i] is None else float(modal_assurance(np.asarray(m.shape)[None], refs[i][None])[0, 0])
                out[i] = ModeEstimate(i + 1, u + 1, m.frequency_hz, amp, float(np.clip(conf, 0, 1)), m.frequency_std_hz, m.damping_ratio,
                                      m.damping_std, m.mpc, mac, tuple(m.shape), None if near is None else near.frequency_hz, confirmed, "ssi")
        if any(e is None for e in out):
            fallback = self._spectral(spec)
            for i, e in enumerate(out):
                if e is None and fallback[i] is not None:
                    f = fallback[i]
                    out[i] = ModeEstimate(f.mode, f.unit, f.frequency_hz, f.amplitude, 0.5 * f.confidence, spectral_hz=f.frequency_hz,
                                          method="spectrum")
        return [e if e is not None else ModeEstimate(i + 1, self.units[i] + 1, None, None, 0.0) for i, e in enumerate(out)]

    def process_window(self, times: object, b: object, temperature: object | None = None, bearing: object | None = None) -> WindowResult:
        """Analyse one window: times (n,) s, b (n, Γ) m, temperature °C (scalar or (n,)) or None,
        support displacement ``bearing`` (n,) m (the bearing sensor or the estimator's d) or None.
        Returns the window's WindowResult."""
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
        acc = support_acceleration(d, self.fs) if d is not None and float(np.ptp(d)) > 0 else None
        kind, excitation = self._classify(B, d, acc)
        trusted = kind in ("free_decay", "ambient")
        spec = amplitude_spectrum(B, self.fs, pad_factor=c.pad_factor, window=c.window)
        fallback_spec = spec
        if trusted and c.spectrum_memory_windows > 1:
            p = spec.amplitude**2
            a = 1.0 / c.spectrum_memory_windows
            self._power = p if self._power is None or self._power.shape != p.shape else (1 - a) * self._power + a * p
            fallback_spec = Spectrum(spec.frequencies, np.sqrt(self._power), spec.resolution_hz, spec.bin_spacing_hz, spec.coherent_gain,
                                     spec.enbw_bins, spec.enbw_hz, spec.window, spec.n_samples, spec.pad_factor, spec.averages)
        if trusted and not self.ref:
            self._init_modes(spec)
        identified: tuple[IdentifiedMode, ...] = ()
        if trusted and self.ref:
            ident = self._identify(B, acc)
            est = self._estimate(ident, fallback_spec)
            if ident is not None:
                # every subspace mode of the window, tracked as shm oma tracks its windows' modes
                ms = ident.modes
                ids = self.tracker.assign(float(t[0]), [(m.frequency_hz, m.start_hz if m.moving else m.frequency_hz,
                                                         m.end_hz if m.moving else m.frequency_hz, m.shape, m.contribution) for m in ms])
                identified = tuple(replace(m, track=i) for m, i in zip(ms, ids))
                est = [replace(e, track=next((m.track for m in identified if e.frequency_hz is not None and abs(m.frequency_hz - e.frequency_hz) < 1e-9), None))
                       if e.method == "ssi" else e for e in est]
        else:
            est = [ModeEstimate(i + 1, self.units[i] + 1, None, None, 0.0) for i in range(self.n_modes)]
        t0, t1 = float(t[0]), float(t[-1] + 1 / self.fs)
        tmid = 0.5 * (t0 + t1)
        for i, e in enumerate(est):
            if e.frequency_hz is not None and e.confidence >= c.min_confidence:
                self.ref[i] += c.track_gain * (e.frequency_hz - self.ref[i])
        change = None
        location = None
        scores: list[float | None] = [None] * self.n_modes
        ci_score = None
        levels: dict = {}
        charts: list[ChartDocument] = []
        if trusted and self._first_trusted is None:
            self._first_trusted = t0
        if self.baseline is None and trusted and self.ref:
            self._trusted += 1
            charted = [e.method == "ssi" for e in est]
            self._records.append(_Record(tmid, T, [e.frequency_hz if ok else None for e, ok in zip(est, charted)],
                                         [e.confidence for e in est], [e.shape if ok else None for e, ok in zip(est, charted)],
                                         [e.frequency_std_hz if ok else None for e, ok in zip(est, charted)]))
            if self.learn == "period" and t1 - self._first_trusted >= c.baseline_s:
                self.baseline = self._fit_baseline(t1)
                self._own_baseline = self.baseline is not None
                if self.baseline is not None:
                    self._arm(self.baseline)
        elif self.baseline is not None and trusted:
            bl = self.baseline
            delta = dsd = None
            curv = self._curvature_window(est) if self._ci_chart is not None else None
            if curv is not None:
                change, delta, stat = curv
                dsd = stat.sigma
                # One-sided: less shape change than in the healthy period is no damage.
                ci_score, lvl = self._ci_chart.update(max(stat.score, 0.0))
                lvl = self._curvature_level(lvl)
                levels[CURVATURE_CHART] = lvl
                warning, alarm = c.chart_levels("curvature")
                charts.append(ChartDocument(name=CURVATURE_CHART, kind="curvature", level=lvl, score_sigma=ci_score,
                                            warning_sigma=warning, alarm_sigma=alarm))
            warning, alarm = c.chart_levels("frequency")
            for i, (e, m) in enumerate(zip(est, bl.modes)):
                if e.frequency_hz is None or e.method != "ssi" or e.confidence < c.min_confidence or m.windows < c.baseline_min_windows:
                    continue
                if m.f_ref_hz * (t1 - t0) < c.chart_min_cycles:
                    continue
                Tw = m.temperature_ref_c if T is None else T
                expected = m.f_ref_hz * (1 + m.slope_per_k * (Tw - m.temperature_ref_c))
                rel = e.frequency_hz / expected - 1
                name = chart_name("frequency", m.mode)
                scores[i], levels[name] = self._charts[i].update(rel / m.sigma_rel)
                charts.append(ChartDocument(name=name, kind="frequency", mode=m.mode, unit=m.unit + 1, level=levels[name],
                                            score_sigma=scores[i], warning_sigma=warning, alarm_sigma=alarm))
            location = self._locate(delta, dsd)
        events = self.alarms.update(charts, t1)
        flags = self._flags(change, scores, ci_score, location)
        return WindowResult(t0, t1, kind, trusted, T, tuple(est), tuple(scores), change, ci_score, levels, tuple(flags), location,
                            excitation, tuple(charts), tuple(events), spec, identified)


    def _model_slope(self, i: int) -> float | None:
        sig = self.signatures
        slope = None if sig is None else (sig.get("temperature_slope") if isinstance(sig, dict) else getattr(sig, "temperature_slope", None))
        if slope is None or i >= len(slope) or not math.isfinite(float(slope[i])):
            return None
        return float(slope[i])

    def _curvature_window(self, est: list[ModeEstimate]) -> tuple[CurvatureChange, np.ndarray, CurvatureStatistic] | None:
        """This window's identified shapes into the modes' curvature averages, and the averages'
        change against the baseline: (change index, Δκ (modes, len(η)), the chart's statistic), or
        None while no mode has a shape.

        A mode's shape enters when the subspace identification found it (confidence at least
        ``min_confidence``) and its MAC with the baseline's shape reaches ``curvature_mac_min`` (a
        different mode, or a spurious pole, is no evidence of a changed shape). Its mode-shape
        curvature (unit RMS, signed against the baseline's) is averaged with an EWMA of
        ``curvature_memory_windows`` windows, and judged once it holds that many. The average's
        healthy covariance is the baseline's one-window covariance C, scaled up by the present
        scatter of a window's shape when that is larger (a weaker mode, a storm's broadband error:
        an EWMA of each window's squared deviation from the average before it), times the EWMA's
        Σ w², inflated for successive windows' correlation, plus the baseline average's own
        C/n_eff; :func:`analytics.curvature_statistic` adds the tolerance ``curvature_min_std`` per
        station."""
        bl, c = self.baseline, self.config
        if bl.curvature_covariance is None:  # a stored state whose baseline predates the index
            return None
        K = np.asarray(bl.curvature_shapes, dtype=float)
        C = np.asarray(bl.curvature_covariance, dtype=float)
        m = K.shape[0]
        base_var = np.einsum("ijj->ij", C)
        if self._kappa is None or self._kappa.shape != K.shape:
            self._kappa, self._kappa_share, self._kappa_n = np.zeros_like(K), np.ones(m), np.zeros(m, dtype=int)
        if self._kappa_var is None or self._kappa_var.shape != K.shape:
            self._kappa_var = base_var.copy()
        a = 1.0 / c.curvature_memory_windows
        r = min(max(bl.curvature_index_rho, 0.0), 0.95)
        corr = (1 + r * (1 - a)) / (1 - r * (1 - a))  # successive windows' correlation, in an EWMA
        for i, e in enumerate(est[:m]):
            if not self._curvature_charted(i) or e.method != "ssi" or e.shape is None or e.confidence < c.min_confidence:
                continue
            if e.mac is None or e.mac < c.curvature_mac_min:
                continue
            try:
                k = mode_shape_curvature([e.shape], self.S, K[i][None])[0]
            except ValueError:
                continue
            if self._kappa_n[i] == 0:
                self._kappa[i], self._kappa_share[i] = k, 1.0
            else:
                # E[(κ_k − κ̄_{k−1})²] = σ²(1 + share·corr) for a healthy window: its σ² estimate
                self._kappa_var[i] = (1 - a) * self._kappa_var[i] + a * (k - self._kappa[i]) ** 2 / (1 + self._kappa_share[i] * corr)
                self._kappa[i] = (1 - a) * self._kappa[i] + a * k
                self._kappa_share[i] = (1 - a) ** 2 * self._kappa_share[i] + a * a
            self._kappa_n[i] += 1
        # a mode is judged once its average has settled over the memory: its first windows say
        # little of the present scatter, and one window's outlier would weigh as an average
        have = self._kappa_n >= math.ceil(c.curvature_memory_windows)
        if not have.any():
            return None
        n_eff = np.maximum(1.0, np.asarray(bl.curvature_mode_windows[:m], dtype=float) * (1 - r) / (1 + r))
        # a window's scatter now, against the baseline's (its correlation over η kept): a weaker
        # mode or a stronger broadband error (a storm) scatters the shapes more, never less
        bend = self._bending
        ratio = np.sum(self._kappa_var[:, bend], axis=1) / np.maximum(np.sum(base_var[:, bend], axis=1), 1e-300)
        gain = np.maximum(1.0, ratio)
        cov = C * (self._kappa_share * corr * gain + 1.0 / n_eff)[:, None, None]
        delta = np.where(have[:, None], self._kappa - K, 0.0)
        stat = curvature_statistic(delta, cov, c.curvature_min_std, have[:, None] & self._bending[None, :])
        change = curvature_change(self._kappa[have], K[have], self.eta, self.length)
        return change, delta, stat

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
        """The charts whose alarm (the alarm logic's, not a single window's level) stands at "alarm"."""
        if self.baseline is None:
            return []
        raised = self.alarms.raised()
        if location is not None:
            where = {"eta_m": location.eta_m, "third": location.third, "damage_kind": location.kind_best,
                     "location_match": round(location.best_match, 3), "located_by": "signatures"}
        else:
            where = {"eta_m": None, "third": None} if change is None else {"eta_m": change.eta_m, "third": change.third, "located_by": "curvature"}
        out = []
        for i, ch in enumerate(self._charts):
            m = self.baseline.modes[i]
            name = chart_name("frequency", m.mode)
            if raised.get(name) != "alarm":
                continue
            score = scores[i] if scores[i] is not None else ch.state.ewma / ch.sigma()
            out.append({
                "kind": "frequency", "mode": m.mode, "unit": m.unit + 1, "level": "alarm",
                "sigma": round(float(score), 2), "percent": round(100 * ch.state.ewma * m.sigma_rel, 4),
                "since_s": self.alarms.since(name), **where,
            })
        if raised.get(CURVATURE_CHART) == "alarm" and self._ci_chart is not None:
            out.append({
                "kind": "curvature", "mode": None, "unit": None, "level": "alarm",
                "sigma": None if ci_score is None else round(float(ci_score), 2),
                "percent": None if change is None else round(100 * change.total, 2),
                "since_s": self.alarms.since(CURVATURE_CHART), **where,
            })
        return out

    def fit_baseline(self) -> Baseline | None:
        """The baseline of every trusted window seen so far (``learn="record"``), without arming it;
        None before the first trusted window."""
        if self._first_trusted is None:
            return None
        end = self._records[-1].t_mid if self._records else self._first_trusted
        return self._fit_baseline(end + 0.5 * self.config.window_s)

    def _fit_baseline(self, t_end: float) -> Baseline | None:
        c = self.config
        recs = self._records
        modes = []
        for i in range(self.n_modes):
            sel = [(r.freqs[i], r.temperature, r.shapes[i] if i < len(r.shapes) else None, r.stds[i] if i < len(r.stds) else None)
                   for r in recs if r.freqs[i] is not None and r.confs[i] >= c.min_confidence]
            shape = ()
            shapes = [np.asarray(s[2], dtype=float) for s in sel if s[2] is not None and len(s[2]) == self.gamma]
            if shapes:
                ref = shapes[0]
                acc = np.sum([s * (1.0 if s @ ref >= 0 else -1.0) for s in shapes], axis=0)
                nrm = np.linalg.norm(acc)
                if nrm > 0:
                    acc = acc / nrm
                    shape = tuple(float(v) for v in acc * (1.0 if acc[int(np.argmax(np.abs(acc)))] > 0 else -1.0))
            if len(sel) < c.baseline_min_windows:
                modes.append(BaselineMode(i + 1, self.units[i], self.ref[i], 20.0, 0.0, 1.0, 0.0, len(sel), shape))
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
            # a few windows underrate the scatter now and then; each window's own jackknife 1σ is
            # an independent measure of it, so the baseline takes the larger of the two
            stated = [s[3] / s[0] for s in sel if s[3] is not None and math.isfinite(s[3]) and s[3] > 0]
            sig = max(sig, float(np.median(stated)) if stated else 0.0, c.min_sigma_rel)
            modes.append(BaselineMode(i + 1, self.units[i], fref0 * (1 + a), tm, slope, sig, _lag1(res), len(sel), shape))
        K, C, counts, rho, shape_std, q_std, with_shape = self._fit_curvature(modes)
        return Baseline(tuple(modes), K, 1.0, q_std, rho, float(self._first_trusted), float(t_end), shape_std, with_shape,
                        self._trusted, float(c.window_s), C, counts)

    def _fit_curvature(self, modes: list[BaselineMode]) -> tuple:
        """The curvature baseline from the learnt windows' identified shapes: per mode the average
        mode-shape curvature (signed by its own unit deformation, as ``estimator.damage_signatures``),
        one window's covariance about it over the stations (windows whose shape's MAC with the
        baseline shape is below ``curvature_mac_min`` left out), the windows behind it; the pooled
        lag-1 correlation of successive windows' deviations, each mode's pooled 1σ, the
        statistic's healthy std for a settled average, and the windows with any shape."""
        c = self.config
        n_eta = self.eta.size
        K, C = np.zeros((self.n_modes, n_eta)), np.zeros((self.n_modes, n_eta, n_eta))
        counts, shape_std = [0] * self.n_modes, [0.0] * self.n_modes
        num = den = 0.0
        seen: set[int] = set()
        for i, bm in enumerate(modes):
            if len(bm.shape) != self.gamma:
                continue
            mean = np.asarray(bm.shape, dtype=float)
            rows = [(k, np.asarray(r.shapes[i], dtype=float)) for k, r in enumerate(self._records)
                    if r.freqs[i] is not None and r.confs[i] >= c.min_confidence and i < len(r.shapes) and r.shapes[i] is not None
                    and len(r.shapes[i]) == self.gamma]
            rows = [(k, p) for k, p in rows if float(modal_assurance(p[None], mean[None])[0, 0]) >= c.curvature_mac_min]
            if len(rows) < 2:
                continue
            try:
                k0 = mode_shape_curvature(mean[None], self.S, np.array([self.units[i]]))
                Kw = mode_shape_curvature(np.array([p for _, p in rows]), self.S, np.repeat(k0, len(rows), axis=0))
            except ValueError:
                continue
            kbar = Kw.mean(axis=0)
            kbar /= float(np.sqrt(np.mean(kbar**2)))
            D = Kw - kbar
            K[i], C[i], counts[i] = kbar, D.T @ D / (len(rows) - 1), len(rows)
            shape_std[i] = float(np.sqrt(np.mean(np.diag(C[i]))))
            seen.update(k for k, _ in rows)
            idx = [k for k, _ in rows]
            for j in range(len(rows) - 1):  # successive windows' deviations (the same mode, adjacent windows)
                if idx[j + 1] == idx[j] + 1:
                    num += float(D[j] @ D[j + 1])
                    den += float(D[j] @ D[j])
        rho = float(np.clip(num / den, 0.0, 0.95)) if den > 0 else 0.0
        ok = np.array([n >= c.baseline_min_windows for n in counts])
        q_std = 0.0
        if ok.any():
            a = 1.0 / c.curvature_memory_windows
            corr = (1 + rho * (1 - a)) / (1 - rho * (1 - a))
            n_eff = np.maximum(1.0, np.asarray(counts, dtype=float) * (1 - rho) / (1 + rho))
            cov = C * (a / (2 - a) * corr + 1.0 / n_eff)[:, None, None]
            q_std = curvature_statistic(np.zeros_like(K), cov, c.curvature_min_std, ok[:, None] & self._bending[None, :]).q_std
        return K, C, tuple(counts), rho, tuple(shape_std), q_std, len(seen)

    # -- persistence -----------------------------------------------------------------------
    def state_dict(self) -> dict:
        """JSON-safe state for a restart (tracker, baseline or its learning data, charts, alarms)."""
        return {
            "fs": self.fs, "config": self.config.model_dump(), "curvature_shapes": self.S.tolist(), "stations_eta": self.eta.tolist(),
            "length": self.length, "units": self.units, "f0": self.f0, "ref": self.ref, "learn": self.learn,
            "baseline": None if self.baseline is None else self.baseline.to_dict(),
            "records": [{**vars(r), "shapes": [None if s is None else list(s) for s in r.shapes]} for r in self._records],
            "first_trusted": self._first_trusted, "trusted": self._trusted,
            "kappa": None if self._kappa is None else self._kappa.tolist(),
            "kappa_share": None if self._kappa_share is None else self._kappa_share.tolist(),
            "kappa_n": None if self._kappa_n is None else self._kappa_n.tolist(),
            "kappa_var": None if self._kappa_var is None else self._kappa_var.tolist(),
            "power": None if self._power is None else self._power.tolist(),
            "charts": [ch.state_dict() for ch in self._charts],
            "ci_chart": None if self._ci_chart is None else self._ci_chart.state_dict(),
            "alarms": self.alarms.state_dict(),
            "tracker": self.tracker.state_dict(),
            "own_baseline": self._own_baseline,
        }

    @classmethod
    def from_state_dict(cls, d: dict) -> "ModalMonitor":
        if not isinstance(d, dict):
            raise ValueError(f"state must be a dict, got {type(d).__name__}")
        try:
            m = cls(None, d["curvature_shapes"], d["stations_eta"], fs=d["fs"], config=AnalysisConfig(**d["config"]), beam_length=d["length"],
                    learn=d.get("learn", "period"))
            m.units, m.f0, m.ref = list(d["units"]), list(d["f0"]), list(d["ref"])
            m.baseline = None if d["baseline"] is None else Baseline.from_dict(d["baseline"])
            m._own_baseline = bool(d.get("own_baseline", True))  # a state stored before: as it charted then
            m._records = [_Record(r["t_mid"], r["temperature"], r["freqs"], r["confs"],
                                  [None if s is None else tuple(s) for s in r.get("shapes", [])], list(r.get("stds", []))) for r in d["records"]]
            m._first_trusted = d["first_trusted"]
            m._trusted = int(d.get("trusted", len(m._records)))
            # a state stored before the curvature index was built from mode shapes starts its averages afresh
            if d.get("kappa") is not None and d.get("kappa_share") is not None and d.get("kappa_n") is not None:
                m._kappa = np.asarray(d["kappa"], dtype=float)
                m._kappa_share = np.asarray(d["kappa_share"], dtype=float)
                m._kappa_n = np.asarray(d["kappa_n"], dtype=int)
                m._kappa_var = None if d.get("kappa_var") is None else np.asarray(d["kappa_var"], dtype=float)
            m._power = None if d.get("power") is None else np.asarray(d["power"], dtype=float)
            m._charts = [EwmaChart.from_state_dict(c) for c in d["charts"]]
            m._ci_chart = None if d["ci_chart"] is None else EwmaChart.from_state_dict(d["ci_chart"])
            m.alarms = AlarmLogic(raise_windows=m.config.hold_windows, clear_windows=m.config.clear_windows,
                                  clear_sigma=m.config.clear_sigma, state=d.get("alarms"))
            if d.get("tracker") is not None:  # states stored before tracks: new ids
                m.tracker = ModeTracker.from_state_dict(d["tracker"])
        except KeyError as exc:
            raise ValueError(f"state dict lacks {exc}") from exc
        return m
