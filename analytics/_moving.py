"""Modes that move within a window: sub-window frequency estimates of one mode.

A support that moves, or a temperature step, changes a mode's frequency while the window is
recorded. A linear time-invariant model (SSI) of such a window spreads the mode over several
poles on either side of its mean, or over none. The sub-window estimate follows it instead:
the mode's response (the channels projected on its shape) is cut into short, half-overlapping
sub-windows of a few of its periods, and in each the frequency of the sinusoid that fits best
(Hann-weighted least squares, searched near the mode) is its frequency at that time. A straight
line through them gives the frequency at the start and the end of the window and whether the
change is significant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._validate import as_signal, check_fs, positive

__all__ = ["SubwindowTrack", "subwindow_frequencies"]


@dataclass(frozen=True, eq=False)
class SubwindowTrack:
    """Frequency of one mode along a window.

    times_s : (k,) sub-window centres (s from the window's first sample).
    frequency_hz : (k,) best-fitting frequency in each sub-window (Hz).
    amplitude : (k,) the fitted sinusoid's amplitude (unit of the signal).
    start_hz, end_hz : the frequency in the first and the last sub-window where the mode stands
        out (amplitude ≥ 0.3 of its largest) (Hz).
    mean_hz : the time average of those sub-windows' frequencies (Hz); mean_std_hz its 1σ, None
        when the mode stands out in one sub-window only (one estimate has no scatter).
    change_hz : the change over the window of a straight line through them (Hz);
        change_std_hz its 1σ from the scatter about the line, None with fewer than three of them
        (a line through two points leaves no scatter).
    standing : how many sub-windows the mode stands out in (those behind start, end and mean).
    """

    times_s: np.ndarray
    frequency_hz: np.ndarray
    amplitude: np.ndarray
    start_hz: float
    end_hz: float
    mean_hz: float
    change_hz: float
    change_std_hz: float | None
    mean_std_hz: float | None
    standing: int = 0

    def moving(self, reference_hz: float | None = None, *, rel: float = 0.01, sigmas: float = 3.0) -> bool:
        """The mode moved: its frequency changed along the window by more than ``rel`` of it and
        ``sigmas`` of its 1σ, or its time average departs from ``reference_hz`` (the window's
        time-invariant estimate) by more than ``rel``: a mode that stepped or went and came
        back, which a time-invariant model pins to one of its ends. A mode that stands out in
        one sub-window only has no course to follow: it is not said to move."""
        if self.mean_std_hz is None:
            return False
        ref = self.mean_hz if reference_hz is None else reference_hz
        if self.change_std_hz is not None and abs(self.change_hz) > max(rel * ref, sigmas * self.change_std_hz):
            return True
        return abs(self.mean_hz - ref) > rel * ref


def _fit_basis(t: np.ndarray, w: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, ...]:
    """The sinusoids of ``grid`` at the sub-window's times and their weighted Gram terms: the
    same for every sub-window of a track (same length, times and weights), so computed once."""
    ph = 2 * np.pi * grid[:, None] * t[None, :]
    c, s = np.cos(ph), np.sin(ph)
    cc, ss, cs = (c * c) @ w, (s * s) @ w, (c * s) @ w
    return c, s, cc, ss, cs, cc * ss - cs * cs


def _best_frequencies(segs: np.ndarray, w: np.ndarray, grid: np.ndarray, basis: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per sub-window (rows of ``segs``): frequency on ``grid`` (refined by a parabola) and
    amplitude of the weighted LS sinusoid fit."""
    c, s, cc, ss, cs, det = basis
    xw = segs * w
    xc, xs = xw @ c.T, xw @ s.T
    with np.errstate(invalid="ignore", divide="ignore"):
        a = (ss * xc - cs * xs) / det
        b = (cc * xs - cs * xc) / det
        e = np.where(det > 0, a * xc + b * xs, 0.0)
    fr, am = np.empty(len(segs)), np.empty(len(segs))
    for j, ej in enumerate(e):
        k = int(np.argmax(ej))
        f = float(grid[k])
        if 0 < k < grid.size - 1:
            y0, y1, y2 = ej[k - 1], ej[k], ej[k + 1]
            den = y0 - 2 * y1 + y2
            if den < 0:
                f += float(0.5 * (y0 - y2) / den * (grid[1] - grid[0]))
        fr[j], am[j] = f, math.hypot(a[j, k], b[j, k])
    return fr, am


def subwindow_frequencies(x: object, fs: float, f0_hz: float, *, lo_hz: float, hi_hz: float, cycles: float = 3.0,
                          min_subwindows: int = 5) -> SubwindowTrack | None:
    """The frequency of one mode along a window from half-overlapping sub-windows.

    Parameters
    ----------
    x : array_like, shape (N,)
        The mode's response over the window (the channels projected on its shape), at fs.
    fs : float
        Sample rate (Hz).
    f0_hz : float
        The mode's frequency over the whole window (Hz): sub-windows span ``cycles`` periods of it.
    lo_hz, hi_hz : float
        The search band (Hz), lo_hz < f0_hz < hi_hz: between the neighbouring modes.
    cycles : float
        Sub-window length in periods of f0 [3]; at least 4 sub-windows of the window's quarter.
    min_subwindows : int
        Fewer sub-windows fit in the window: None [5].

    Returns
    -------
    SubwindowTrack, or None if the window holds too few sub-windows.

    Raises
    ------
    ValueError
        If x is not a finite 1-D signal or the band does not hold f0.

    Examples
    --------
    >>> fs = 1000.0; t = np.arange(500) / fs
    >>> x = np.sin(2 * np.pi * (25 * t + 17 * t**2))  # 25 → 42 Hz in 0.5 s
    >>> tr = subwindow_frequencies(x, fs, 33.0, lo_hz=20, hi_hz=50)
    >>> round(tr.start_hz), round(tr.end_hz), round(tr.change_hz)
    (27, 40, 17)
    """
    fs = check_fs(fs)
    a = as_signal("x", x, min_len=16)
    if a.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {a.shape}")
    positive("f0_hz", f0_hz)
    if not (0 <= lo_hz < f0_hz < hi_hz):
        raise ValueError(f"the band ({lo_hz=}, {hi_hz=}) must hold {f0_hz=}")
    n = a.size
    T = n / fs
    L = round(max(cycles / f0_hz, T / 4) * fs)
    L = min(L, n)
    step = max(1, L // 2)
    starts = list(range(0, n - L + 1, step))
    if len(starts) < min_subwindows:
        return None
    hi_hz = min(hi_hz, 0.49 * fs)
    # the parabola refines between grid points: a few hundred points over the band are plenty
    res = max(1e-3 * f0_hz, 0.02 / (L / fs), (hi_hz - lo_hz) / 400)
    grid = np.arange(lo_hz, hi_hz + res, res)
    t = np.arange(L) / fs
    w = np.hanning(L + 2)[1:-1]
    segs = np.array([a[s: s + L] for s in starts])
    fr, am = _best_frequencies(segs - segs.mean(axis=1, keepdims=True), w, grid, _fit_basis(t, w, grid))
    tm = (np.array(starts) + L / 2) / fs
    # a sub-window where the mode has rung down into the noise says little about its frequency
    keep = am >= 0.3 * am.max() if am.max() > 0 else np.ones(am.size, bool)
    fk, tk = fr[keep], tm[keep]
    mean = float(np.mean(fk))
    k = fk.size
    change: float = 0.0
    change_std: float | None = None
    if k >= 3:
        A = np.column_stack([np.ones(k), tk - tk.mean()])
        coef, *_ = np.linalg.lstsq(A, fk, rcond=None)
        resid = fk - A @ coef
        # half-overlapping sub-windows: about half as many independent estimates
        s2 = 2 * float(np.sum(resid ** 2)) / (k - 2)
        sxx = float(np.sum((tk - tk.mean()) ** 2))
        change = float(coef[1]) * T
        # sub-windows at distinct times (k >= 3 of them half-overlapping) have sxx > 0
        change_std = math.sqrt(s2 / sxx) * T if sxx > 0 else None
    mean_std = math.sqrt(2 * float(np.var(fk, ddof=1)) / k) if k > 1 else None
    return SubwindowTrack(tm, fr, am, float(fk[0]), float(fk[-1]), mean, change, change_std, mean_std, int(k))
