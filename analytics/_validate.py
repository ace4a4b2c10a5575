"""Input validation shared by the public entry points (messages name the offending value)."""

from __future__ import annotations

import numpy as np

__all__ = ["as_signal", "check_fs", "positive", "fraction", "as_times"]


def check_fs(fs: float) -> float:
    if isinstance(fs, bool) or not isinstance(fs, (int, float, np.floating, np.integer)) or not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive finite sample rate in Hz")
    return float(fs)


def positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    ok = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool) and np.isfinite(value)
    if not ok or (value < 0 if allow_zero else value <= 0):
        raise ValueError(f"{name}={value!r} must be {'>= 0' if allow_zero else '> 0'} and finite")
    return float(value)


def fraction(name: str, value: float, lo: float = 0.0, hi: float = 1.0) -> float:
    if not isinstance(value, (int, float, np.floating, np.integer)) or not (lo <= value < hi):
        raise ValueError(f"{name}={value!r} must be in [{lo}, {hi})")
    return float(value)


def as_signal(name: str, x: object, *, min_len: int = 2, ndim: tuple[int, ...] = (1, 2)) -> np.ndarray:
    """A finite float array of shape (N,) or (N, k) with N >= min_len."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric array-like, got {type(x).__name__}") from exc
    if a.ndim not in ndim:
        raise ValueError(f"{name} must have ndim in {ndim}, got shape {a.shape}")
    if a.shape[0] < min_len:
        raise ValueError(f"{name} needs at least {min_len} samples along axis 0, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


def as_times(name: str, t: object, n: int | None = None) -> np.ndarray:
    a = as_signal(name, t, min_len=1, ndim=(1,))
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name} has {a.shape[0]} samples, expected {n}")
    if a.size > 1 and np.any(np.diff(a) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return a
