"""Prescribed bearing motion d(t) and ambient loads of the virtual rig.

Every excitation starts with a rest phase (the estimator calibrates its biases there). The
bearing motion is a sum of windowed components whose window sin⁴(πτ) starts and ends with zero
displacement, velocity and acceleration, so d, ḋ, d̈ are smooth and known in closed form — or,
for the operational excitation, a stationary random process (:class:`RandomBearingMotion`)
whose d, ḋ, d̈ are outputs of one linear system, so they are consistent at every instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

import numba
import numpy as np
import scipy.linalg
import scipy.signal

from ._wind import storm_factor

__all__ = [
    "BearingMotion", "DistributedLoad", "Excitation", "ExcitationKind", "OperationalExcitation", "RandomBearingMotion",
    "make_excitation",
]

ExcitationKind = Literal["paper", "ambient", "decay", "operational"]
EXCITATIONS: tuple[ExcitationKind, ...] = ("paper", "ambient", "decay", "operational")


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
            # a plain move multiplies the window by constants, an oscillation by arrays over tt
            osc: np.ndarray | float
            osc_d: np.ndarray | float
            osc_dd: np.ndarray | float
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


class Motion(Protocol):
    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


def _ramp(t: np.ndarray, start: float, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raised-cosine ramp 0 → 1 over [start, start + length] and its first two derivatives."""
    if length <= 0:
        on = (t >= start).astype(float)
        return on, np.zeros_like(t), np.zeros_like(t)
    x = np.clip((t - start) / length, 0.0, 1.0)
    inside = (t > start) & (t < start + length)
    k = math.pi / length
    env = 0.5 - 0.5 * np.cos(math.pi * x)
    d1 = np.where(inside, 0.5 * k * np.sin(math.pi * x), 0.0)
    d2 = np.where(inside, 0.5 * k * k * np.cos(math.pi * x), 0.0)
    return env, d1, d2


@numba.njit(cache=True)
def _recursion(phi, noise, x0, out):
    """x_{k+1} = Φ x_k + noise_k; out[k] = x_k (k = 0 … n−1); returns x_n."""
    x = x0.copy()
    n, m = noise.shape
    for k in range(n):
        for i in range(m):
            out[k, i] = x[i]
        y = phi @ x
        for i in range(m):
            x[i] = y[i] + noise[k, i]
    return x


class RandomBearingMotion:
    """A stationary random support motion: its acceleration is white noise through a Butterworth
    band-pass (``order`` per edge, ``band_hz``), the displacement its double integral, scaled to
    ``rms_m`` (after the rest phase and a raised-cosine ramp of ``ramp_s``).

    The band-pass is a cascade of second-order sections in state space; two of its zeros at
    s = 0 are the double integration, so displacement, velocity, acceleration and jerk are all
    outputs of one stable linear system. It is discretised exactly (Van Loan) on a grid of
    ``grid_s``; between grid points d, ḋ and d̈ are cubic Hermite interpolants of (d, ḋ),
    (ḋ, d̈) and (d̈, jerk). Chunks of the grid are generated in order from a seeded stream per
    chunk, with the state at every chunk start kept, so any time can be evaluated again
    (memory: a few chunks and one state per chunk).
    """

    def __init__(self, rng: np.random.Generator, *, rms_m: float, band_hz: tuple[float, float], start_s: float, ramp_s: float,
                 order: int = 4, grid_s: float = 1e-3, chunk_s: float = 10.0) -> None:
        lo, hi = (float(f) for f in band_hz)
        if not (0 < lo < hi < 0.5 / grid_s):
            raise ValueError(f"band_hz={band_hz!r} must satisfy 0 < low < high < {0.5 / grid_s:g} Hz")
        if not rms_m >= 0:
            raise ValueError(f"{rms_m=} must be >= 0")
        z, p, k = scipy.signal.butter(order, [2 * np.pi * lo, 2 * np.pi * hi], btype="bandpass", analog=True, output="zpk")
        poles = [q for q in p if q.imag > 0] + [q for q in p if abs(q.imag) < 1e-12 * abs(q)]
        if len(poles) != order:  # a Butterworth band-pass of this order has only complex pairs
            raise ValueError(f"{order=} gives real poles: use an even-free design")
        m = 2 * order
        A = np.zeros((m, m))
        B = np.zeros(m)
        # sections in order: the first ``order − 2`` carry one zero at s = 0 each (output x'),
        # the last two none (output x): the remaining two zeros at 0 are d = ∬ a
        for i, q in enumerate(poles):
            w2, c = abs(q) ** 2, -2 * q.real
            r = 2 * i
            A[r, r + 1] = 1.0
            A[r + 1, r] = -w2
            A[r + 1, r + 1] = -c
            if i == 0:
                B[r + 1] = 1.0
            else:
                prev = 2 * (i - 1)
                # input of section i: the output of section i − 1 (x' with a zero at 0, else x)
                A[r + 1, prev + (1 if i - 1 < order - 2 else 0)] += 1.0
        last = 2 * (order - 1)
        C_d = np.zeros(m)
        C_d[last] = 1.0
        C_v = C_d @ A  # d/dt of the output is C A x (B does not reach the last section directly)
        C_a = C_v @ A
        C_j = C_a @ A
        if abs(C_d @ B) + abs(C_v @ B) + abs(C_a @ B) + abs(C_j @ B) > 0:
            raise AssertionError("the support motion's outputs must not see the white noise directly")
        P = scipy.linalg.solve_continuous_lyapunov(A, -np.outer(B, B))
        scale = rms_m / math.sqrt(float(C_d @ P @ C_d))
        self._C = np.vstack([C_d, C_v, C_a, C_j]) * scale
        h = float(grid_s)
        # Van Loan: exp([[−A, BBᵀ], [0, Aᵀ]] h) gives Φ = e^{Ah} and the noise covariance Q_d
        M = np.zeros((2 * m, 2 * m))
        M[:m, :m] = -A
        M[:m, m:] = np.outer(B, B)
        M[m:, m:] = A.T
        E = scipy.linalg.expm(M * h)
        self._phi = E[m:, m:].T.copy()
        Q = self._phi @ E[:m, m:]
        Q = 0.5 * (Q + Q.T)
        w, V = np.linalg.eigh(Q)
        self._qroot = V * np.sqrt(np.clip(w, 0.0, None))
        self.h = h
        self.chunk = int(round(chunk_s / h))
        self.start_s, self.ramp_s = float(start_s), float(ramp_s)
        self._seed = int(rng.integers(0, 2**63 - 1))
        Pw, Pv = np.linalg.eigh(0.5 * (P + P.T))
        x0 = (Pv * np.sqrt(np.clip(Pw, 0.0, None))) @ rng.standard_normal(m)  # a stationary start
        self._states: list[np.ndarray] = [x0]
        self._cache: dict[int, np.ndarray] = {}

    def _chunk(self, c: int) -> np.ndarray:
        """Outputs (d, ḋ, d̈, jerk) at the chunk's grid points and its first point of the next, (chunk + 1, 4)."""
        got = self._cache.get(c)
        if got is not None:
            return got
        while len(self._states) <= c:  # the states before c, in order
            self._advance(len(self._states) - 1)
        out = self._advance(c)
        if len(self._cache) >= 8:
            self._cache.pop(next(iter(self._cache)))
        self._cache[c] = out
        return out

    def _advance(self, c: int) -> np.ndarray:
        rng = np.random.default_rng(np.random.SeedSequence(self._seed, spawn_key=(c,)))
        noise = rng.standard_normal((self.chunk, self._phi.shape[0])) @ self._qroot.T
        states = np.empty((self.chunk + 1, self._phi.shape[0]))
        end = _recursion(self._phi, noise, self._states[c], states[:-1])
        states[-1] = end
        if len(self._states) == c + 1:
            self._states.append(end)
        return states @ self._C.T

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Displacement (m), velocity (m/s) and acceleration (m/s²) at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        d = np.zeros_like(t)
        v = np.zeros_like(t)
        a = np.zeros_like(t)
        live = t > self.start_s
        if not np.any(live):
            return d, v, a
        tl = t[live]
        g = tl / self.h
        k = np.floor(g).astype(np.int64)
        s = g - k
        chunks = k // self.chunk
        vals = np.empty((tl.size, 2, 4))
        for c in np.unique(chunks):
            sel = chunks == c
            out = self._chunk(int(c))
            j = k[sel] - c * self.chunk
            vals[sel, 0] = out[j]
            vals[sel, 1] = out[j + 1]
        h = self.h
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        dd, vv, aa = (h00 * vals[:, 0, i] + h10 * h * vals[:, 0, i + 1] + h01 * vals[:, 1, i] + h11 * h * vals[:, 1, i + 1] for i in range(3))
        env, e1, e2 = _ramp(tl, self.start_s, self.ramp_s)
        d[live] = env * dd
        v[live] = env * vv + e1 * dd
        a[live] = env * aa + 2 * e1 * vv + e2 * dd
        return d, v, a


class DistributedLoad:
    """A random load p(η, t) along the beam (N/m), spatially correlated (exponential kernel,
    correlation length ``correlation_m``) and band-limited in time (Butterworth band-pass of
    ``band_hz``, held over each sample), as wind or flow would load a mast or blade; zero during
    the rest phase, then ramped in. ``nodal_loads`` gives the consistent lumped loads at the
    nodes beyond the support (p times each node's tributary length), one block after another.
    """

    def __init__(self, rng: np.random.Generator, nodes_m: np.ndarray, *, rms_n_per_m: float, correlation_m: float,
                 band_hz: tuple[float, float], sample_rate_hz: float, start_s: float, ramp_s: float,
                 storm: tuple[float, float, float] | None = None) -> None:
        x = np.asarray(nodes_m, dtype=float)
        if x.ndim != 1 or x.size < 1 or np.any(np.diff(x) <= 0):
            raise ValueError("nodes_m must be increasing positions along the beam, m")
        if not correlation_m > 0 or not rms_n_per_m >= 0:
            raise ValueError(f"{correlation_m=} must be > 0 and {rms_n_per_m=} >= 0")
        lo, hi = (float(f) for f in band_hz)
        if not (0 < lo < hi < 0.5 * sample_rate_hz):
            raise ValueError(f"band_hz={band_hz!r} must satisfy 0 < low < high < {0.5 * sample_rate_hz:g} Hz")
        C = np.exp(-np.abs(x[:, None] - x[None, :]) / correlation_m)
        lam, V = np.linalg.eigh(C)
        keep = lam > 1e-6 * lam.max()
        self._basis = V[:, keep] * np.sqrt(lam[keep])  # p = basis @ z, z independent with unit variance
        edges = np.concatenate([[x[0]], 0.5 * (x[1:] + x[:-1]), [x[-1]]])
        lower = np.concatenate([[0.0], edges[1:-1]]) if x[0] > 0 else edges[:-1]
        self._tributary = edges[1:] - np.maximum(lower, 0.0)
        self._sos = scipy.signal.butter(4, [lo, hi], btype="bandpass", fs=sample_rate_hz, output="sos")
        impulse = scipy.signal.sosfilt(self._sos, np.r_[1.0, np.zeros(int(60 * sample_rate_hz))])
        self._gain = 1.0 / math.sqrt(float(impulse @ impulse))  # unit variance for unit white noise
        self._zi = np.zeros((self._sos.shape[0], 2, self._basis.shape[1]))
        self.rng = rng
        self.rms = float(rms_n_per_m)
        self.start_s, self.ramp_s = float(start_s), float(ramp_s)
        #: (start s, end s, peak factor) of a storm that passes, or None
        self.storm = storm
        if storm is not None:
            storm_factor([0.0], *storm)  # refuses a bad storm now, not in the middle of a run

    def nodal_loads(self, t: np.ndarray) -> np.ndarray:
        """Loads (len(t), nodes) in N at the next len(t) sample times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        white = self.rng.standard_normal((t.size, self._basis.shape[1]))
        z, self._zi = scipy.signal.sosfilt(self._sos, white, axis=0, zi=self._zi)
        env = _ramp(t, self.start_s, self.ramp_s)[0]
        if self.storm is not None:
            env = env * storm_factor(t, *self.storm)
        p = (z * (self._gain * self.rms)) @ self._basis.T
        return p * env[:, None] * self._tributary[None, :]


@dataclass(frozen=True)
class OperationalExcitation:
    """What the operational excitation is made of (the issue's "3 mm RMS broadband support
    motion and a spatially correlated random distributed load")."""

    support_rms_m: float = 0.003
    support_band_hz: tuple[float, float] = (0.2, 30.0)
    load_rms_n_per_m: float = 0.05
    load_correlation_m: float = 1.0
    load_band_hz: tuple[float, float] = (0.1, 30.0)
    ramp_s: float = 10.0


@dataclass(frozen=True)
class Excitation:
    kind: ExcitationKind
    bearing: Motion
    rest_s: float
    ambient_force_std: float  # N per load point and sample (0: no ambient load)
    still_phases: tuple[tuple[float, float], ...]  # (start, end) s without bearing motion after the rest
    operational: OperationalExcitation | None = None  # the distributed load's settings (operational only)


def make_excitation(
    kind: ExcitationKind,
    duration: float,
    rng: np.random.Generator,
    *,
    eigenfrequencies_hz: np.ndarray,
    rest_s: float = 60.0,
    ambient_force_std: float = 0.05,
    operational: OperationalExcitation | None = None,
) -> Excitation:
    """The bearing motion and ambient load of one recording.

    paper: back-and-forth moves of a few centimetres with superimposed components near the
    eigenfrequencies up to the fifth, separated by still phases in which free decays appear.
    ambient: the bearing stands still; random loads along the beam excite all modes (wind-like).
    decay: short broadband plucks of the bearing, each followed by ~50 s of free decay.
    operational: the support moves randomly (broadband acceleration, a few mm RMS) and a
    spatially correlated random load acts along the beam, both for the whole run after the rest
    (a mast on a vessel, a blade on its hub): :class:`RandomBearingMotion`, :class:`DistributedLoad`.
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
    if kind == "operational":
        op = operational or OperationalExcitation()
        motion = RandomBearingMotion(rng, rms_m=op.support_rms_m, band_hz=op.support_band_hz, start_s=rest, ramp_s=op.ramp_s)
        return Excitation(kind, motion, rest, 0.0, (), op)
    raise ValueError(f"{kind=} must be one of {EXCITATIONS}")
