"""Prescribed bearing motion d(t) and ambient loads of the virtual rig.

Every excitation starts with a rest phase (the estimator calibrates its biases there). The
bearing motion is a sum of windowed components whose window sin⁴(πτ) starts and ends with zero
displacement, velocity and acceleration, so d, ḋ, d̈ are smooth and known in closed form.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["BearingMotion", "Excitation", "ExcitationKind", "make_excitation"]

ExcitationKind = Literal["paper", "ambient", "decay"]
EXCITATIONS: tuple[ExcitationKind, ...] = ("paper", "ambient", "decay")


@dataclass(frozen=True)
class _Component:
    start: float  # s
    duration: float  # s
    amplitude: float  # m
    frequency: float  # Hz; 0 for a plain back-and-forth move
    phase: float  # rad


@dataclass(frozen=True)
class BearingMotion:
    """d(t) as a sum of windowed components; evaluate with ``__call__``."""

    components: tuple[_Component, ...]

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Displacement (m), velocity (m/s) and acceleration (m/s²) at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        d = np.zeros_like(t)
        v = np.zeros_like(t)
        a = np.zeros_like(t)
        for comp in self.components:
            lo = np.searchsorted(t, comp.start)
            hi = np.searchsorted(t, comp.start + comp.duration)
            if hi <= lo:
                continue
            tt = t[lo:hi] - comp.start
            k = np.pi / comp.duration
            s, c = np.sin(k * tt), np.cos(k * tt)
            window = s**4
            window_d = 4 * s**3 * c * k
            window_dd = (12 * s**2 * c**2 - 4 * s**4) * k**2
            if comp.frequency > 0:
                w = 2 * np.pi * comp.frequency
                osc = np.sin(w * tt + comp.phase)
                osc_d = w * np.cos(w * tt + comp.phase)
                osc_dd = -(w**2) * osc
            else:
                osc, osc_d, osc_dd = 1.0, 0.0, 0.0
            d[lo:hi] += comp.amplitude * window * osc
            v[lo:hi] += comp.amplitude * (window_d * osc + window * osc_d)
            a[lo:hi] += comp.amplitude * (window_dd * osc + 2 * window_d * osc_d + window * osc_dd)
        return d, v, a


@dataclass(frozen=True)
class Excitation:
    kind: ExcitationKind
    bearing: BearingMotion
    rest_s: float
    ambient_force_std: float  # N per load point and sample (0: no ambient load)
    still_phases: tuple[tuple[float, float], ...]  # (start, end) s without bearing motion after the rest


def make_excitation(
    kind: ExcitationKind,
    duration: float,
    rng: np.random.Generator,
    *,
    eigenfrequencies_hz: np.ndarray,
    rest_s: float = 60.0,
    ambient_force_std: float = 0.05,
) -> Excitation:
    """The bearing motion and ambient load of one recording.

    paper: back-and-forth moves of a few centimetres with superimposed components near the
    eigenfrequencies up to the fifth, separated by still phases in which free decays appear.
    ambient: the bearing stands still; random loads along the beam excite all modes (wind-like).
    decay: short broadband plucks of the bearing, each followed by ~50 s of free decay.
    """
    if duration <= 0:
        raise ValueError(f"{duration=} must be positive")
    rest = min(rest_s, duration)
    components: list[_Component] = []
    still: list[tuple[float, float]] = []
    t = rest
    if kind == "paper":
        freqs = np.asarray(eigenfrequencies_hz, dtype=float)[:5]
        while t < duration:
            gap = rng.uniform(6.0, 14.0)
            still.append((t, min(t + gap, duration)))
            t += gap
            length = rng.uniform(10.0, 22.0)
            if t + length > duration:
                break
            components.append(_Component(t, length, rng.choice([-1, 1]) * rng.uniform(0.02, 0.05), 0.0, 0.0))
            for f in rng.choice(freqs, size=rng.integers(1, 4), replace=False):
                f = f * rng.uniform(0.97, 1.03)
                # Keep the bearing's acceleration modest (≤ ~0.6 m/s²) and its stroke small.
                amplitude = min(0.004, rng.uniform(0.15, 0.5) / (2 * np.pi * f) ** 2)
                if f < 0.5:
                    # Near the pendulum resonance a few millimetres already swing the beam by degrees.
                    amplitude = rng.uniform(0.001, 0.003)
                components.append(_Component(t, length, amplitude, f, rng.uniform(0, 2 * np.pi)))
            t += length
        return Excitation(kind, BearingMotion(tuple(components)), rest, 0.0, tuple(still))
    if kind == "ambient":
        return Excitation(kind, BearingMotion(()), rest, ambient_force_std, ())
    if kind == "decay":
        while t < duration:
            length = rng.uniform(0.25, 0.5)
            if t + length > duration:
                break
            components.append(_Component(t, length, rng.choice([-1, 1]) * rng.uniform(0.004, 0.012), 0.0, 0.0))
            gap = rng.uniform(45.0, 60.0)
            still.append((t + length, min(t + length + gap, duration)))
            t += length + gap
        return Excitation(kind, BearingMotion(tuple(components)), rest, 0.0, tuple(still))
    raise ValueError(f"{kind=} must be one of {EXCITATIONS}")
