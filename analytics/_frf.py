"""Input–output identification: H1 frequency response functions with coherence, a modal fit on
them (poly-reference least-squares complex frequency domain, pLSCF), and the excitation class of
a measured input judged from its spectrum."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import signal

from ._validate import as_signal, check_fs, positive

__all__ = ["ExcitationClass", "classify_excitation"]


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
    if frac < line_fraction:
        return ExcitationClass("broadband", line, frac, near, rms)
    if near is not None and abs(line - near) <= tolerance * near:
        return ExcitationClass("deterministic_near_mode", line, frac, near, rms)
    return ExcitationClass("deterministic", line, frac, near, rms)
