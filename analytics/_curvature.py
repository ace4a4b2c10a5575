"""Curvature along the beam from deformation variables, operational curvature shapes, change index."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import as_signal

__all__ = ["curvature_field", "curvature_shape", "curvature_change", "CurvatureChange", "beam_third"]


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
