"""Both bending planes of a biaxial beam: each plane's modes analysed on their own (ζ and ξ), and
the degenerate pairs of a symmetric section (a round tube bends at the same frequencies in both
planes: a real case, not an error, and each plane is still tracked on its own)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ._analyze import AnalysisResult

__all__ = ["DEGENERATE_REL", "PLANE_NAMES", "DegeneratePair", "combine_planes", "degenerate_pairs", "with_plane"]

#: the plane names of the contract: "zeta" (the planar contract's plane) and "xi"
PLANE_NAMES = ("zeta", "xi")

#: ζ mode k and ξ mode k closer than this (relative to the ζ frequency) are a degenerate pair even
#: where their stated 1σ are tighter: 0.5 %, what an engineer calls "the same frequency"
DEGENERATE_REL = 0.005


@dataclass(frozen=True)
class DegeneratePair:
    """ζ mode ``mode`` and ξ mode ``mode`` at (about) the same frequency.

    frequency_zeta_hz, frequency_xi_hz : the two planes' identified frequencies (Hz);
    relative_difference : f_ξ / f_ζ − 1; within : "sigma" (inside the combined 1σ) or
    "relative" (inside ``DEGENERATE_REL`` but not the 1σ).
    """

    mode: int
    frequency_zeta_hz: float
    frequency_xi_hz: float
    relative_difference: float
    within: str

    def as_dict(self) -> dict:
        return {"mode": self.mode, "frequency_zeta_hz": self.frequency_zeta_hz, "frequency_xi_hz": self.frequency_xi_hz,
                "relative_difference": self.relative_difference, "within": self.within}


def _column(name: str, values: object) -> np.ndarray:
    """A 1-D float array with None as NaN (an unidentified mode)."""
    if values is None:
        return np.zeros(0)
    out = np.array([np.nan if v is None else v for v in np.atleast_1d(np.asarray(values, dtype=object))], dtype=float)
    if out.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {out.shape}")
    return out


def degenerate_pairs(
    frequency_zeta_hz: object,
    frequency_xi_hz: object,
    std_zeta_hz: object | None = None,
    std_xi_hz: object | None = None,
    *,
    rel_tol: float = DEGENERATE_REL,
) -> tuple[DegeneratePair, ...]:
    """The degenerate pairs of two planes' modes: ζ mode k and ξ mode k with
    ``|f_ξ − f_ζ| <= sqrt(σ_ζ² + σ_ξ²)`` (their combined 1σ) or ``|f_ξ / f_ζ − 1| <= rel_tol``.

    Parameters
    ----------
    frequency_zeta_hz, frequency_xi_hz : (K_ζ,), (K_ξ,) Hz of modes 1, 2, ... of each plane
        (None or NaN: not identified; such a mode pairs with none). Modes 1..min(K_ζ, K_ξ) are compared.
    std_zeta_hz, std_xi_hz : their 1σ (Hz), same lengths, or None (only ``rel_tol`` applies).
        A missing or non-finite 1σ leaves that mode to ``rel_tol``.
    rel_tol : the relative difference below which two modes are the same frequency whatever their 1σ.

    Returns
    -------
    tuple of DegeneratePair, in mode order.

    Raises
    ------
    ValueError
        For a negative or non-finite ``rel_tol``, a 1σ array whose length is not its frequencies',
        or a non-positive frequency.
    """
    if not (isinstance(rel_tol, (int, float)) and math.isfinite(rel_tol) and rel_tol >= 0):
        raise ValueError(f"rel_tol={rel_tol!r} must be a finite number >= 0")
    fz, fx = _column("frequency_zeta_hz", frequency_zeta_hz), _column("frequency_xi_hz", frequency_xi_hz)
    sz = np.full(fz.shape, np.nan) if std_zeta_hz is None else _column("std_zeta_hz", std_zeta_hz)
    sx = np.full(fx.shape, np.nan) if std_xi_hz is None else _column("std_xi_hz", std_xi_hz)
    for name, s, f in (("std_zeta_hz", sz, fz), ("std_xi_hz", sx, fx)):
        if s.shape != f.shape:
            raise ValueError(f"{name} has {s.size} values for {f.size} frequencies")
    for name, f in (("frequency_zeta_hz", fz), ("frequency_xi_hz", fx)):
        if np.any(f[np.isfinite(f)] <= 0):
            raise ValueError(f"{name} must be > 0 Hz where given, got {f.tolist()}")
    out = []
    for k in range(min(fz.size, fx.size)):
        if not (math.isfinite(fz[k]) and math.isfinite(fx[k])):
            continue
        diff = abs(float(fx[k] - fz[k]))
        sigma = math.hypot(sz[k], sx[k])
        if math.isfinite(sigma) and diff <= sigma:
            within = "sigma"
        elif diff <= rel_tol * fz[k]:
            within = "relative"
        else:
            continue
        out.append(DegeneratePair(k + 1, float(fz[k]), float(fx[k]), float(fx[k] / fz[k] - 1.0), within))
    return tuple(out)


def with_plane(summaries: tuple, plane: str) -> tuple:
    """The mode summaries (``ModeSummary``) marked with their plane ("zeta" or "xi")."""
    if plane not in PLANE_NAMES:
        raise ValueError(f"plane={plane!r} must be one of {PLANE_NAMES}")
    return tuple(replace(m, plane=plane) for m in summaries)


def combine_planes(zeta: AnalysisResult, xi: AnalysisResult, *, rel_tol: float = DEGENERATE_REL) -> AnalysisResult:
    """One record's analysis of both planes of a biaxial beam.

    Parameters
    ----------
    zeta, xi : ``AnalysisResult`` of the ζ plane's b(t) and of the ξ plane's b_ξ(t) (``analyze``
        over each plane's own curvature shapes at the same stations).
    rel_tol : see :func:`degenerate_pairs`.

    Returns
    -------
    AnalysisResult
        ``zeta`` with its modes marked "zeta", ``xi`` (its modes marked "xi") and ``degenerate``
        (the pairs of ζ mode k and ξ mode k at the same frequency); each plane keeps its own
        windows, baseline and flags.
    """
    xi_marked = replace(xi, modes=with_plane(xi.modes, "xi"))
    pairs = degenerate_pairs([m.frequency_hz for m in zeta.modes], [m.frequency_hz for m in xi.modes],
                             [m.frequency_std_hz for m in zeta.modes], [m.frequency_std_hz for m in xi.modes], rel_tol=rel_tol)
    return replace(zeta, modes=with_plane(zeta.modes, "zeta"), xi=xi_marked, degenerate=pairs)
