"""Synthetic structures with known poles for the OMA tests (seeded, exact discrete poles)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal


@dataclass(frozen=True)
class ModalSystem:
    """A classically damped system: frequencies_hz (m,), damping (m,), shapes (m, l) real."""

    frequencies_hz: np.ndarray
    damping: np.ndarray
    shapes: np.ndarray

    def discrete_poles(self, fs: float) -> np.ndarray:
        wn = 2 * np.pi * self.frequencies_hz
        lam = -self.damping * wn + 1j * wn * np.sqrt(1 - self.damping**2)
        return np.exp(lam / fs)


def three_dof() -> ModalSystem:
    """A 3-storey shear frame: m = 1 kg each, k = 1000 N/m each, 1 %, 1.5 %, 2 % modal damping."""
    M = np.eye(3)
    k = 1000.0
    K = k * np.array([[2, -1, 0], [-1, 2, -1], [0, -1, 1]], dtype=float)
    w2, phi = linalg.eigh(K, M)
    f = np.sqrt(w2) / (2 * np.pi)
    phi = phi / np.abs(phi).max(axis=0)
    return ModalSystem(f, np.array([0.01, 0.015, 0.02]), phi.T.copy())


def ambient_response(system: ModalSystem, fs: float, n: int, seed: int, *, noise_rel: float = 0.0) -> np.ndarray:
    """Outputs (n, l) of the system under independent white forces on every modal coordinate;
    each mode is a 2nd-order filter whose discrete poles are exactly exp(λ/fs).
    ``noise_rel``: white measurement noise, a fraction of each channel's RMS."""
    rng = np.random.default_rng(seed)
    burn = int(20 / (system.damping.min() * 2 * np.pi * system.frequencies_hz.min()) * fs)
    q = []
    for mu in system.discrete_poles(fs):
        a = np.real(np.poly([mu, np.conj(mu)]))
        e = rng.standard_normal(n + burn)
        q.append(signal.lfilter([1.0], a, e)[burn:])
    y = np.column_stack(q) @ system.shapes
    if noise_rel:
        y = y + noise_rel * y.std(axis=0) * rng.standard_normal(y.shape)
    return y


def exact_correlations(system: ModalSystem, fs: float, max_lag: int) -> np.ndarray:
    """Exact output correlations (max_lag+1, l, l) of :func:`ambient_response` (unit white forces)."""
    blocks = []
    for mu in system.discrete_poles(fs):
        a = np.real(np.poly([mu, np.conj(mu)]))
        # autocorrelation of an AR(2) driven by unit white noise, from its impulse response
        h = signal.lfilter([1.0], a, np.r_[1.0, np.zeros(20000 + max_lag)])
        blocks.append(np.array([h[k:] @ h[: h.size - k] for k in range(max_lag + 1)]))
    r = np.array(blocks)  # (m, K)
    return np.einsum("mk,ma,mb->kab", r, system.shapes, system.shapes)
