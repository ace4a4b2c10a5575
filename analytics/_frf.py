"""Input–output identification: H1 frequency response functions with coherence, a modal fit on
them (poly-reference least-squares complex frequency domain, pLSCF), and the excitation class of
a measured input judged from its spectrum."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import signal

from ._ssi import PoleSet, modal_phase_collinearity
from ._stabilisation import cluster_poles, stabilisation_diagram
from ._validate import as_signal, check_fs, positive

__all__ = ["ExcitationClass", "Frf", "FrfMode", "classify_excitation", "frf_h1", "frf_modes"]


@dataclass(frozen=True, eq=False)
class Frf:
    """H1 frequency response functions from m inputs to l outputs.

    frequencies : (M,) Hz. h : (M, l, m) complex, output unit per input unit.
    coherence : (M, l) multiple coherence of each output with all inputs (ordinary coherence
        for one input), 0 … 1: the share of the output's power the inputs explain linearly.
    averages : segments averaged. segment_cross : per-segment spectra kept for the jackknife
        (Gyu (S, M, l, m), Guu (S, M, m, m), Gyy (S, M, l)).
    """

    frequencies: np.ndarray
    h: np.ndarray
    coherence: np.ndarray
    averages: int
    segment_cross: tuple[np.ndarray, np.ndarray, np.ndarray]


def _h1(Gyu: np.ndarray, Guu: np.ndarray, Gyy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    H = np.linalg.solve(np.swapaxes(Guu, -1, -2), np.swapaxes(Gyu, -1, -2))  # (M, m, l)
    H = np.swapaxes(H, -1, -2)
    explained = np.real(np.einsum("klm,kml->kl", H, np.conj(np.swapaxes(Gyu, -1, -2))))
    with np.errstate(invalid="ignore", divide="ignore"):
        coh = np.clip(np.where(Gyy > 0, explained / np.where(Gyy > 0, Gyy, 1), 0.0), 0.0, 1.0)
    return H, coh


def frf_h1(u: object, y: object, fs: float, *, segment_s: float, overlap: float = 0.5) -> Frf:
    """H1 estimate H = G_yu G_uu⁻¹ and the multiple coherence, Welch-averaged (Hann segments).

    Parameters
    ----------
    u : array_like, shape (N,) or (N, m)
        Measured inputs (support acceleration, unit v).
    y : array_like, shape (N,) or (N, l)
        Outputs (unit w).
    fs : float
        Sample rate (Hz).
    segment_s : float
        Segment length (s); the resolution is 1/segment_s Hz.
    overlap : float
        Overlap of the segments, fraction in [0, 1) [0.5].

    Returns
    -------
    Frf

    Raises
    ------
    ValueError
        If u and y differ in length, hold fewer than two segments, or an argument is invalid.
    """
    fs = check_fs(fs)
    a = as_signal("u", u, min_len=16)
    a = a.reshape(a.shape[0], -1)
    b = as_signal("y", y, min_len=16)
    b = b.reshape(b.shape[0], -1)
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"u has {a.shape[0]} samples, y has {b.shape[0]}")
    positive("segment_s", segment_s)
    if not (0 <= overlap < 1):
        raise ValueError(f"{overlap=} must be in [0, 1)")
    nseg = int(round(segment_s * fs))
    step = max(1, int(round(nseg * (1 - overlap))))
    starts = np.arange(0, a.shape[0] - nseg + 1, step)
    if nseg < 16 or starts.size < 2:
        raise ValueError(f"{segment_s=} s gives {starts.size} segment(s) of {nseg} samples; needs at least 2 of 16 or more")
    w = signal.get_window("hann", nseg)
    idx = starts[:, None] + np.arange(nseg)[None, :]
    U = np.fft.rfft(signal.detrend(a[idx], axis=1, type="constant") * w[None, :, None], axis=1)  # (S, M, m)
    Y = np.fft.rfft(signal.detrend(b[idx], axis=1, type="constant") * w[None, :, None], axis=1)  # (S, M, l)
    Gyu = Y[:, :, :, None] * np.conj(U[:, :, None, :])
    Guu = U[:, :, :, None] * np.conj(U[:, :, None, :])
    Gyy = np.abs(Y) ** 2
    H, coh = _h1(Gyu.mean(0), Guu.mean(0), Gyy.mean(0))
    return Frf(np.fft.rfftfreq(nseg, 1 / fs), H, coh, int(starts.size), (Gyu, Guu, Gyy))


@dataclass(frozen=True)
class FrfMode:
    """A mode fitted to FRFs (method "frf_plscf"): frequency_hz, damping_ratio and their 1σ
    (segment jackknife combined with the scatter across model orders), the shape (l,) from the
    residues (real, unit norm), its mpc, the orders it was stable at and the mean coherence
    over its half-power band."""

    frequency_hz: float
    damping_ratio: float
    frequency_std_hz: float
    damping_std: float
    shape: tuple[float, ...]
    mpc: float
    orders: int
    coherence: float
    method: str = "frf_plscf"


def _plscf(f: np.ndarray, H: np.ndarray, wgt: np.ndarray, order: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Common-denominator least-squares fit of H (K, p) at f (K,) with weights (K, p); returns the
    continuous poles λ (Im > 0) and residue vectors (p, npoles)."""
    z = np.exp(1j * 2 * np.pi * f * dt)
    Om = z[:, None] ** np.arange(order + 1)[None, :]  # (K, n+1)
    M = np.zeros((order + 1, order + 1))
    cache = []
    for o in range(H.shape[1]):
        X = wgt[:, o, None] * Om
        Yo = -(wgt[:, o] * H[:, o])[:, None] * Om
        R = np.real(X.conj().T @ X)
        S = np.real(X.conj().T @ Yo)
        T = np.real(Yo.conj().T @ Yo)
        Rinv_S = np.linalg.solve(R, S)
        M += T - S.T @ Rinv_S
        cache.append(Rinv_S)
    alpha = np.ones(order + 1)
    alpha[:order] = np.linalg.solve(M[:order, :order], -M[:order, order])
    mu = np.roots(alpha[::-1])
    lam = np.log(mu.astype(complex)) / dt
    keep = lam.imag > 0
    mu, lam = mu[keep], lam[keep]
    # residues of B_o/A at each pole: B_o(μ)/A'(μ)
    dA = np.polyval(np.polyder(alpha[::-1]), mu)
    res = np.array([np.polyval((-(Rs @ alpha))[::-1], mu) / dA for Rs in cache])
    return lam, res


def frf_modes(
    frf: Frf,
    *,
    fmin_hz: float,
    fmax_hz: float,
    max_order: int = 24,
    groups: int = 6,
    freq_rel: float = 0.01,
    damping_rel: float = 0.3,
    mac_min: float = 0.95,
    min_orders: float = 0.3,
    min_coherence: float = 0.8,
) -> tuple[FrfMode, ...]:
    """Modes fitted to H1 FRFs in a band: pLSCF over model orders, stabilisation, clustering.

    The band is mapped to the unit circle (a fictitious sample time 1/(2·fmax)) for a well-posed
    polynomial basis; each line is weighted by coherence/(1 − coherence), its inverse variance.

    Parameters
    ----------
    frf : Frf
        From :func:`frf_h1` (one input: the shapes are the residues of that input's column).
    fmin_hz, fmax_hz : float
        Band fitted (Hz), 0 <= fmin < fmax <= the FRF's last line.
    max_order : int
        Largest denominator order (even) [24].
    groups : int
        Segment groups of the jackknife uncertainty (>= 3, at most the averages) [6].
    freq_rel, damping_rel, mac_min, min_orders : float
        Stabilisation and clustering criteria (:func:`stabilisation_diagram`, :func:`cluster_poles`).
    min_coherence : float
        A mode whose half-power band has a lower mean coherence is not listed: where the input
        does not explain the outputs the FRF is noise [0.8].

    Returns
    -------
    tuple of FrfMode, lowest frequency first.

    Raises
    ------
    ValueError
        If frf is not an Frf, the band holds too few lines for max_order, or an argument is invalid.
    """
    if not isinstance(frf, Frf):
        raise ValueError(f"frf must be an Frf, got {type(frf).__name__}")
    if not (0 <= fmin_hz < fmax_hz <= frf.frequencies[-1]):
        raise ValueError(f"{fmin_hz=} and {fmax_hz=} must satisfy 0 <= fmin < fmax <= {frf.frequencies[-1]} Hz")
    if isinstance(max_order, bool) or not isinstance(max_order, (int, np.integer)) or max_order < 2:
        raise ValueError(f"{max_order=} must be an integer >= 2")
    sel = (frf.frequencies >= fmin_hz) & (frf.frequencies <= fmax_hz)
    f = frf.frequencies[sel]
    if f.size < 2 * max_order:
        raise ValueError(f"the band {fmin_hz}–{fmax_hz} Hz holds {f.size} lines; max_order={max_order} needs {2 * max_order}")
    dt = 1.0 / (2.0 * fmax_hz)

    def fit_all(H: np.ndarray, coh: np.ndarray, orders: np.ndarray):
        Hs = H[sel][:, :, 0]
        c = np.clip(coh[sel], 0.0, 0.999)
        w = np.sqrt(c / (1 - c) + 1e-6)
        return [_plscf(f, Hs, w, int(n), dt) for n in orders]

    orders = np.arange(2, max_order + 1, 2)
    fits = fit_all(frf.h, frf.coherence, orders)
    order_arr = np.concatenate([np.full(lam.size, n) for n, (lam, _) in zip(orders, fits)])
    lam = np.concatenate([lam for lam, _ in fits])
    res = np.concatenate([r for _, r in fits], axis=1).T if lam.size else np.zeros((0, frf.h.shape[1]), complex)
    nrm = np.linalg.norm(res, axis=1, keepdims=True)
    shapes = res / np.where(nrm > 0, nrm, 1)
    wn = np.abs(lam)
    poles = PoleSet(order_arr.astype(int), lam, wn / (2 * np.pi), -lam.real / np.where(wn > 0, wn, 1), shapes, modal_phase_collinearity(shapes) if lam.size else np.zeros(0))
    diag = stabilisation_diagram(poles, fmin_hz=fmin_hz, fmax_hz=fmax_hz, freq_rel=freq_rel, damping_rel=damping_rel, mac_min=mac_min)
    clusters = cluster_poles(diag, min_orders=min_orders)
    Gyu, Guu, Gyy = frf.segment_cross
    S = Gyu.shape[0]
    g = int(min(groups, S))
    parts = np.array_split(np.arange(S), g) if g >= 3 else []
    out = []
    for c in clusters:
        rep = c.representative
        n = int(poles.order[rep])
        lam0 = poles.eigenvalue[rep]
        jf, jz = [], []
        for part in parts:
            keep = np.setdiff1d(np.arange(S), part)
            H, coh = _h1(Gyu[keep].mean(0), Guu[keep].mean(0), Gyy[keep].mean(0))
            (lj, _), = fit_all(H, coh, np.array([n]))
            if lj.size == 0:
                continue
            k = int(np.argmin(np.abs(lj - lam0)))
            jf.append(abs(lj[k]) / (2 * np.pi))
            jz.append(-lj[k].real / abs(lj[k]))
        if len(jf) >= 3:
            G = len(jf)
            sf = float(np.sqrt((G - 1) / G * np.sum((np.array(jf) - np.mean(jf)) ** 2)))
            sz = float(np.sqrt((G - 1) / G * np.sum((np.array(jz) - np.mean(jz)) ** 2)))
        else:
            sf = sz = 0.0
        shape_c = shapes[rep]
        k = int(np.argmax(np.abs(shape_c)))
        real = np.real(shape_c * np.exp(-1j * np.angle(shape_c[k])))
        real = real / (np.linalg.norm(real) or 1.0)
        fr, zr = c.frequency_hz, c.damping_ratio
        band = (frf.frequencies >= fr * (1 - max(zr, 0.002))) & (frf.frequencies <= fr * (1 + max(zr, 0.002)))
        coh = float(frf.coherence[band].mean()) if band.any() else float(frf.coherence[np.argmin(np.abs(frf.frequencies - fr))].mean())
        if coh < min_coherence:
            continue
        out.append(FrfMode(fr, zr, float(np.hypot(sf, c.frequency_spread_hz)), float(np.hypot(sz, c.damping_spread)),
                           tuple(float(v) for v in real), float(poles.mpc[rep]), c.orders, coh))
    return tuple(out)


@dataclass(frozen=True)
class ExcitationClass:
    """What drives a window, from the measured input's spectrum.

    kind : "deterministic_near_mode" (a dominant narrow line within ``tolerance`` of a tracked
        mode: the response there is forced, not free: distrust the window), "deterministic"
        (a dominant line away from every tracked mode), "broadband" (no dominant line) or
        "quiet" (no measurable input).
    line_hz : frequency of the strongest line (Hz) or None; line_fraction : share of the input's
        power (above 0 Hz) within that line's main lobe (0 … 1); nearest_mode_hz : the tracked
        frequency nearest the line (Hz) or None; rms : input RMS (input unit).
    """

    kind: Literal["deterministic_near_mode", "deterministic", "broadband", "quiet"]
    line_hz: float | None
    line_fraction: float
    nearest_mode_hz: float | None
    rms: float


def classify_excitation(
    u: object,
    fs: float,
    tracked_hz: object = (),
    *,
    line_fraction: float = 0.5,
    tolerance: float = 0.05,
    quiet_rms: float = 0.0,
    floor_ratio: float | None = None,
) -> ExcitationClass:
    """Classify a window's measured input (support acceleration) from its spectrum.

    Parameters
    ----------
    u : array_like, shape (N,) or (N, m)
        Measured input(s) at fs (any unit); several columns are summed in power.
    fs : float
        Sample rate (Hz).
    tracked_hz : sequence of float
        Frequencies of the tracked modes (Hz).
    line_fraction : float
        A line holding at least this share of the input power is dominant [0.5].
    tolerance : float
        A line within this relative distance of a tracked mode is "near" it [0.05].
    quiet_rms : float
        Inputs with an RMS at or below this are "quiet" [0].
    floor_ratio : float, optional
        Also "deterministic_near_mode" when, within ``tolerance`` (at least two resolution bins)
        of a tracked mode, the input's periodogram has a line this many times above its median
        over ±4·tolerance there: a weak sine at a mode forces the response in the mode's
        bandwidth even when the broadband input carries most of the power. Broadband noise
        peaks at about 6, rarely 12, times its median [None: off].

    Returns
    -------
    ExcitationClass

    Raises
    ------
    ValueError
        If u is not finite or too short, or an argument is out of range.
    """
    fs = check_fs(fs)
    a = as_signal("u", u, min_len=16)
    a = a.reshape(a.shape[0], -1)
    if not (0 < line_fraction < 1):
        raise ValueError(f"{line_fraction=} must be in (0, 1)")
    positive("tolerance", tolerance)
    positive("quiet_rms", quiet_rms, allow_zero=True)
    tr = np.atleast_1d(np.asarray(tracked_hz, dtype=float))
    if tr.size and (not np.all(np.isfinite(tr)) or np.any(tr <= 0)):
        raise ValueError(f"tracked_hz={tracked_hz!r} must be positive finite frequencies")
    a = a - a.mean(axis=0)
    rms = float(np.sqrt(np.mean(np.sum(a**2, axis=1))))
    if rms <= quiet_rms or rms == 0:
        return ExcitationClass("quiet", None, 0.0, None, rms)
    n = a.shape[0]
    # one Hann-windowed periodogram of the whole window: the finest resolution, and a steady
    # line's main lobe (±2 bins) then holds ~all of its power
    nfft = 1 << int(np.ceil(np.log2(4 * n)))
    X = np.fft.rfft(a * signal.get_window("hann", n)[:, None], nfft, axis=0)
    P = np.sum(np.abs(X) ** 2, axis=1)
    P[0] = 0.0
    f = np.fft.rfftfreq(nfft, 1 / fs)
    k = int(np.argmax(P))
    lobe = 2 * nfft // n  # Hann main lobe half width: 2 bins of the unpadded record
    frac = float(P[max(1, k - lobe): k + lobe + 1].sum() / P.sum())
    line = float(f[k])
    near = float(tr[np.argmin(np.abs(tr - line))]) if tr.size else None
    if floor_ratio is not None:
        if not floor_ratio > 1:
            raise ValueError(f"{floor_ratio=} must be > 1")
        res = fs / n
        for fm in tr:
            half = max(tolerance * fm, 2 * res)
            inner = (f >= fm - half) & (f <= fm + half) & (f > 0)
            ring = (f >= fm - 4 * half) & (f <= fm + 4 * half) & (f > 0)
            if not inner.any() or ring.sum() < 8:
                continue
            floor = float(np.median(P[ring]))
            j = int(np.flatnonzero(inner)[np.argmax(P[inner])])
            if floor > 0 and P[j] >= floor_ratio * floor:
                share = float(P[max(1, j - lobe): j + lobe + 1].sum() / P.sum())
                return ExcitationClass("deterministic_near_mode", float(f[j]), share, float(fm), rms)
    if frac < line_fraction:
        return ExcitationClass("broadband", line, frac, near, rms)
    if near is not None and abs(line - near) <= tolerance * near:
        return ExcitationClass("deterministic_near_mode", line, frac, near, rms)
    return ExcitationClass("deterministic", line, frac, near, rms)
