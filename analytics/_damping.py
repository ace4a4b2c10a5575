"""Damping from the time-domain decay: segment detection, mode isolation, decay fits, random decrement."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from ._validate import as_signal, check_fs, positive

__all__ = [
    "DampingEstimate",
    "bandpass",
    "find_decay_segments",
    "log_decrement",
    "envelope_decay",
    "random_decrement",
    "combine_estimates",
]


@dataclass(frozen=True)
class DampingEstimate:
    """A damping ratio ζ (dimensionless, 0.01 = 1 %) with its 1σ uncertainty.

    frequency_hz : damped frequency of the fitted decay (Hz); method : "log_decrement",
    "envelope", "random_decrement" or "combined"; cycles : cycles used; segments : decays combined.
    """

    damping_ratio: float
    damping_std: float
    frequency_hz: float
    method: str
    cycles: float
    segments: int = 1


def _zeta_from_sigma(sigma: float, fd: float) -> float:
    wd = 2 * np.pi * fd
    return float(sigma / np.hypot(sigma, wd))


def bandpass(x: object, fs: float, f_center: float, *, rel_half_width: float = 0.2, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth band-pass (sosfiltfilt) of x (N,) or (N, k) around f_center (Hz).

    The pass band is f_center·(1 ± rel_half_width); its ringing decays far faster than a lightly
    damped mode (bandwidth ≫ 2ζf), so it does not bias the decay rate away from the edges.
    """
    fs = check_fs(fs)
    positive("f_center", f_center)
    positive("rel_half_width", rel_half_width)
    if rel_half_width >= 1:
        raise ValueError(f"{rel_half_width=} must be < 1")
    if f_center * (1 + rel_half_width) >= fs / 2:
        raise ValueError(f"{f_center=} with {rel_half_width=} exceeds the Nyquist frequency {fs / 2} Hz")
    a = as_signal("x", x, min_len=16)
    sos = signal.butter(order, [f_center * (1 - rel_half_width), f_center * (1 + rel_half_width)], btype="bandpass", fs=fs, output="sos")
    return signal.sosfiltfilt(sos, a, axis=0)


def _edge_s(f_center: float, rel_half_width: float) -> float:
    # a few time constants of the band-pass filter (its bandwidth 2·rel·f)
    return 3.0 / (np.pi * 2 * rel_half_width * f_center)


def log_decrement(x: object, fs: float, *, min_cycles: float = 3.0) -> DampingEstimate:
    """Logarithmic decrement of a free decay x (N,) (a single mode, e.g. band-passed), fs in Hz.

    Positive peaks are located (parabolic sub-sample refinement), ln(peak) is fitted linearly
    against time: slope −σ; ζ = σ/√(σ² + ω_d²). σ's standard error gives the uncertainty.

    Examples
    --------
    >>> import numpy as np
    >>> from analytics import log_decrement
    >>> fs, f, zeta = 200.0, 3.0, 0.02
    >>> t = np.arange(0.0, 30.0, 1 / fs)
    >>> x = np.exp(-zeta * 2 * np.pi * f * t) * np.cos(2 * np.pi * f * np.sqrt(1 - zeta**2) * t)
    >>> est = log_decrement(x, fs)
    >>> round(est.damping_ratio, 4), round(est.frequency_hz, 2)
    (0.02, 3.0)
    """
    fs = check_fs(fs)
    a = as_signal("x", x, min_len=16, ndim=(1,))
    idx, _ = signal.find_peaks(a)
    idx = idx[a[idx] > 0]
    if idx.size < max(3, int(np.ceil(min_cycles)) + 1):
        raise ValueError(f"x shows {idx.size} positive peaks; needs at least {min_cycles=} cycles of decay")
    t, amp = [], []
    for i in idx:
        if 0 < i < a.size - 1:
            ym, y0, yp = a[i - 1 : i + 2]
            den = ym - 2 * y0 + yp
            p = 0.5 * (ym - yp) / den if den < 0 else 0.0
            t.append((i + p) / fs)
            amp.append(y0 - 0.25 * (ym - yp) * p)
    t, amp = np.asarray(t), np.asarray(amp)
    fd = (t.size - 1) / (t[-1] - t[0])
    return _fit_log_line(t, np.log(amp), fd, "log_decrement", corr_samples=1.0)


def _fit_log_line(t: np.ndarray, y: np.ndarray, fd: float, method: str, corr_samples: float) -> DampingEstimate:
    A = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    dof = max(1, t.size - 2)
    s2 = float(resid @ resid) / dof
    var_slope = s2 / float(np.sum((t - t.mean()) ** 2)) * max(1.0, corr_samples)
    sigma = -float(coef[1])
    zeta = _zeta_from_sigma(sigma, fd)
    dz = abs(_zeta_from_sigma(sigma + np.sqrt(var_slope), fd) - zeta)
    cycles = float((t[-1] - t[0]) * fd)
    return DampingEstimate(zeta, float(dz), float(fd), method, cycles)


def envelope_decay(x: object, fs: float, *, f_center: float | None = None, trim_s: float = 0.0) -> DampingEstimate:
    """Hilbert-envelope fit of a free decay x (N,) of a single mode, fs in Hz.

    ln|analytic signal| is fitted linearly against time after trimming ``trim_s`` seconds at both
    ends (filter and Hilbert edge effects). The standard error of the slope is inflated by the
    envelope's correlation length (one period) so the uncertainty is not optimistic.
    """
    fs = check_fs(fs)
    a = as_signal("x", x, min_len=16, ndim=(1,))
    positive("trim_s", trim_s, allow_zero=True)
    z = signal.hilbert(a - a.mean())
    env = np.abs(z)
    phase = np.unwrap(np.angle(z))
    k = int(round(trim_s * fs))
    if a.size - 2 * k < 16:
        raise ValueError(f"{trim_s=} leaves fewer than 16 of {a.size} samples")
    sl = slice(k, a.size - k)
    t = np.arange(a.size)[sl] / fs
    if np.any(env[sl] <= 0):
        raise ValueError("x has a zero envelope inside the fitted span")
    fd = float(np.polyfit(t, phase[sl], 1)[0] / (2 * np.pi)) if f_center is None else float(f_center)
    if fd <= 0:
        raise ValueError("x shows no oscillation (non-positive instantaneous frequency)")
    # decimate to ~8 points per period to keep the fit cheap and samples less correlated
    step = max(1, int(fs / (8 * fd)))
    return _fit_log_line(t[::step], np.log(env[sl][::step]), fd, "envelope", corr_samples=8.0)


def find_decay_segments(
    x: object,
    fs: float,
    f_center: float,
    *,
    bearing: object | None = None,
    bearing_threshold: float = 5e-4,
    min_cycles: float = 8.0,
    rel_half_width: float = 0.2,
    min_r2: float = 0.9,
) -> list[tuple[int, int]]:
    """Free-decay segments (sample index ranges [start, end)) of the mode near f_center (Hz) in x (N,).

    With a bearing displacement (N,) (m): spans where the bearing stays still (its motion from
    the span's median below ``bearing_threshold`` m), started right after a motion, at least
    min_cycles long. Without: spans where the band-passed Hilbert envelope falls steadily
    (linear fit of ln envelope with negative slope and R² ≥ min_r2) for min_cycles or more.
    """
    fs = check_fs(fs)
    a = as_signal("x", x, min_len=16, ndim=(1,))
    positive("f_center", f_center)
    positive("min_cycles", min_cycles)
    n_min = int(np.ceil(min_cycles / f_center * fs))
    if bearing is not None:
        d = as_signal("bearing", bearing, min_len=a.size, ndim=(1,))
        if d.size != a.size:
            raise ValueError(f"bearing has {d.size} samples, x has {a.size}")
        moving = _moving(d, fs, bearing_threshold)
        segs = []
        i = 0
        n = a.size
        while i < n:
            if moving[i]:
                i += 1
                continue
            j = i
            while j < n and not moving[j]:
                j += 1
            if i > 0 and j - i >= n_min:  # still after a motion: a free decay
                segs.append((i, j))
            i = j
        return segs
    y = bandpass(a, fs, f_center, rel_half_width=rel_half_width)
    env = np.abs(signal.hilbert(y))
    # smooth the envelope over one period, then look at its slope over sliding blocks
    per = max(1, int(fs / f_center))
    env_s = np.convolve(env, np.ones(per) / per, mode="same")
    logenv = np.log(np.maximum(env_s, env_s.max() * 1e-12 + np.finfo(float).tiny))
    block = max(per * 2, n_min // 4)
    edge = int(_edge_s(f_center, rel_half_width) * fs)
    ok = np.zeros(a.size, dtype=bool)
    for s in range(edge, a.size - edge - block, block // 2):
        t = np.arange(block)
        yb = logenv[s : s + block]
        c = np.polyfit(t, yb, 1)
        r = yb - np.polyval(c, t)
        ss = np.sum((yb - yb.mean()) ** 2)
        r2 = 1 - np.sum(r**2) / ss if ss > 0 else 0.0
        if c[0] < 0 and r2 >= min_r2:
            ok[s : s + block] = True
    segs = []
    i = 0
    while i < a.size:
        if not ok[i]:
            i += 1
            continue
        j = i
        while j < a.size and ok[j]:
            j += 1
        if j - i >= n_min:
            segs.append((i, j))
        i = j
    return segs


def _moving(d: np.ndarray, fs: float, threshold: float) -> np.ndarray:
    """True where the bearing moves: the 0.25 s-smoothed displacement departs from its running
    median over 2 s, or changes over 0.5 s, by more than ``threshold`` (raised to 6σ of the
    smoothed sensor noise); dilated by 1 s on both sides."""
    from scipy.ndimage import maximum_filter1d, median_filter, uniform_filter1d

    w = max(1, int(0.25 * fs))
    noise = float(np.median(np.abs(np.diff(d))) / 0.6745 / np.sqrt(2)) if d.size > 2 else 0.0
    thr = max(threshold, 6 * noise / np.sqrt(w))
    ds = uniform_filter1d(d, size=w, mode="nearest")
    k = max(3, int(2 * fs) | 1)
    dev = np.abs(ds - median_filter(ds, size=k, mode="nearest"))
    lag = max(1, int(0.5 * fs))
    ramp = np.zeros_like(ds)
    ramp[lag:] = np.abs(ds[lag:] - ds[:-lag])
    moving = (dev > thr) | (ramp > thr)
    return maximum_filter1d(moving.astype(np.uint8), size=max(1, 2 * int(fs)), mode="nearest").astype(bool)


def random_decrement(
    x: object,
    fs: float,
    f_center: float,
    *,
    rel_half_width: float = 0.2,
    duration_cycles: float = 15.0,
    trigger_sigma: float = 1.0,
    groups: int = 8,
) -> DampingEstimate:
    """Random decrement damping of the mode near f_center (Hz) from an ambient response x (N,).

    The band-passed signal is cut at every up-crossing of trigger_sigma·σ and the following
    duration_cycles periods are averaged: the signature is the mode's free decay, fitted with
    the Hilbert envelope. The triggers are split into ``groups`` blocks; the scatter of the block
    estimates gives the uncertainty (std/√groups).
    """
    fs = check_fs(fs)
    positive("f_center", f_center)
    positive("duration_cycles", duration_cycles)
    positive("trigger_sigma", trigger_sigma)
    if not isinstance(groups, int) or groups < 2:
        raise ValueError(f"{groups=} must be an integer >= 2")
    a = as_signal("x", x, min_len=16, ndim=(1,))
    y = bandpass(a, fs, f_center, rel_half_width=rel_half_width)
    edge = int(_edge_s(f_center, rel_half_width) * fs)
    L = int(round(duration_cycles / f_center * fs))
    level = trigger_sigma * float(np.std(y[edge:-edge] if a.size > 2 * edge + L else y))
    trig = np.flatnonzero((y[:-1] < level) & (y[1:] >= level)) + 1
    trig = trig[(trig >= edge) & (trig + L <= a.size - edge)]
    if trig.size < 4 * groups:
        raise ValueError(f"x yields {trig.size} random-decrement triggers at f_center={f_center} Hz; needs {4 * groups}")
    idx = trig[:, None] + np.arange(L)[None, :]
    segs = y[idx]
    trim = 1.0 / f_center

    def fit(s: np.ndarray) -> DampingEstimate:
        return envelope_decay(s.mean(axis=0), fs, trim_s=trim)

    whole = fit(segs)
    parts = []
    for g in np.array_split(np.arange(trig.size), groups):
        try:
            parts.append(fit(segs[g]).damping_ratio)
        except ValueError:
            continue
    std = float(np.std(parts, ddof=1) / np.sqrt(len(parts))) if len(parts) >= 2 else float("nan")
    return DampingEstimate(whole.damping_ratio, max(std, whole.damping_std), whole.frequency_hz, "random_decrement", whole.cycles, int(trig.size))


def combine_estimates(estimates: list[DampingEstimate]) -> DampingEstimate:
    """Inverse-variance weighted mean of several estimates; the uncertainty is the larger of the
    formal one and the scatter of the estimates (1σ of the mean)."""
    if not estimates:
        raise ValueError("estimates must not be empty")
    z = np.array([e.damping_ratio for e in estimates])
    s = np.array([max(e.damping_std, 1e-6) for e in estimates])
    w = 1 / s**2
    mean = float(np.sum(w * z) / np.sum(w))
    formal = float(1 / np.sqrt(np.sum(w)))
    scatter = float(np.std(z, ddof=1) / np.sqrt(z.size)) if z.size > 1 else 0.0
    f = float(np.mean([e.frequency_hz for e in estimates]))
    return DampingEstimate(mean, max(formal, scatter), f, "combined" if z.size > 1 else estimates[0].method, float(sum(e.cycles for e in estimates)), int(z.size))
