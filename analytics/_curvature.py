"""Curvature along the beam from deformation variables; mode-shape curvature (Pandey, Biswas & Samman
1991) of identified mode shapes in unit-deformation coordinates; the change index along the beam and
the curvature chart's statistic."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import as_signal

__all__ = ["curvature_field", "curvature_shape", "mode_shape_curvature", "curvature_change", "curvature_statistic", "CurvatureChange",
           "CurvatureStatistic", "beam_third"]


def _check_shapes(curvature_shapes: object, gamma: int | None = None) -> np.ndarray:
    S = as_signal("curvature_shapes", curvature_shapes, min_len=2, ndim=(2,))
    if gamma is not None and S.shape[1] != gamma:
        raise ValueError(f"curvature_shapes has {S.shape[1]} columns, b has {gamma} unit deformations")
    return S


def curvature_field(b: object, curvature_shapes: object) -> np.ndarray:
    """κ(η, t) = Σ_χ b_χ(t) s''_χ(η): b (N, Γ) (m), curvature_shapes (len(η), Γ) (1/m²) → (N, len(η)) 1/m."""
    B = as_signal("b", b, min_len=1, ndim=(2,))
    S = _check_shapes(curvature_shapes, B.shape[1])
    return B @ S.T


def curvature_shape(cross: object, reference: int, curvature_shapes: object) -> np.ndarray:
    """Operational curvature shape of one mode, unit RMS along η, sign fixed by the reference unit.

    cross : (Γ,) complex cross spectra G_{χ,ref} = E[c_χ·conj(c_ref)] of the deformation variables
    at the mode's frequency (any unit); the in-phase (real) part is the mode's share in each b_χ.
    Returns (len(η),) dimensionless.
    """
    G = np.asarray(cross, dtype=complex)
    if G.ndim != 1 or not np.all(np.isfinite(G)):
        raise ValueError(f"cross must be a finite 1-D complex array, got shape {G.shape}")
    S = _check_shapes(curvature_shapes, G.size)
    if not isinstance(reference, (int, np.integer)) or not 0 <= reference < G.size:
        raise ValueError(f"{reference=} must index one of the {G.size} unit deformations")
    k = S @ G.real
    rms = float(np.sqrt(np.mean(k**2)))
    if rms == 0:
        raise ValueError("cross gives a zero curvature shape")
    return k / rms


def mode_shape_curvature(shapes: object, curvature_shapes: object, reference: object) -> np.ndarray:
    """Mode-shape curvature (Pandey, Biswas & Samman 1991) of mode shapes over the unit deformations.

    A mode shape φ over the Γ unit deformations (the identified shape of b, any scale and sign) has
    the curvature κ(η) = Σ_χ φ_χ s''_χ(η) along the beam. Each mode's κ is normalised to unit RMS
    over the stations and its sign fixed by ``reference``, so that shapes of different windows,
    excitations and amplitudes compare.

    Parameters
    ----------
    shapes : (modes, Γ) real mode shapes over the unit deformations (any unit).
    curvature_shapes : (len(η), Γ) s''_χ at the stations (1/m²).
    reference : (modes,) integers, the unit deformation whose component of φ is made positive (the
        convention of ``estimator.damage_signatures``), or (modes, len(η)) reference curvatures
        onto which each κ projects positively (a baseline's).

    Returns
    -------
    (modes, len(η)) dimensionless unit-RMS curvature shapes.

    Raises
    ------
    ValueError
        For shapes of the wrong size, a reference that does not fit, or a shape whose curvature
        vanishes at every station.

    Examples
    --------
    >>> S = np.array([[1.0, 0.0], [0.0, 2.0]])
    >>> mode_shape_curvature([[3.0, 0.0]], S, [0]).tolist()
    [[1.4142135623730951, 0.0]]
    """
    P = as_signal("shapes", np.atleast_2d(np.asarray(shapes, dtype=float)), min_len=1, ndim=(2,))
    S = _check_shapes(curvature_shapes, P.shape[1])
    k = P @ S.T
    rms = np.sqrt(np.mean(k**2, axis=1, keepdims=True))
    if np.any(rms == 0):
        raise ValueError("a shape has zero curvature at every station")
    k = k / rms
    ref = np.asarray(reference)
    if ref.shape == (P.shape[0],) and np.issubdtype(ref.dtype, np.integer):
        if np.any((ref < 0) | (ref >= P.shape[1])):
            raise ValueError(f"reference={ref.tolist()} must index the {P.shape[1]} unit deformations")
        sign = np.sign(P[np.arange(P.shape[0]), ref])
    elif ref.shape == k.shape and np.all(np.isfinite(ref.astype(float))):
        sign = np.sign(np.sum(k * ref, axis=1))
    else:
        raise ValueError(f"reference of shape {ref.shape} must be ({P.shape[0]},) unit indices or {k.shape} curvatures")
    sign[sign == 0] = 1.0
    return k * sign[:, None]


@dataclass(frozen=True)
class CurvatureStatistic:
    """The curvature chart's statistic of one window.

    q : mean over the used modes and stations of (Δκ/σ)² (dimensionless; 1 on average when
    healthy). q_std : its healthy standard deviation. score : (q − 1)/q_std, σ. sigma : (modes,
    len(η)) the σ each Δκ was divided by (inf where unused). terms : number of (mode, station)
    terms in q.
    """

    q: float
    q_std: float
    score: float
    sigma: np.ndarray
    terms: int


def curvature_statistic(delta: object, covariance: object, tolerance: float, used: object | None = None) -> CurvatureStatistic:
    """Standardised change of curvature shapes against a baseline: the curvature chart's statistic.

    The change Δκ of each mode's (averaged) unit-RMS curvature shape is, for a healthy structure, the
    average's estimation error (covariance C_i over the stations, learnt from the baseline's windows
    and scaled to the average) plus a tolerance τ per station for what the baseline cannot show:
    the small shift of an identified shape with the excitation's balance (wind spectrum, storm). So
    Δκ_i ~ N(0, C_i + τ²I), and Q = mean over modes and stations of (Δκ/σ)², σ² = diag(C_i) + τ², has
    mean 1 and variance 2·Σ_i tr(R_i²)/n² (R_i the correlation matrix of mode i's terms, n the
    number of terms): the score (Q − 1)/std(Q) in σ.

    Parameters
    ----------
    delta : (modes, len(η)) change of the curvature shapes against the baseline's (dimensionless).
    covariance : (modes, len(η), len(η)) covariance of each mode's Δκ for a healthy structure
        without the tolerance (dimensionless²).
    tolerance : τ ≥ 0, the per-station 1σ of a healthy shift the baseline cannot learn (dimensionless).
    used : (modes, len(η)) booleans, the terms to count (default: all); a station where a mode's
        curvature is zero by construction (a free end) carries no information.

    Returns
    -------
    CurvatureStatistic

    Raises
    ------
    ValueError
        For arrays that disagree, a negative tolerance, no term to use, or a zero σ.

    Examples
    --------
    >>> s = curvature_statistic([[0.02, 0.0]], np.zeros((1, 2, 2)), 0.01)
    >>> round(s.q, 6), round(s.q_std, 6), round(s.score, 6)
    (2.0, 1.0, 1.0)
    """
    D = as_signal("delta", delta, min_len=1, ndim=(2,))
    C = np.asarray(covariance, dtype=float)
    if C.shape != (D.shape[0], D.shape[1], D.shape[1]) or not np.all(np.isfinite(C)):
        raise ValueError(f"covariance of shape {C.shape} must be finite {(D.shape[0], D.shape[1], D.shape[1])} for delta {D.shape}")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"{tolerance=} must be a finite number >= 0")
    U = np.ones(D.shape, dtype=bool) if used is None else np.asarray(used, dtype=bool)
    if U.shape != D.shape:
        raise ValueError(f"used of shape {U.shape} must match delta {D.shape}")
    n = int(U.sum())
    if n == 0:
        raise ValueError("no (mode, station) term is used")
    sigma = np.full(D.shape, np.inf)
    q_sum = 0.0
    trace2 = 0.0
    for i in range(D.shape[0]):
        u = U[i]
        if not u.any():
            continue
        Ci = C[i][np.ix_(u, u)] + tolerance**2 * np.eye(int(u.sum()))
        sd = np.sqrt(np.diag(Ci))
        if np.any(sd <= 0):
            raise ValueError(f"mode {i + 1} has a zero σ at a used station: give a tolerance > 0")
        sigma[i, u] = sd
        q_sum += float(np.sum((D[i, u] / sd) ** 2))
        R = Ci / np.outer(sd, sd)
        trace2 += float(np.sum(R**2))
    q = q_sum / n
    q_std = float(np.sqrt(2.0 * trace2)) / n
    return CurvatureStatistic(q, q_std, (q - 1.0) / q_std, sigma, n)


@dataclass(frozen=True)
class CurvatureChange:
    """Change of normalised curvature shapes against a baseline.

    index : (len(η),) RMS over modes of the shape differences (dimensionless; 0 = unchanged).
    total : RMS of ``index`` over η (dimensionless). eta_m : η (m) of the largest change.
    third : "upper" / "middle" / "lower" third of the beam (η from the bearing, downwards).
    """

    index: np.ndarray
    total: float
    eta_m: float
    third: str


def beam_third(eta: float, length: float) -> str:
    """'upper' for η < L/3, 'middle' for η < 2L/3, else 'lower' (η measured from the bearing, m)."""
    if not np.isfinite(eta) or not length > 0:
        raise ValueError(f"{eta=} and {length=} must be finite with length > 0")
    r = eta / length
    return "upper" if r < 1 / 3 else ("middle" if r < 2 / 3 else "lower")


def curvature_change(shapes: object, baseline_shapes: object, stations_eta: object, length: float) -> CurvatureChange:
    """Index along η of the change of curvature shapes (modes, len(η)) against baseline shapes (same)."""
    A = as_signal("shapes", shapes, min_len=1, ndim=(2,))
    B = as_signal("baseline_shapes", baseline_shapes, min_len=1, ndim=(2,))
    eta = as_signal("stations_eta", stations_eta, min_len=2, ndim=(1,))
    if A.shape != B.shape or A.shape[1] != eta.size:
        raise ValueError(f"shapes {A.shape}, baseline_shapes {B.shape} and stations_eta ({eta.size},) disagree")
    sign = np.sign(np.sum(A * B, axis=1, keepdims=True))
    sign[sign == 0] = 1
    d = A * sign - B
    index = np.sqrt(np.mean(d**2, axis=0))
    i = int(np.argmax(index))
    return CurvatureChange(index, float(np.sqrt(np.mean(index**2))), float(eta[i]), beam_third(float(eta[i]), float(length)))
