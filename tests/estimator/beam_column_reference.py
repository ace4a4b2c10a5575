"""An independent reference for the clamped beam-column: shooting on the ODE, no finite elements.

The free vibration of a beam under the static axial force N(x) (tension > 0) solves

    EI w'''' − (N(x) w')' = ρA ω² w,

written as the first-order system in y = [w, θ = w', M = EI w'', Q = M' − N w']:

    w' = θ,   θ' = M / EI,   M' = Q + N θ,   Q' = ρA ω² w.

An attached mass m with rotary inertia J at x_p makes Q jump by +m ω² w(x_p) and M by
−J ω² θ(x_p) (virtual work of the point inertia). The clamp at x = 0 fixes w = θ = 0; the free
tip has M = Q = 0. Integrating the two fundamental solutions that start with M(0) = 1 and
Q(0) = 1 and asking that some combination meet the tip conditions gives det D(ω) = 0, whose
roots are the eigenfrequencies. This shares nothing with ``estimator._beam`` (no shape functions,
no mesh, no matrices), so it checks the FE model's assembly, its geometric stiffness and its sign.
"""

from __future__ import annotations

import numpy as np
import scipy.integrate
import scipy.optimize


def _axial_force(x, *, length, mu, masses, axial_gravity):
    """N(x) (N): the weight beyond x times the axial gravity (+g hanging: tension; −g standing)."""
    beyond = sum(m for p, m, _ in masses if p > x)
    return axial_gravity * (mu * (length - x) + beyond)


def tip_determinant(omega, *, length, EI, mu, masses=(), axial_gravity=0.0):
    """det D(ω) of the clamped–free beam-column (see module docstring) for an array of ω (rad/s).

    ``masses`` are (x, m, J). All ω are integrated together (one ODE system), which is what
    makes a dense scan affordable. Returns an array like ``omega`` (scaled, the sign is what counts).
    """
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    k = omega.size
    points = sorted({p for p, _, _ in masses if 0.0 < p <= length} | {length})
    y = np.zeros((4, 2, k))
    y[2, 0] = 1.0  # M(0) = 1
    y[3, 1] = 1.0  # Q(0) = 1
    w2 = omega**2
    start = 0.0
    for stop in points:
        if stop > start:
            n_start = _axial_force(start, length=length, mu=mu, masses=masses, axial_gravity=axial_gravity)
            slope = -axial_gravity * mu  # dN/dx between the masses

            def rhs(x, z, n_start=n_start, start=start):
                z = z.reshape(4, 2, k)
                N = n_start + slope * (x - start)  # noqa: B023  (solved within the iteration)
                return np.stack([z[1], z[2] / EI, z[3] + N * z[1], mu * w2 * z[0]]).ravel()

            sol = scipy.integrate.solve_ivp(rhs, (start, stop), y.ravel(), method="DOP853", rtol=1e-11, atol=1e-13)
            y = sol.y[:, -1].reshape(4, 2, k)
        for p, m, J in masses:
            if p == stop:
                y = y.copy()
                y[3] += m * w2 * y[0]
                y[2] -= J * w2 * y[1]
        start = stop
    det = y[2, 0] * y[3, 1] - y[2, 1] * y[3, 0]
    return det / np.abs(y).max(axis=(0, 1)) ** 2


def clamped_frequencies(count, *, length, EI, mu, masses=(), axial_gravity=0.0, f_max=None, samples=400):
    """The first ``count`` eigenfrequencies (Hz) of the clamped–free beam-column by root bracketing.

    ``f_max`` bounds the scan (default: well above the ``count``-th bare clamped–free frequency).
    """
    if f_max is None:
        bare = (np.array([1.8751, 4.6941, 7.8548, 10.9955, 14.1372, 17.2788, 20.4204])[count - 1] / length) ** 2
        f_max = 2.0 * bare * np.sqrt(EI / mu) / (2 * np.pi) + 5.0
    grid = np.geomspace(1e-3, f_max, samples)
    kwargs = dict(length=length, EI=EI, mu=mu, masses=masses, axial_gravity=axial_gravity)
    values = tip_determinant(2 * np.pi * grid, **kwargs)
    roots = []
    for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[:count]:
        lo, hi = grid[i], grid[i + 1]
        # Bisection on a vectorised bracket: 16 points per pass shrink it by 15 each time.
        for _ in range(6):
            f = np.linspace(lo, hi, 16)
            v = tip_determinant(2 * np.pi * f, **kwargs)
            j = np.flatnonzero(np.sign(v[:-1]) != np.sign(v[1:]))[0]
            lo, hi = f[j], f[j + 1]
        roots.append(0.5 * (lo + hi))
    if len(roots) < count:
        raise RuntimeError(f"found only {len(roots)} of {count} roots below {f_max} Hz")
    return np.array(roots)
