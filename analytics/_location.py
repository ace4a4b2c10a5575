"""Model-assisted damage location: match the observed change with predicted damage signatures.

The observed change is the vector of relative eigenfrequency shifts of modes 1..n (temperature
normalised) and, optionally, the change of each mode's operational curvature shape, each
component divided by its 1σ uncertainty. Every candidate damage j (location η_j, kind) predicts
the same vector s_j (e.g. ``estimator.damage_signatures``, computed from the FE model). The
match is the damage location assurance criterion (Messina et al. 1998) generalised to weighted
and signed data:

    match_j = max(0, yᵀ s_j)² / (‖y‖² ‖s_j‖²)   ∈ [0, 1]

(the sign is kept: a damage of the candidate's kind moves the figures in the direction of its
signature, a stiffness loss never raises a frequency). Its maximum gives the location and kind;
α_j = yᵀ s_j / ‖s_j‖² is the severity relative to the signature's (1 = as large as computed).
For Gaussian noise, argmax match_j is the generalised-likelihood-ratio location. Pure numerics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._curvature import beam_third
from ._validate import as_signal

__all__ = ["DamageLocation", "locate_damage"]


@dataclass(frozen=True)
class DamageLocation:
    """Where the observed change points.

    match : (M,) DLAC-type match of each candidate (0..1). eta : (M,) m, kind : (M,) of the
    candidates. profile_eta (K,) m / profile (K,): best match over kinds at each distinct η (the
    index along the beam). eta_m, kind_best, third : the best candidate; best_match its match;
    severity : its α (observed/predicted size); next_best : best match at a different third.
    """

    match: np.ndarray
    eta: np.ndarray
    kind: tuple[str, ...]
    profile_eta: np.ndarray
    profile: np.ndarray
    eta_m: float
    kind_best: str
    third: str
    best_match: float
    severity: float
    next_best: float

    def as_dict(self) -> dict:
        return {"eta_m": round(self.eta_m, 4), "kind": self.kind_best, "third": self.third, "match": round(self.best_match, 4),
                "severity": round(self.severity, 4), "next_best_other_third": round(self.next_best, 4)}


def _get(obj: object, name: str):
    return obj.get(name) if isinstance(obj, dict) else getattr(obj, name, None)


def locate_damage(
    frequency_shift: object,
    frequency_std: object,
    signatures: object,
    *,
    shape_change: object | None = None,
    shape_std: object | None = None,
    length: float | None = None,
) -> DamageLocation:
    """Match observed changes against damage signatures.

    frequency_shift (n,) relative eigenfrequency changes of modes 1..n; frequency_std (n,) their
    1σ (inf or NaN: mode unused). signatures : object or dict with ``eta`` (M,) m, ``kind`` (M,),
    ``frequency_shift`` (M, ≥n) and, if shape_change is given, ``curvature_change`` (M, n, S).
    shape_change (n, S) observed change of the unit-RMS curvature shapes, shape_std (n,) or (n, S)
    its 1σ. length : beam length (m; default ``signatures.length`` or max η).
    """
    df = as_signal("frequency_shift", frequency_shift, min_len=1, ndim=(1,))
    sd = np.asarray(frequency_std, dtype=float)
    if sd.shape != df.shape or np.any(sd <= 0):
        raise ValueError(f"frequency_std must be positive with shape {df.shape}, got {sd.shape}")
    eta = _get(signatures, "eta")
    kind = _get(signatures, "kind")
    sf = _get(signatures, "frequency_shift")
    if eta is None or kind is None or sf is None:
        raise ValueError("signatures need eta, kind and frequency_shift")
    eta = as_signal("signatures.eta", eta, min_len=1, ndim=(1,))
    sf = as_signal("signatures.frequency_shift", sf, min_len=1, ndim=(2,))
    kind = tuple(str(k) for k in kind)
    if sf.shape[0] != eta.size or len(kind) != eta.size or sf.shape[1] < df.size:
        raise ValueError(f"signatures disagree: eta ({eta.size},), kind ({len(kind)},), frequency_shift {sf.shape} for {df.size} modes")
    w = np.where(np.isfinite(sd), 1.0 / np.where(np.isfinite(sd), sd, 1.0), 0.0)
    y = [np.nan_to_num(df) * w]
    S = [sf[:, : df.size] * w]
    if shape_change is not None:
        dk = as_signal("shape_change", shape_change, min_len=1, ndim=(2,))
        sc = _get(signatures, "curvature_change")
        if sc is None:
            raise ValueError("shape_change needs signatures.curvature_change")
        sc = np.asarray(sc, dtype=float)
        if sc.ndim != 3 or sc.shape[0] != eta.size or sc.shape[1] < dk.shape[0] or sc.shape[2] != dk.shape[1]:
            raise ValueError(f"signatures.curvature_change {sc.shape} does not fit shape_change {dk.shape}")
        ks = np.broadcast_to(np.asarray(shape_std if shape_std is not None else 1.0, dtype=float).reshape(
            (-1, 1) if np.ndim(shape_std) == 1 else np.shape(shape_std) or (1, 1)), dk.shape)
        if np.any(~(ks > 0)):
            raise ValueError("shape_std must be positive")
        wk = np.where(np.isfinite(ks), 1.0 / np.where(np.isfinite(ks), ks, 1.0), 0.0)
        y.append((dk * wk).ravel())
        S.append((sc[:, : dk.shape[0]] * wk[None]).reshape(eta.size, -1))
    yv = np.concatenate(y)
    Sm = np.concatenate(S, axis=1)
    ny = float(yv @ yv)
    ns = np.einsum("ij,ij->i", Sm, Sm)
    proj = Sm @ yv
    ok = (ns > 0) & (ny > 0)
    match = np.where(ok, np.maximum(proj, 0.0) ** 2 / np.where(ok, ns * ny, 1.0), 0.0)
    L = float(length if length is not None else (_get(signatures, "length") or eta.max()))
    j = int(np.argmax(match))
    third = beam_third(float(eta[j]), L)
    others = [m for m, e in zip(match, eta) if beam_third(float(e), L) != third]
    pe = np.unique(np.round(eta, 9))
    profile = np.array([match[np.isclose(eta, e)].max() for e in pe])
    return DamageLocation(match, eta, kind, pe, profile, float(eta[j]), kind[j], third, float(match[j]),
                          float(proj[j] / ns[j]) if ns[j] > 0 else 0.0, float(max(others, default=0.0)))
