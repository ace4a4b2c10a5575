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
    """P⁺ = F P Fᵀ + Q, symmetrised (n, n)."""
    Pn = F @ P @ F.T + Q
    return 0.5 * (Pn + Pn.T)


@numba.njit(cache=True)
def update_scalar(x: np.ndarray, P: np.ndarray, innovation: float, H: np.ndarray, R: float, gate: float):
    """One scalar measurement update.

    ``innovation`` is z − h(x), ``H`` (n,) the measurement Jacobian row, ``R`` its variance.
    Returns (x, P, S, d2, accepted): S the innovation variance, d2 = innovation² / S (the
    squared Mahalanobis distance). With d2 > ``gate`` the update is skipped (x, P unchanged).
    """
    PH = P @ H
    S = H @ PH + R
    d2 = innovation * innovation / S
    if not (d2 <= gate):  # also rejects NaN
        return x, P, S, d2, False
    K = PH / S
    x_new = x + K * innovation
    n = x.shape[0]
    I_KH = np.eye(n) - np.outer(K, H)
    P_new = I_KH @ P @ I_KH.T + R * np.outer(K, K)
    return x_new, 0.5 * (P_new + P_new.T), S, d2, True
