"""Extended Kalman filter steps as small functions (compiled with numba).

``predict_covariance`` takes the Jacobian F of an already computed (nonlinear) propagation, so
any kinematic model fits; ``update_scalar`` is one scalar measurement in Joseph form with an
innovation gate. They are the same formulas as filterpy's ``ExtendedKalmanFilter`` (which the
tests use as the reference), written for scalar measurements because the aiding of this product
arrives sensor by sensor at its own time.

Each step has a pure form (returns new arrays) and an ``_into`` form that works in place on
preallocated buffers: the event loop runs millions of steps, and allocations of small arrays
cost more than the arithmetic.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["predict_covariance", "predict_covariance_into", "update_scalar", "update_scalar_into"]


@numba.njit(cache=True)
def predict_covariance_into(P: np.ndarray, F: np.ndarray, Q: np.ndarray, work: np.ndarray) -> None:
    """P ← F P Fᵀ + Q in place (n, n); ``work`` is an (n, n) scratch buffer.

    F of a kinematic model is sparse (the identity plus a few couplings): both products skip its
    zeros, testing each entry of F once per product (n² tests, not n³)."""
    n = P.shape[0]
    for i in range(n):  # work = F P
        for j in range(n):
            work[i, j] = 0.0
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    work[i, j] += f * P[k, j]
    for j in range(n):  # P = work Fᵀ + Q, column j on and above the diagonal
        for i in range(j + 1):
            P[i, j] = Q[i, j]
        for k in range(n):
            f = F[j, k]
            if f != 0.0:
                for i in range(j + 1):
                    P[i, j] += work[i, k] * f
    for j in range(n):  # mirrored: exactly symmetric
        for i in range(j):
            P[j, i] = P[i, j]


@numba.njit(cache=True)
def predict_covariance(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P⁺ = F P Fᵀ + Q (n, n)."""
    out = P.copy()
    predict_covariance_into(out, F, Q, np.empty_like(P))
    return out


@numba.njit(cache=True)
def update_scalar_into(x: np.ndarray, P: np.ndarray, innovation: float, H: np.ndarray, R: float, gate: float,
                       u: np.ndarray) -> tuple[float, float, bool]:
    """One scalar measurement update of x (n,) and P (n, n) in place; ``u`` is an (n,) buffer.

    ``innovation`` is z − h(x), ``H`` the Jacobian row, ``R`` the measurement variance.
    Returns (S, d2, accepted): S the innovation variance and d2 = innovation²/S (the squared
    Mahalanobis distance); with d2 > ``gate`` (or NaN) nothing changes.
    """
    n = x.shape[0]
    # u = P H, column by column over the few states H touches (n tests of H, not n²)
    for i in range(n):
        u[i] = 0.0
    for j in range(n):
        h = H[j]
        if h != 0.0:
            for i in range(n):
                u[i] += P[i, j] * h
    S = R
    for j in range(n):
        S += H[j] * u[j]
    d2 = innovation * innovation / S
    if not (d2 <= gate):
        return S, d2, False
    # Joseph form for a scalar measurement, (I − K Hᵀ) P (I − H Kᵀ) + R K Kᵀ with K = u/S,
    # expanded with u = P H: P − K uᵀ − u Kᵀ + (Hᵀ P H + R) K Kᵀ. O(n²) instead of O(n³).
    inv = 1.0 / S
    for i in range(n):
        Ki = u[i] * inv
        x[i] += Ki * innovation
        for j in range(i, n):
            Kj = u[j] * inv
            v = P[i, j] - Ki * u[j] - u[i] * Kj + S * Ki * Kj
            P[i, j] = v
            P[j, i] = v
    return S, d2, True


@numba.njit(cache=True)
def update_scalar(x: np.ndarray, P: np.ndarray, innovation: float, H: np.ndarray, R: float, gate: float):
    """Pure form of ``update_scalar_into``: returns (x, P, S, d2, accepted) as new arrays."""
    x_new = x.copy()
    P_new = P.copy()
    S, d2, ok = update_scalar_into(x_new, P_new, innovation, H, R, gate, np.empty_like(x))
    return x_new, P_new, S, d2, ok
