"""analyze(): the one entry point over a whole record."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._config import AnalysisConfig
from ._damping import DampingEstimate, bandpass, combine_estimates, envelope_decay, find_decay_segments, random_decrement, _edge_s
from ._monitor import Baseline, ModalMonitor, WindowResult, _none
from ._peaks import find_peaks
from ._spectrum import _spectrum_of
from ._validate import as_signal, as_times, check_fs

__all__ = ["ModeSummary", "AnalysisResult", "analyze"]


@dataclass(frozen=True)
class ModeSummary:
    """One tracked mode over the record: frequency (Hz, peak of the Welch-averaged spectrum of the
    trusted windows), its 1σ (per-window scatter / √independent windows), damping ratio ± 1σ
    (from free decays, else random decrement), confidence (mean of the windows'), windows used."""

    mode: int
    unit: int
    frequency_hz: float | None
    frequency_std_hz: float | None
    damping_ratio: float | None
    damping_std: float | None
    damping_method: str | None
    confidence: float
    windows: int

    def as_dict(self) -> dict:
        return {
            "unit": self.unit, "mode": self.mode,
            "frequency_hz": _none(self.frequency_hz), "frequency_std_hz": _none(self.frequency_std_hz),
            "damping_ratio": _none(self.damping_ratio), "damping_std": _none(self.damping_std),
            "damping_method": self.damping_method, "confidence": round(self.confidence, 4), "windows": self.windows,
        }


@dataclass(frozen=True)
class AnalysisResult:
    """modes (one per tracked mode), windows (per analysis window), flags (alarms raised during the
    record, each once, at its latest state), baseline (given or learnt; None if none could be learnt)."""

    modes: tuple[ModeSummary, ...]
    windows: tuple[WindowResult, ...]
    flags: tuple[dict, ...]
    baseline: Baseline | None

    def as_dict(self) -> dict:
        """JSON-safe {"modes": [...], "windows": [...], "flags": [...]} (None instead of NaN)."""
        return {"modes": [m.as_dict() for m in self.modes], "windows": [w.as_dict() for w in self.windows], "flags": [dict(f) for f in self.flags]}


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


def _damping(b: np.ndarray, fs: float, f: float, bearing: np.ndarray | None, free: bool, cfg: AnalysisConfig, start: int) -> DampingEstimate | None:
    x = b[start:]
    d = None if bearing is None else bearing[start:]
    if x.size < 16 or f * (1 + cfg.bandpass_rel) >= fs / 2:
        return None
    ests = []
    if d is not None or free:
        try:
            segs = find_decay_segments(x, fs, f, bearing=d, bearing_threshold=cfg.bearing_threshold_m, min_cycles=cfg.decay_min_cycles, rel_half_width=cfg.bandpass_rel)
        except ValueError:
            segs = []
        if segs:
            y = bandpass(x, fs, f, rel_half_width=cfg.bandpass_rel)
            trim = _edge_s(f, cfg.bandpass_rel)
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
    if ests:
        return combine_estimates(ests)
    if not free:  # ambient: no usable free decay, so random decrement
        try:
            return random_decrement(x, fs, f, rel_half_width=cfg.bandpass_rel, duration_cycles=cfg.rd_cycles)
        except ValueError:
            return None
    return None


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
) -> AnalysisResult:
    """Modal analytics of a record.

    times_s (N,) s, b (N, Γ) deformation variables (m), curvature_shapes (len(η), Γ) s''_χ (1/m²)
    at stations_eta (len(η),) m from the bearing; fs (Hz); temperature (times (M,) s, values (M,)
    °C) or None; bearing displacement (N,) m on the times of b, or None; expected_hz per unit
    deformation (Hz, e.g. UnitDeformations.frequencies_hz) or None (largest peak per unit);
    baseline (Baseline or its dict) or None (learnt from the first config.baseline_s seconds);
    signatures : predicted damage signatures at stations_eta (``estimator.damage_signatures(rig,
    stations_eta)``, or an object/dict with eta, kind, frequency_shift, curvature_change) for the
    model-assisted location of flags (see ``ModalMonitor``), or None.
    """
    cfg = config or AnalysisConfig()
    if not isinstance(cfg, AnalysisConfig):
        raise ValueError(f"config must be an AnalysisConfig, got {type(cfg).__name__}")
    fs = check_fs(fs)
    B = as_signal("b", b, min_len=16, ndim=(2,))
    t = as_times("times_s", times_s, B.shape[0])
    d = None if bearing is None else as_signal("bearing", bearing, min_len=1, ndim=(1,))
    if d is not None and d.size != B.shape[0]:
        raise ValueError(f"bearing has {d.size} samples, b has {B.shape[0]}")
    temp_t = temp_v = None
    if temperature is not None:
        if not (isinstance(temperature, (tuple, list)) and len(temperature) == 2):
            raise ValueError(f"temperature must be (times, values) or None, got {type(temperature).__name__}")
        temp_t = as_times("temperature times", temperature[0])
        temp_v = as_signal("temperature values", temperature[1], min_len=1, ndim=(1,))
        if temp_v.size != temp_t.size:
            raise ValueError(f"temperature has {temp_t.size} times and {temp_v.size} values")
    if isinstance(baseline, dict):
        baseline = Baseline.from_dict(baseline)
    elif baseline is not None and not isinstance(baseline, Baseline):
        raise ValueError(f"baseline must be a Baseline, its dict or None, got {type(baseline).__name__}")
    n = int(round(cfg.window_s * fs))
    if n < 16 or n > B.shape[0]:
        raise ValueError(f"config.window_s={cfg.window_s} gives {n} samples; the record has {B.shape[0]} (needs 16 .. N)")
    step = max(1, int(round(n * (1 - cfg.overlap))))
    mon = ModalMonitor(expected_hz, curvature_shapes, stations_eta, fs=fs, config=cfg, baseline=baseline, beam_length=beam_length,
                      signatures=signatures)
    windows: list[WindowResult] = []
    starts = list(range(0, B.shape[0] - n + 1, step))
    flags: dict = {}
    power = None
    for s in starts:
        tw = t[s : s + n]
        Tw = None
        if temp_t is not None:
            Tw = float(np.mean(np.interp(tw, temp_t, temp_v)))
        w = mon.process_window(tw, B[s : s + n], Tw, None if d is None else d[s : s + n])
        windows.append(w)
        for f in w.flags:
            flags[(f["kind"], f["mode"], f["since_s"])] = f
        if w.trusted:
            _, X, _ = _spectrum_of(B[s : s + n], fs, cfg.pad_factor, cfg.window, True)
            p = np.abs(X) ** 2
            power = p if power is None else power + p
    # one summary per tracked mode
    freqs = np.fft.rfftfreq(cfg.pad_factor * n, 1 / fs)
    n_trusted = sum(w.trusted for w in windows)
    free = n_trusted > 0 and sum(w.kind == "free_decay" for w in windows) >= 0.25 * n_trusted
    first = next((int(round((w.start_s - t[0]) * fs)) for w in windows if w.trusted), 0)
    summaries = []
    indep = 1.0 - cfg.overlap
    from ._spectrum import Spectrum

    avg = None if power is None else Spectrum(freqs, np.sqrt(power), fs / n, fs / (cfg.pad_factor * n), 0.0, 0.0, 0.0, cfg.window, n, cfg.pad_factor)
    for i in range(mon.n_modes):
        u = mon.units[i]
        vals = [w.estimates[i] for w in windows if w.trusted and i < len(w.estimates)]
        good = [e for e in vals if e.frequency_hz is not None and e.confidence >= cfg.min_confidence]
        f_hz = None
        if avg is not None:
            ref = mon.f0[i]
            pk = find_peaks(avg, column=u, fmin=ref * (1 - cfg.search_rel), fmax=min(ref * (1 + cfg.search_rel), fs / 2), min_prominence=cfg.min_prominence)
            if pk:
                f_hz = pk[0].frequency_hz  # the highest peak of the averaged spectrum in the band
        std = None
        if len(good) >= 2:
            fv = np.array([e.frequency_hz for e in good])
            std = float(np.std(fv, ddof=1) / math.sqrt(max(1.0, len(good) * indep)))
            if f_hz is None:
                f_hz = float(np.mean(fv))
        dmp = _damping(B[:, u], fs, f_hz or mon.ref[i], d, free, cfg, first) if (f_hz or mon.ref) else None
        conf = float(np.mean([e.confidence for e in vals])) if vals else 0.0
        summaries.append(ModeSummary(i + 1, u + 1, f_hz, std, None if dmp is None else dmp.damping_ratio, None if dmp is None else dmp.damping_std, None if dmp is None else dmp.method, conf, len(good)))
    return AnalysisResult(tuple(summaries), tuple(windows), tuple(flags.values()), mon.baseline)
