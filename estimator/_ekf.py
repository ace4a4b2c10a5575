"""Extended Kalman filter steps as small pure functions (compiled with numba).

``predict`` takes the already propagated state and the Jacobian F of the propagation, so any
(nonlinear) kinematic model fits; ``update_scalar`` is one scalar measurement in Joseph form,
with an innovation gate. The same formulas as filterpy's ``ExtendedKalmanFilter`` (which the
tests use as the reference), written for scalar measurements because the aiding of this product
arrives sensor by sensor at its own time.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["predict_covariance", "update_scalar"]


@numba.njit(cache=True)
def predict_covariance(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P⁺ = F P Fᵀ + Q (n, n), symmetric by construction.

    Explicit loops: for the ~10-state IMMS they beat BLAS calls, whose overhead dominates.
    """
    n = P.shape[0]
    FP = np.zeros((n, n))
    for i in range(n):
        for k in range(n):
            f = F[i, k]
            if f != 0.0:
                for j in range(n):
                    FP[i, j] += f * P[k, j]
    Pn = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            acc = Q[i, j]
            for k in range(n):
                acc += FP[i, k] * F[j, k]
            Pn[i, j] = acc
            Pn[j, i] = acc
    return Pn


@numba.njit(cache=True)
def update_scalar(x: np.ndarray, P: np.ndarray, innovation: float, H: np.ndarray, R: float, gate: float):
    """One scalar measurement update.

    ``innovation`` is z − h(x), ``H`` (n,) the measurement Jacobian row, ``R`` its variance.
    Returns (x, P, S, d2, accepted): S the innovation variance, d2 = innovation² / S (the
    squared Mahalanobis distance). With d2 > ``gate`` the update is skipped (x, P unchanged).
    """
    n = x.shape[0]
    u = np.zeros(n)  # P H
    for i in range(n):
        acc = 0.0
        for j in range(n):
            h = H[j]
            if h != 0.0:
                acc += P[i, j] * h
        u[i] = acc
    S = R
    for j in range(n):
        S += H[j] * u[j]
    d2 = innovation * innovation / S
    if not (d2 <= gate):  # also rejects NaN
        return x, P, S, d2, False
    K = u / S
    x_new = x + K * innovation
    # Joseph form for a scalar measurement, (I − K Hᵀ) P (I − H Kᵀ) + R K Kᵀ, expanded with
    # u = P H: P − K uᵀ − u Kᵀ + (Hᵀ P H + R) K Kᵀ. O(n²) instead of O(n³), same numbers.
    P_new = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            v = P[i, j] - K[i] * u[j] - u[i] * K[j] + S * K[i] * K[j]
            P_new[i, j] = v
            P_new[j, i] = v
    return x_new, P_new, S, d2, True
