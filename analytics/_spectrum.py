"""Single-sided, amplitude-correct spectra (Hamming window, zero padding) and Welch-type averages."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import signal

from ._validate import as_signal, check_fs, fraction, positive

__all__ = ["Spectrum", "amplitude_spectrum", "averaged_spectrum", "cross_spectra"]

WindowName = Literal["hamming", "hann", "boxcar", "blackman", "flattop"]
_WINDOWS = ("hamming", "hann", "boxcar", "blackman", "flattop")


@dataclass(frozen=True)
class Spectrum:
    """A single-sided amplitude spectrum.

    frequencies : (M,) Hz, 0 .. fs/2 on the padded grid (spacing ``bin_spacing_hz``).
    amplitude : (M,) or (M, k), same unit as the signal: a sinusoid of amplitude A peaks at A
        (up to scalloping between bins, zero with enough padding).
    resolution_hz : fs/N, the true frequency resolution of the N-sample record (Hz).
    bin_spacing_hz : fs/(pad_factor·N), spacing of the interpolated (zero-padded) grid (Hz).
    coherent_gain : mean of the window (Hamming 0.54), the factor the amplitude was corrected for.
    enbw_bins : equivalent noise bandwidth of the window in resolution bins (Hamming ≈ 1.36).
    enbw_hz : enbw_bins · resolution_hz (Hz).
    window : name of the window.
    n_samples, pad_factor, averages : record length, zero-padding factor, number of averaged segments.
    """

    frequencies: np.ndarray
    amplitude: np.ndarray
    resolution_hz: float
    bin_spacing_hz: float
    coherent_gain: float
    enbw_bins: float
    enbw_hz: float
    window: str
    n_samples: int
    pad_factor: int
    averages: int = 1


def _window(name: str, n: int) -> np.ndarray:
    if name not in _WINDOWS:
        raise ValueError(f"window={name!r} must be one of {_WINDOWS}")
    return signal.get_window(name, n, fftbins=False).astype(float)


def _check_pad(pad_factor: int) -> int:
    if isinstance(pad_factor, bool) or not isinstance(pad_factor, (int, np.integer)) or pad_factor < 1:
        raise ValueError(f"{pad_factor=} must be an integer >= 1")
    return int(pad_factor)


def _spectrum_of(x: np.ndarray, fs: float, pad: int, window: str, detrend: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = x.shape[0]
    w = _window(window, n)
    xd = x - x.mean(axis=0) if detrend else x
    shape = (n,) + (1,) * (x.ndim - 1)
    nfft = pad * n
    X = np.fft.rfft(xd * w.reshape(shape), n=nfft, axis=0)
    scale = 2.0 / w.sum()
    X = X * scale
    X[0] *= 0.5
    if nfft % 2 == 0:
        X[-1] *= 0.5
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    return f, X, w


def _meta(w: np.ndarray, fs: float, n: int, pad: int) -> dict:
    cg = float(w.mean())
    enbw = float(n * np.sum(w**2) / np.sum(w) ** 2)
    return dict(resolution_hz=fs / n, bin_spacing_hz=fs / (pad * n), coherent_gain=cg, enbw_bins=enbw, enbw_hz=enbw * fs / n)


def amplitude_spectrum(x: object, fs: float, *, pad_factor: int = 4, window: str = "hamming", detrend: bool = True) -> Spectrum:
    """Single-sided amplitude spectrum of ``x`` (N,) or (N, k) sampled at ``fs`` Hz.

    The mean is removed (``detrend``), the record is windowed, zero padded to pad_factor·N and
    scaled by 2/Σw so that a sinusoid of amplitude A (signal unit) shows a peak of A.

    Examples
    --------
    >>> import numpy as np
    >>> from analytics import amplitude_spectrum, find_peaks
    >>> fs = 100.0                                   # Hz
    >>> t = np.arange(0.0, 20.0, 1 / fs)             # 20 s
    >>> x = 0.5 * np.sin(2 * np.pi * 2.0 * t)        # 0.5 units at 2 Hz
    >>> peak = find_peaks(amplitude_spectrum(x, fs), fmin=0.5)[0]
    >>> round(peak.frequency_hz, 3), round(peak.amplitude, 3)   # amplitude-correct
    (2.0, 0.5)
    """
    fs = check_fs(fs)
    pad = _check_pad(pad_factor)
    a = as_signal("x", x, min_len=4)
    f, X, w = _spectrum_of(a, fs, pad, window, detrend)
    return Spectrum(frequencies=f, amplitude=np.abs(X), window=window, n_samples=a.shape[0], pad_factor=pad, **_meta(w, fs, a.shape[0], pad))


def _segments(n: int, seg: int, overlap: float) -> list[int]:
    step = max(1, int(round(seg * (1.0 - overlap))))
    return list(range(0, n - seg + 1, step))


def averaged_spectrum(
    x: object, fs: float, segment_s: float, *, overlap: float = 0.5, pad_factor: int = 4, window: str = "hamming"
) -> Spectrum:
    """Welch-type average: RMS of the amplitude spectra of segments of ``segment_s`` seconds.

    x (N,) or (N, k); overlap in [0, 1). A stationary sinusoid of amplitude A still peaks at A;
    noise averages to its RMS level, so peaks of lightly damped modes stand out more clearly.
    """
    fs = check_fs(fs)
    pad = _check_pad(pad_factor)
    positive("segment_s", segment_s)
    fraction("overlap", overlap)
    a = as_signal("x", x, min_len=4)
    seg = int(round(segment_s * fs))
    if seg < 4 or seg > a.shape[0]:
        raise ValueError(f"{segment_s=} gives {seg} samples; needs 4 .. {a.shape[0]} (the record length)")
    starts = _segments(a.shape[0], seg, overlap)
    power = None
    for s in starts:
        f, X, w = _spectrum_of(a[s : s + seg], fs, pad, window, True)
        p = np.abs(X) ** 2
        power = p if power is None else power + p
    amp = np.sqrt(power / len(starts))
    return Spectrum(frequencies=f, amplitude=amp, window=window, n_samples=seg, pad_factor=pad, averages=len(starts), **_meta(w, fs, seg, pad))


def cross_spectra(x: object, fs: float, frequencies_hz: object, *, window: str = "hamming") -> np.ndarray:
    """Complex single-sided Fourier coefficients of x (N, k) at given frequencies (Hz).

    Returns (len(frequencies_hz), k) complex, amplitude-correct (|c| = A for a sinusoid of
    amplitude A at that frequency). Products c_i·conj(c_j) are the cross spectra at that line.
    """
    fs = check_fs(fs)
    a = as_signal("x", x, min_len=4, ndim=(2,))
    fr = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
    if fr.ndim != 1 or not np.all(np.isfinite(fr)) or np.any(fr < 0) or np.any(fr > fs / 2):
        raise ValueError(f"frequencies_hz={frequencies_hz!r} must be finite and in [0, fs/2]")
    n = a.shape[0]
    w = _window(window, n)
    t = np.arange(n) / fs
    xd = (a - a.mean(axis=0)) * w[:, None]
    E = np.exp(-2j * np.pi * np.outer(fr, t))
    return (E @ xd) * (2.0 / w.sum())
