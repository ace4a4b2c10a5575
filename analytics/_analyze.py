"""analyze() and learn_baseline(): the engine over a whole record, and the record's modes."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._config import AnalysisConfig
from ._damping import DampingEstimate, bandpass, combine_estimates, envelope_decay, find_decay_segments, random_decrement, _edge_s
from ._engine import MonitoringEngine
from ._monitor import Baseline, BaselineError, ModalMonitor, WindowResult, _none, _round
from ._oma import IdentifiedMode, OmaConfig, identify_modes, prepare_band, subspace_damping
from ._peaks import find_peaks
from ._spectrum import Spectrum, _spectrum_of
from ._ssi import modal_assurance
from ._validate import as_signal, as_times, check_fs

__all__ = ["AnalysisResult", "ModeSummary", "analyze", "learn_baseline"]

_NS = 1_000_000_000


@dataclass(frozen=True)
class ModeSummary:
    """One tracked mode over the record.

    frequency_hz : Hz, from a subspace identification of the record's trusted windows together
    (method "ssi"; "ssi_windows": the mean of the windows' subspace estimates where the record's
    identification shows no such mode; "spectrum": the peak of the windows' averaged amplitude
    spectra where neither does); frequency_std_hz its 1σ. damping_ratio, damping_std,
    damping_method : the preferred estimate of ``damping`` (free decays where the record has
    them, else the record's subspace pole, else random decrement); damping : every estimate the
    record allows, each with its method and 1σ. mpc, mac : of the record's shape (MAC against the
    baseline's). spectral_hz : the averaged spectrum's peak (the cross-check). confidence : mean
    of the windows'; windows : windows with a usable subspace estimate.
    """

    mode: int
    unit: int
    frequency_hz: float | None
    frequency_std_hz: float | None
    damping_ratio: float | None
    damping_std: float | None
    damping_method: str | None
    confidence: float
    windows: int
    method: str | None = None
    damping: tuple[DampingEstimate, ...] = ()
    mpc: float | None = None
    mac: float | None = None
    spectral_hz: float | None = None
    plane: str = "zeta"  # the bending plane of the mode: "zeta" (the planar contract's) or "xi"

    def as_dict(self) -> dict:
        return {
            "unit": self.unit, "mode": self.mode,
            "frequency_hz": _none(self.frequency_hz), "frequency_std_hz": _none(self.frequency_std_hz),
            "damping_ratio": _none(self.damping_ratio), "damping_std": _none(self.damping_std),
            "damping_method": self.damping_method, "confidence": round(self.confidence, 4), "windows": self.windows,
            "method": self.method, "mpc": _round(self.mpc, 4), "mac": _round(self.mac, 4), "spectral_hz": _none(self.spectral_hz),
            "damping": [{"method": d.method, "damping_ratio": _none(d.damping_ratio), "damping_std": _none(d.damping_std)}
                        for d in self.damping],
            "plane": self.plane,
        }


@dataclass(frozen=True)
class AnalysisResult:
    """modes (one per tracked mode), windows (per analysis window), flags (alarms raised during the
    record, each once, at its latest state), baseline (given or learnt; None if none could be
    learnt), skipped (windows not analysed: "incomplete", "warmup")."""

    modes: tuple[ModeSummary, ...]
    windows: tuple[WindowResult, ...]
    flags: tuple[dict, ...]
    baseline: Baseline | None
    skipped: dict | None = None
    config: AnalysisConfig | None = None
    loads: tuple = ()  # per window (contract.LoadsWindowDocument, its fatigue AlarmEvents), with hot spots
    tracks: tuple = ()  # analytics.ModeTrack: each subspace mode followed across the windows (the engine's tracker)
    usability: dict | None = None  # analytics.usability_document of the windows: why none is usable, when none is
    xi: AnalysisResult | None = None  # a biaxial beam: the ξ plane's analysis (this one is the ζ plane's)
    degenerate: tuple = ()  # a biaxial beam: analytics.DegeneratePair of the two planes' modes

    def as_dict(self) -> dict:
        """JSON-safe {"modes": [...], "windows": [...], "flags": [...], "baseline": {...}} (None instead of NaN)."""
        bl = None
        if self.baseline is not None:
            problems = self.baseline.problems(self.config or AnalysisConfig())
            bl = {"start_s": self.baseline.start_s, "end_s": self.baseline.end_s,
                  "modes": [{"mode": m.mode, "unit": m.unit + 1, "f_ref_hz": m.f_ref_hz, "temperature_ref_c": m.temperature_ref_c,
                             "slope_per_k": m.slope_per_k, "sigma_rel": m.sigma_rel, "windows": m.windows,
                             "charted": m.mode not in problems, "reason": problems.get(m.mode)} for m in self.baseline.modes]}
        out = {"modes": [m.as_dict() for m in self.modes], "windows": [w.as_dict() for w in self.windows],
               "flags": [dict(f) for f in self.flags], "baseline": bl, "skipped_windows": dict(self.skipped or {}),
               "tracks": [t.as_dict() for t in self.tracks], "usability": self.usability}
        if self.xi is not None:
            self._add_xi(out)
        if self.loads:
            out["loads"] = [{**doc.model_dump(mode="json"), "alarm_events": [{"action": e.action, "chart": e.chart, "level": e.level,
                                                                               "at_s": e.at_s, "message": e.message()} for e in events]}
                            for doc, events in self.loads]
        return out


    def _add_xi(self, out: dict) -> None:
        """The ξ plane's modes after the ζ plane's, every flag naming its plane, the ξ plane's windows,
        baseline and tracks under ``*_xi`` keys, and the degenerate pairs."""
        if self.xi is None:
            raise ValueError("a planar analysis has no xi plane to add")
        xi = self.xi.as_dict()
        out["modes"] += xi["modes"]
        out["flags"] = [{**f, "plane": "zeta"} for f in out["flags"]] + [{**f, "plane": "xi"} for f in xi["flags"]]
        for key in ("windows", "baseline", "skipped_windows", "tracks", "usability"):
            out[f"{key}_xi"] = xi[key]
        out["degenerate_pairs"] = [p.as_dict() for p in self.degenerate]


def _above_floor(y: np.ndarray, s: int, e: int, fs: float, trim: float) -> int:
    """End of the part of a decay [s, e) whose envelope stays above 1/30 of its start (about 3.4
    time constants): a fit that runs into the noise floor flattens the decay and underrates the
    damping of the faster modes."""
    from scipy.signal import hilbert

    env = np.abs(hilbert(y[s:e]))
    k = max(1, int(trim * fs))
    if env.size <= 3 * k:
        return e
    start = float(np.median(env[k : 2 * k]))
    below = np.flatnonzero(env[2 * k :] < start / 30.0)
    return e if below.size == 0 else min(e, s + 2 * k + int(below[0]) + k)


def _free_decay_damping(x: np.ndarray, fs: float, f: float, bearing: np.ndarray | None, cfg: AnalysisConfig) -> DampingEstimate | None:
    """Damping of the mode near f (Hz) from the free decays of x (N,): after each support motion
    (when the support displacement is known), else where the band-passed envelope falls steadily."""
    if x.size < 16 or f * (1 + cfg.bandpass_rel) >= fs / 2:
        return None
    try:
        segs = find_decay_segments(x, fs, f, bearing=bearing, bearing_threshold=cfg.bearing_threshold_m, min_cycles=cfg.decay_min_cycles,
                                   rel_half_width=cfg.bandpass_rel)
    except ValueError:
        return None
    if not segs:
        return None
    y = bandpass(x, fs, f, rel_half_width=cfg.bandpass_rel)
    trim = _edge_s(f, cfg.bandpass_rel)
    ests = []
    for s, e in segs:
        e = _above_floor(y, s, e, fs, trim)
        if (e - s) / fs - 2 * trim < cfg.decay_min_cycles / (2 * f):
            continue
        try:
            est = envelope_decay(y[s:e], fs, trim_s=trim)
        except ValueError:
            continue
        if 0 < est.damping_ratio < 0.5 and abs(est.frequency_hz / f - 1) < cfg.bandpass_rel:
            ests.append(est)
    if not ests:
        return None
    est = combine_estimates(ests)
    return DampingEstimate(est.damping_ratio, est.damping_std, est.frequency_hz, "free_decay", est.cycles, est.segments)


def _spans(windows: tuple[WindowResult, ...], times: np.ndarray, zero_s: float) -> list[tuple[int, int]]:
    """Sample index ranges of the record covered by trusted windows, merged where they touch."""
    out: list[tuple[int, int]] = []
    for w in windows:
        if not w.trusted:
            continue
        s, e = (int(v) for v in np.searchsorted(times, [w.start_s - zero_s, w.end_s - zero_s]))
        if out and s <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], e))
        else:
            out.append((s, e))
    return out


#: Cycles of the slowest tracked mode in each segment of the record's jackknife.
_SEGMENT_CYCLES = 40.0
#: SVD budget of the record's identification (block rows × channels).
_RECORD_SVD_BUDGET = 480


def _record_identification(B: np.ndarray, fs: float, spans: list[tuple[int, int]], cfg: OmaConfig, slowest_hz: float | None = None):
    """The subspace modes of the trusted spans together: each span band-prepared on its own (no
    filter runs across a gap), the prepared spans joined (a few Hankel columns per joint).

    The correlation lags span a full period of the slowest tracked mode (``slowest_hz``; else half
    a period of the band's lower edge) within an SVD budget of i·l ≤ 480: a record has far more
    samples than a window and affords the lags a slow mode needs. Each frequency's 1σ is the
    delete-one jackknife over segments of the record holding ≥ 40 cycles of the slowest mode each
    (3 … 12 segments), each left-out record identified anew (not to first order), widened by
    Student's t: it holds for the slow modes where the first-order jackknife of a window underrates
    the scatter, and unlike batch means of the segments' own estimates it does not overrate it."""
    parts = []
    fsb = fs
    for s, e in spans:
        try:
            yb, fsb = prepare_band(B[s:e], fs, fmin_hz=cfg.fmin_hz, fmax_hz=cfg.fmax_hz)
        except ValueError:
            continue
        parts.append(yb)
    if not parts:
        return None, None
    y = np.concatenate(parts)
    slow = slowest_hz if slowest_hz is not None and slowest_hz > 0 else 2 * max(cfg.fmin_hz, 1e-3)
    rows = int(min(max(math.ceil(fsb / slow), 12), max(12, _RECORD_SVD_BUDGET // B.shape[1]), max(4, y.shape[0] // 10)))
    segments = int(np.clip(math.floor(y.shape[0] / fsb * slow / _SEGMENT_CYCLES), 3, 12))
    try:
        # the record's estimate is the mean over its trusted spans: a mode drifting with the
        # temperature over the record is followed by the windows, not split here
        return identify_modes(y, fsb, config=cfg.model_copy(update={"block_rows": rows, "moving_modes": False, "segments": segments,
                                                                    "uncertainty": "delete-one"}), band_ready=True), y
    except (ValueError, np.linalg.LinAlgError):
        return None, None


def _pick(modes: tuple[IdentifiedMode, ...], f_ref: float, unit: int, shape_ref: np.ndarray | None, rel: float,
          taken: set[int], similarity_min: float) -> int | None:
    best, best_cost = None, math.inf
    for j, m in enumerate(modes):
        if j in taken:
            continue
        dev = abs(math.log(m.frequency_hz / f_ref)) / rel
        if dev > 1:
            continue
        shape = np.asarray(m.shape)
        sim = float(modal_assurance(shape[None], shape_ref[None])[0, 0]) if shape_ref is not None else float(shape[unit] ** 2 / (shape @ shape))
        if sim < similarity_min:
            continue
        cost = dev**2 + (1 - sim) - 0.1 * m.contribution
        if cost < best_cost:
            best, best_cost = j, cost
    return best


def _summaries(mon: ModalMonitor, windows: tuple[WindowResult, ...], B: np.ndarray, t: np.ndarray, d: np.ndarray | None, fs: float,
               cfg: AnalysisConfig, zero_s: float) -> tuple[ModeSummary, ...]:
    trusted = [w for w in windows if w.trusted]
    n = int(round(cfg.window_s * fs))
    spans = _spans(windows, t, zero_s)
    ocfg = mon.oma_config
    ident = y_band = None
    if ocfg is not None and spans:
        ident, y_band = _record_identification(B, fs, spans, ocfg, min(mon.ref) if mon.ref else None)
    # the averaged power spectra of the trusted windows: the record's cross-check
    power = None
    for w in trusted:
        k0 = int(np.searchsorted(t, w.start_s - zero_s))
        if k0 + n <= B.shape[0]:
            _, X, _ = _spectrum_of(B[k0: k0 + n], fs, cfg.pad_factor, cfg.window, True)
            p = np.abs(X) ** 2
            power = p if power is None else power + p
    avg = None
    if power is not None:
        freqs = np.fft.rfftfreq(cfg.pad_factor * n, 1 / fs)
        avg = Spectrum(freqs, np.sqrt(power), fs / n, fs / (cfg.pad_factor * n), 0.0, 0.0, 0.0, cfg.window, n, cfg.pad_factor)
    free = bool(trusted) and sum(w.kind == "free_decay" for w in trusted) >= 0.25 * len(trusted)
    first = int(np.searchsorted(t, trusted[0].start_s - zero_s)) if trusted else 0
    refs = mon._baseline_shapes()
    taken: set[int] = set()
    out = []
    indep = 1.0 - cfg.overlap
    for i in range(mon.n_modes):
        u = mon.units[i]
        vals = [w.estimates[i] for w in trusted if i < len(w.estimates)]
        good = [e for e in vals if e.frequency_hz is not None and e.method == "ssi" and e.confidence >= cfg.min_confidence]
        f_windows = float(np.median([e.frequency_hz for e in good])) if good else None
        f_ref = f_windows or mon.ref[i]
        method = f_hz = f_std = mpc = mac = None
        damping: list[DampingEstimate] = []
        shape = None
        if ident is not None:
            j = _pick(ident.modes, f_ref, u, refs[i], cfg.search_rel, taken, cfg.track_similarity_min)
            if j is not None:
                taken.add(j)
                m = ident.modes[j]
                method, f_hz, f_std, mpc = "ssi", m.frequency_hz, m.frequency_std_hz, m.mpc
                shape = np.asarray(m.shape)
                mac = None if refs[i] is None else float(modal_assurance(shape[None], refs[i][None])[0, 0])
                if math.isfinite(m.damping_ratio) and m.damping_ratio > 0 and m.damping_std is not None:
                    damping.append(subspace_damping(m))
        if len(good) >= 2:
            # the windows' subspace frequencies, averaged: the record's estimate when the record-long
            # identification found no pole, or one it states less precisely than they agree (a weak
            # mode whose record-long pole a neighbouring one pulls: the windows' spread is the measure)
            fv = np.array([e.frequency_hz for e in good])
            w_std = float(np.std(fv, ddof=1) / math.sqrt(max(1.0, len(good) * indep)))
            if f_hz is None or not (f_std is not None and math.isfinite(f_std) and f_std <= w_std):
                method, f_hz, f_std = "ssi_windows", float(np.mean(fv)), w_std
        spectral = None
        if avg is not None:
            ref = f_hz or mon.f0[i]
            pk = find_peaks(avg, column=u, fmin=ref * (1 - cfg.search_rel), fmax=min(ref * (1 + cfg.search_rel), fs / 2),
                            min_prominence=cfg.min_prominence)
            if pk:
                spectral = min(pk, key=lambda p: abs(p.frequency_hz - ref)).frequency_hz
        if f_hz is None and spectral is not None:
            method, f_hz = "spectrum", spectral
        if f_hz is not None and first < B.shape[0]:
            x = B[first:, u] if shape is None else (B[first:] - B[first:].mean(axis=0)) @ shape
            if free:
                fd = _free_decay_damping(B[first:, u], fs, f_hz, None if d is None else d[first:], cfg)
                if fd is not None:
                    damping.insert(0, fd)
            try:
                # about nine samples per period are plenty for the band-passed signature: decimate first
                xb, fsb = prepare_band(x, fs, fmax_hz=min(3.0 * f_hz, 0.45 * fs)) if 3.0 * f_hz < 0.15 * fs else (x, fs)
                damping.append(random_decrement(xb[:, 0] if xb.ndim == 2 else xb, fsb, f_hz, rel_half_width=cfg.bandpass_rel,
                                                duration_cycles=cfg.rd_cycles))
            except ValueError:
                pass
        primary = _preferred(damping, free)
        conf = float(np.mean([e.confidence for e in vals])) if vals else 0.0
        out.append(ModeSummary(i + 1, u + 1, f_hz, f_std, None if primary is None else primary.damping_ratio,
                               None if primary is None else primary.damping_std, None if primary is None else primary.method, conf,
                               len(good), method, tuple(damping), mpc, mac, spectral))
    return tuple(out)


def _preferred(estimates: list[DampingEstimate], free: bool) -> DampingEstimate | None:
    """Free decays where the record is made of them; else, of the record's subspace pole (no
    assumption on the input's colour, measured across all windows together) and the random
    decrement, the one with the smaller stated 1σ (the subspace pole's when the two are alike
    within a factor 2; a weak mode's record-long pole can be far less certain than its signature)."""
    by = {e.method: e for e in estimates}
    if free and "free_decay" in by:
        return by["free_decay"]
    ssi, rd = by.get("ssi"), by.get("random_decrement")
    if ssi is not None and rd is not None:
        sharper = math.isfinite(rd.damping_std) and rd.damping_std > 0 and not ssi.damping_std <= 2.0 * rd.damping_std
        return rd if sharper else ssi
    for method in ("ssi", "random_decrement", "free_decay"):
        if method in by:
            return by[method]
    return None


def _prepare(times_s, b, temperature, bearing, fs):
    fs = check_fs(fs)
    B = as_signal("b", b, min_len=16, ndim=(2,))
    t = as_times("times_s", times_s, B.shape[0])
    d = None if bearing is None else as_signal("bearing", bearing, min_len=1, ndim=(1,))
    if d is not None and d.size != B.shape[0]:
        raise ValueError(f"bearing has {d.size} samples, b has {B.shape[0]}")
    temp = None
    if temperature is not None:
        if not (isinstance(temperature, (tuple, list)) and len(temperature) == 2):
            raise ValueError(f"temperature must be (times, values) or None, got {type(temperature).__name__}")
        temp_t = as_times("temperature times", temperature[0])
        temp_v = as_signal("temperature values", temperature[1], min_len=1, ndim=(1,))
        if temp_v.size != temp_t.size:
            raise ValueError(f"temperature has {temp_t.size} times and {temp_v.size} values")
        temp = (temp_t, temp_v)
    return fs, B, t, d, temp


def _run(times_s, b, curvature_shapes, stations_eta, *, fs, temperature, bearing, expected_hz, baseline, config, beam_length,
         signatures, time_origin_ns, not_before_s, learn, loads=None, gauges=None):
    cfg = config or AnalysisConfig()
    if not isinstance(cfg, AnalysisConfig):
        raise ValueError(f"config must be an AnalysisConfig, got {type(cfg).__name__}")
    fs, B, t, d, temp = _prepare(times_s, b, temperature, bearing, fs)
    if isinstance(baseline, dict):
        baseline = Baseline.from_dict(baseline)
    elif baseline is not None and not isinstance(baseline, Baseline):
        raise ValueError(f"baseline must be a Baseline, its dict or None, got {type(baseline).__name__}")
    n = int(round(cfg.window_s * fs))
    if n < 16 or n > B.shape[0]:
        raise ValueError(f"config.window_s={cfg.window_s} gives {n} samples; the record has {B.shape[0]} (needs 16 .. N)")
    if isinstance(time_origin_ns, bool) or not isinstance(time_origin_ns, (int, np.integer)):
        raise ValueError(f"time_origin_ns={time_origin_ns!r} must be an integer (ns)")
    mon = ModalMonitor(expected_hz, curvature_shapes, stations_eta, fs=fs, config=cfg, baseline=baseline, beam_length=beam_length,
                       signatures=signatures, learn=learn)
    origin = int(time_origin_ns)
    not_before = None if not_before_s is None else origin + int(round(float(not_before_s) * _NS))
    engine = MonitoringEngine(mon, origin_ns=origin, time_zero_ns=origin, not_before_ns=not_before, loads=loads)
    engine_windows = engine.add(t, B, support=d, temperature=temp, gauges=gauges)
    windows = tuple(w.result for w in engine_windows)
    # the hot spots' loads per window and their alarm events, when the engine has loads
    loads_windows = tuple((w.loads, w.loads_events) for w in engine_windows if w.loads is not None)
    return cfg, fs, B, t, d, mon, engine, windows, loads_windows


def analyze(
    times_s: object,
    b: object,
    curvature_shapes: object,
    stations_eta: object,
    *,
    fs: float = 200.0,
    temperature: tuple | None = None,
    bearing: object | None = None,
    expected_hz: object | None = None,
    baseline: Baseline | dict | None = None,
    config: AnalysisConfig | None = None,
    beam_length: float | None = None,
    signatures: object | None = None,
    time_origin_ns: int = 0,
    not_before_s: float | None = None,
    loads: object | None = None,
    gauges: dict[str, tuple[object, object]] | None = None,
) -> AnalysisResult:
    """Modal analytics of a record: the engine's windows (:class:`analytics.MonitoringEngine`, the
    same as ``shm serve``'s) and the record's modes.

    Parameters
    ----------
    times_s : (N,) s after ``time_origin_ns``; b : (N, Γ) deformation variables (m).
    curvature_shapes : (len(η), Γ) s''_χ (1/m²) at stations_eta (len(η),) m from the bearing.
    fs : sample rate of b (Hz).
    temperature : (times (M,) s after time_origin_ns, values (M,) °C) or None.
    bearing : (N,) support displacement on the times of b (m): the bearing sensor or the
        estimator's d; the measured input (excitation class, FRFs, free decays). None: output only.
    expected_hz : per unit deformation the model's eigenfrequencies (Hz, ``UnitDeformations.frequencies_hz``)
        or None (the largest peak per unit).
    baseline : Baseline or its dict, or None (learnt from the first config.baseline_s seconds).
    signatures : predicted damage signatures at stations_eta (``estimator.damage_signatures(rig,
        stations_eta)``, or an object/dict with eta, kind, frequency_shift, curvature_change) for
        the model-assisted location of flags (see ``ModalMonitor``), or None.
    time_origin_ns : data time (ns, UNIX for a contract recording) of times_s = 0: windows are
        aligned to multiples of the step in data time and reported in s after it.
    not_before_s : windows starting earlier (s after the origin) are not analysed (the filter converging).
    loads : LoadsMonitor or None: the hot spots' loads and fatigue, per window.
    gauges : measured strain by gauge name, (times s after time_origin_ns, values m/m), for the
        loads' DEL bands (the monitor's gauges), or None: the windows' loads carry no band.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    ValueError
        For inputs of the wrong shape, non-finite values, a window longer than the record, or a
        malformed baseline, naming the value.
    """
    cfg, fs, B, t, d, mon, engine, windows, loads_windows = _run(
        times_s, b, curvature_shapes, stations_eta, fs=fs, temperature=temperature, bearing=bearing, expected_hz=expected_hz,
        baseline=baseline, config=config, beam_length=beam_length, signatures=signatures, time_origin_ns=time_origin_ns,
        not_before_s=not_before_s, learn="period", loads=loads, gauges=gauges)
    flags: dict = {}
    for w in windows:
        for f in w.flags:
            flags[(f["kind"], f["mode"], f["since_s"])] = f
    summaries = _summaries(mon, windows, B, t, d, fs, cfg, 0.0)
    return AnalysisResult(summaries, windows, tuple(flags.values()), mon.baseline,
                          {"incomplete": engine.skipped_incomplete, "warmup": engine.skipped_warmup}, cfg, loads_windows,
                          mon.tracker.tracks(), engine.usability())


def learn_baseline(
    times_s: object,
    b: object,
    curvature_shapes: object,
    stations_eta: object,
    *,
    fs: float = 200.0,
    temperature: tuple | None = None,
    bearing: object | None = None,
    expected_hz: object | None = None,
    config: AnalysisConfig | None = None,
    beam_length: float | None = None,
    signatures: object | None = None,
    time_origin_ns: int = 0,
    not_before_s: float | None = None,
) -> Baseline:
    """A baseline learnt from every trusted window of a healthy record (any length, with or
    without a temperature swing: the temperature model is fitted over all of it).

    Parameters are those of :func:`analyze` (without ``baseline``).

    Returns
    -------
    Baseline
        Its ``problems(config)`` names the modes it cannot chart and why.

    Raises
    ------
    BaselineError
        When no mode can be charted: the message names each mode and what it lacked (windows
        with a subspace estimate, minutes of trusted data, cycles per window).
    ValueError
        For bad inputs, as :func:`analyze`.
    """
    cfg, fs, B, t, d, mon, engine, windows, _loads = _run(
        times_s, b, curvature_shapes, stations_eta, fs=fs, temperature=temperature, bearing=bearing, expected_hz=expected_hz,
        baseline=None, config=config, beam_length=beam_length, signatures=signatures, time_origin_ns=time_origin_ns,
        not_before_s=not_before_s, learn="record")
    kinds = {k: sum(w.kind == k for w in windows) for k in ("ambient", "free_decay", "forced", "quiet")}
    skipped = engine.skipped_incomplete + engine.skipped_warmup
    what = (f"{len(windows)} windows of {cfg.window_s:g} s analysed ({', '.join(f'{v} {k}' for k, v in kinds.items())}; "
            f"{skipped} skipped)")
    # the least a record must hold: baseline_min_windows trusted windows on the window grid
    minimum_s = cfg.window_s + (cfg.baseline_min_windows - 1) * cfg.window_s * (1.0 - cfg.overlap)
    need = (f"a baseline needs at least {cfg.baseline_min_windows} trusted windows with each mode "
            f"(analytics.baseline_min_windows): {minimum_s:g} s of ambient data after the rest phase and the filter's warm-up")
    bl = mon.fit_baseline()
    if bl is None:
        raise BaselineError(f"no baseline can be learnt: {what}, and none of them is a trusted window of operational (ambient) "
                            f"data; {need}")
    problems = bl.problems(cfg)
    if len(problems) == len(bl.modes):
        lines = "; ".join(f"mode {m}: {why}" for m, why in sorted(problems.items()))
        raise BaselineError(f"no mode can be charted from this record ({what}): {lines}; {need}")
    return bl
