"""An independent reference for beams whose section varies: shooting on the ODE, no finite elements.

The free vibration of a beam of bending stiffness EI(x) and mass per length μ(x) under the static
axial force N(x) (tension > 0) solves

    (EI w'')'' − (N w')' = ω² μ w,

written as the first-order system in y = [w, θ = w', M = EI w'', Q = M' − N w', N]:

    w' = θ,   θ' = M / EI(x),   M' = Q + N θ,   Q' = ω² μ(x) w,   N' = −g_η μ(x),

with g_η the gravity along +η (+g hanging, −g standing): N is the weight beyond x times g_η, and
N(0) = g_η × (the whole mass), from ``scipy.integrate.quad``. An attached mass m at x_p makes Q
jump by +m ω² w(x_p) and N by −g_η m. The support at x = 0 fixes w = θ = 0 (clamped) or
w = M = 0 (pinned); the free tip has M = Q = 0. Across a step of the section w, θ, M and Q are
continuous (the integration restarts there). Two fundamental solutions and det D(ω) = 0 give the
eigenfrequencies. Nothing here is shared with ``estimator._beam`` or with ``contract.Beam``: the
caller gives EI(x) and μ(x) as plain functions written from the closed forms.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import numpy as np
import scipy.integrate

Profile = Callable[[float], float]


def _total_mass(mu: Profile, breaks: Sequence[float]) -> float:
    return float(sum(scipy.integrate.quad(mu, a, b, epsabs=0.0, epsrel=1e-13, limit=200)[0]
                     for a, b in itertools.pairwise(breaks) if b > a))


def tip_determinant(omega, *, length: float, EI: Profile, mu: Profile, breaks: Sequence[float] = (),
                    masses: Sequence[tuple[float, float]] = (), axial_gravity: float = 0.0,
                    support: str = "clamped") -> np.ndarray:
    """det D(ω) (scaled; its sign is what counts) for an array of ω (rad/s).

    ``EI`` and ``mu`` are functions of x valid inside each stretch between ``breaks`` (steps);
    ``masses`` are (x, m) attached masses.
    """
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    k = omega.size
    points = sorted({float(p) for p in breaks if 0.0 < p < length} | {p for p, _ in masses if 0.0 < p < length}
                    | {float(length)})
    total = _total_mass(mu, [0.0, *points]) + sum(m for _, m in masses)
    y = np.zeros((4, 2, k))
    if support == "clamped":
        y[2, 0] = 1.0  # M(0) = 1
        y[3, 1] = 1.0  # Q(0) = 1
    elif support == "pinned":
        y[1, 0] = 1.0  # θ(0) = 1
        y[3, 1] = 1.0  # Q(0) = 1
    else:
        raise ValueError(f"{support=} must be 'clamped' or 'pinned'")
    axial = axial_gravity * total
    w2 = omega**2
    start = 0.0
    for stop in points:
        # a probe just inside the stretch picks the section beyond a step
        def rhs(x, z):
            n = z[-1]
            z = z[:-1].reshape(4, 2, k)
            m_here = mu(x)
            d = np.stack([z[1], z[2] / EI(x), z[3] + n * z[1], m_here * w2 * z[0]]).ravel()
            return np.concatenate([d, [-axial_gravity * m_here]])

        state = np.concatenate([y.ravel(), [axial]])
        sol = scipy.integrate.solve_ivp(rhs, (start, stop), state, method="DOP853", rtol=1e-12, atol=1e-14)
        if not sol.success:
            raise RuntimeError(sol.message)
        y = sol.y[:-1, -1].reshape(4, 2, k)
        axial = sol.y[-1, -1]
        for p, m in masses:
            if p == stop:
                y = y.copy()
                y[3] += m * w2 * y[0]
                axial -= axial_gravity * m
        start = stop
    det = y[2, 0] * y[3, 1] - y[2, 1] * y[3, 0]
    return det / np.abs(y).max(axis=(0, 1)) ** 2


def frequencies(count: int, *, f_max: float, samples: int = 300, **kwargs) -> np.ndarray:
    """The first ``count`` eigenfrequencies (Hz) below ``f_max`` by root bracketing, to ~1e-9 relative."""
    grid = np.geomspace(1e-3, f_max, samples)
    values = tip_determinant(2 * np.pi * grid, **kwargs)
    roots = []
    for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[:count]:
        lo, hi = grid[i], grid[i + 1]
        for _ in range(8):  # 16 points per pass shrink the bracket 15-fold
            f = np.linspace(lo, hi, 16)
            v = tip_determinant(2 * np.pi * f, **kwargs)
            change = np.flatnonzero(np.sign(v[:-1]) != np.sign(v[1:]))
            if change.size != 1:  # the integration's own error decides the sign: the bracket is that narrow
                break
            lo, hi = f[change[0]], f[change[0] + 1]
        roots.append(0.5 * (lo + hi))
    if len(roots) < count:
        raise RuntimeError(f"found only {len(roots)} of {count} roots below {f_max} Hz")
    return np.array(roots)
