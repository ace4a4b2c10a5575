"""Virtual strain, stress and bending moment along the beam from the deformation variables, and the
loads summary of one signal (rainflow, DELs, Miner damage) — the paper's Section 6 outlook.

ε(η, t) = −c(η)·κ(η, t) with κ = Σ_χ b_χ s''_χ(η) (the contract's sign: the +ζ face), σ = E(T)·ε,
M = EI(η, T)·κ. Pure numerics: arrays in, arrays and frozen results out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ._fatigue import FatigueDetail
from ._rainflow import Cycles, HalfCyclePolicy, _finite_samples, _half_weight, cycles_by_range, rainflow_cycles
from ._sn_curves import damage_equivalent_range
from ._validate import as_signal

__all__ = ["BAND_COVERAGE", "BAND_FLOOR", "UNKNOWN_LEVERAGE", "WITHHOLD_HALF_WIDTH", "DelBand", "OutsideBasis", "outside_basis_bands", "SignalLoads", "VirtualLoads", "bending_moment", "gauge_bands", "signal_loads", "virtual_strain"]


def virtual_strain(b: object, curvature_shapes: object, fibre_distance: object) -> np.ndarray:
    """ε(η, t) = −c(η) Σ b_χ(t) s''_χ(η).

    Parameters
    ----------
    b : (N, Γ) deformation variables (m). curvature_shapes : (S, Γ) s''_χ at the stations (1/m per
    unit b). fibre_distance : (S,) c at the stations (m, > 0).

    Returns
    -------
    (N, S) bending strain (m/m) on the +ζ face.

    Examples
    --------
    >>> virtual_strain([[1.0, 2.0]], [[1e-3, 0.0], [0.0, 1e-3]], [0.005, 0.005]).tolist()
    [[-5e-06, -1e-05]]
    """
    B = as_signal("b", b, min_len=1, ndim=(2,))
    S = as_signal("curvature_shapes", curvature_shapes, min_len=1, ndim=(2,))
    if S.shape[1] != B.shape[1]:
        raise ValueError(f"curvature_shapes has {S.shape[1]} columns, b has {B.shape[1]} unit deformations")
    kappa = B @ S.T
    c = as_signal("fibre_distance", fibre_distance, min_len=1, ndim=(1,))
    if c.size != kappa.shape[1]:
        raise ValueError(f"fibre_distance has {c.size} stations, curvature_shapes {kappa.shape[1]}")
    if np.any(c <= 0):
        raise ValueError(f"fibre_distance must be > 0, got {c[c <= 0][0]}")
    return -kappa * c


def bending_moment(curvature: object, bending_stiffness: object) -> np.ndarray:
    """M = EI·κ (N·m): curvature (N, S) 1/m, bending_stiffness (S,) or (N, S) N·m² (> 0)."""
    k = as_signal("curvature", curvature, min_len=1, ndim=(2,))
    ei = np.asarray(bending_stiffness, dtype=float)
    if not np.all(np.isfinite(ei)) or np.any(ei <= 0):
        raise ValueError("bending_stiffness must be finite and > 0")
    return k * ei


@dataclass(frozen=True)
class DelBand:
    """Relative band of a virtual signal's DEL: the true DEL lies in [DEL·low, DEL·high] (low ≤ 1 ≤ high)."""

    low: float
    high: float
    method: str


#: Smallest half-width of a virtual station's DEL band (the estimate's own resolution).
BAND_FLOOR = 0.02
#: Two-sided coverage of the prediction of a station's half-width between or beyond the gauges.
PREDICTION_COVERAGE = 0.8
#: Leverage assumed for a gauge that aided the estimate when its own is unknown (an estimate file, the
#: live engine): its residual r becomes r/(1 − h) = 2r. A re-estimate without the gauge (``shm loads`` on
#: a raw recording) needs no assumption: its virtual strain there is out of sample (h = 0).
UNKNOWN_LEVERAGE = 0.5


def _held_out_strain(name: str, virtual: object, measured: object, leverage: float) -> tuple[float, np.ndarray, np.ndarray]:
    """(h, measured, held-out virtual strain) of a gauge: the virtual strain's residual widened by
    1/(1 − h), as if the estimate had not seen this gauge (h: its leverage, in [0, 1))."""
    h = float(leverage)
    if not 0.0 <= h < 1.0:
        raise ValueError(f"leverage of gauge {name} must be in [0, 1), got {leverage}")
    m = _finite_samples(f"strain gauge {name}", measured)
    v = _finite_samples(f"virtual strain at {name}", virtual)
    if m.size != v.size or m.size == 0:
        raise ValueError(f"gauge {name}: virtual strain has {v.size} samples, measured {m.size} (must agree, > 0)")
    return h, m, m - (m - v) / (1.0 - h)


def gauge_bands(gauges: list[tuple[str, float, np.ndarray, np.ndarray, float]], stations: object, *,
                exponents: tuple[float, ...], n_eq: float,
                half_cycles: HalfCyclePolicy = "half") -> tuple[list[DelBand] | None, list[dict]]:
    """Per-station DEL bands of virtual strain from leave-one-gauge-out residuals at the strain gauges.

    At gauge g the virtual strain v (from b) is compared with the measured strain m. When v comes
    from an estimate that never saw gauge g its residual r = m − v is out of sample (leverage h = 0);
    when g aided the estimate, v was pulled towards m and the leave-one-out residual is r/(1 − h)
    (the hat-matrix correction), so v_loo = m − r/(1 − h). The gauge's DEL factor is
    ρ_m = DEL_m(measured)/DEL_m(v_loo) and its half-width a_g = max over exponents of max(ρ, 1/ρ) − 1.
    A station at a gauge takes that gauge's a. Elsewhere no gauge sees the truncation: the n gauges'
    half-widths are a sample of it, and a point's is predicted from them with Student's t (zero
    mean, n degrees of freedom, two-sided ``PREDICTION_COVERAGE``): k·rms(a_g), k = t·sqrt(1 + 1/n).
    Between two gauges a station takes the larger of the two gauges' and the prediction; beyond
    the outermost gauges the largest of all and the prediction; at least ``BAND_FLOOR``. The band
    is [DEL/(1 + a), DEL·(1 + a)].

    Parameters
    ----------
    gauges : (name, position m, virtual strain (n,), measured strain (n,), leverage h in [0, 1)) per gauge.
    stations : (S,) positions of the virtual stations, m.
    exponents : Wöhler exponents (> 0). n_eq : equivalent cycles (> 0).

    Returns
    -------
    (one DelBand per station, or None without a gauge that has cycles; per gauge its discrepancies).

    Raises
    ------
    ValueError : a leverage outside [0, 1), virtual and measured of different lengths, a non-finite sample.

    Examples
    --------
    >>> m = np.sin(np.linspace(0.0, 20.0, 400))
    >>> bands, _ = gauge_bands([("g1", 1.0, m / 1.1, m, 0.0)], [1.0], exponents=(3.0,), n_eq=10.0)
    >>> round(bands[0].high, 6)
    1.1
    """
    eta = as_signal("stations", stations, min_len=1, ndim=(1,))
    rows, found = [], []
    for name, position, virtual, measured, leverage in gauges:
        h, m, loo = _held_out_strain(name, virtual, measured, leverage)
        g = signal_loads(m, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"strain gauge {name}")
        w = signal_loads(loo, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"virtual strain at {name}")
        ratios = [(mx, dg / dv if dv > 0 else np.inf) for (mx, _, dg), (_, _, dv) in zip(g.dels, w.dels) if dg > 0]
        a = max((max(r, 1.0 / r) - 1.0 for _, r in ratios), default=None)
        rows.append({"name": name, "position_m": float(position), "leverage": h, "out_of_sample": h == 0.0,
                     "del_factor": [{"m": mx, "measured_over_virtual": r} for mx, r in ratios], "half_width": a,
                     "strain_rms_discrepancy": float(np.sqrt(np.mean((loo - m) ** 2)) / max(g.rms, 1e-300))})
        if a is not None:  # a gauge without cycles says nothing about the DELs
            found.append((float(position), a, str(name)))
    if not found:
        return None, rows
    found.sort()
    pos = np.array([p for p, _, _ in found])
    half = np.array([a for _, a, _ in found])
    # between the gauges the truncation is unseen: the gauges' half-widths are a sample of n values of
    # it, and a station's is predicted from them (Student's t, zero mean, n degrees of freedom, two-sided
    # PREDICTION_COVERAGE): k·rms with k = t·sqrt(1 + 1/n)
    n = half.size
    predicted = float(stats.t.ppf(0.5 + PREDICTION_COVERAGE / 2, n) * np.sqrt(1.0 + 1.0 / n) * np.sqrt(np.mean(half**2)))
    names = ", ".join(f"{n} {p:g} m" for p, _, n in found)
    kinds = {"out of sample" if r["out_of_sample"] else f"in sample, h = {r['leverage']:g}" for r in rows}
    bands = []
    for x in eta:
        at = np.isclose(pos, x, rtol=0.0, atol=1e-9)
        if at.any():
            a, where = float(half[at].max()), "at that gauge"
        elif pos[0] < x < pos[-1]:
            k = int(np.searchsorted(pos, x))
            a, where = float(max(half[k - 1], half[k], predicted)), (
                f"the larger of the gauges at {pos[k - 1]:g} and {pos[k]:g} m and the prediction {predicted:.4f}")
        else:
            a, where = float(max(half.max(), predicted)), f"beyond the outermost gauges: the largest and the prediction {predicted:.4f}"
        a = max(BAND_FLOOR, a)
        method = (f"leave-one-gauge-out DEL residuals at the strain gauges ({names}; {', '.join(sorted(kinds))}): "
                  f"measured/virtual DEL factor rho with the virtual strain of an estimate without the gauge, or the "
                  f"in-sample residual r/(1-h); a = max(rho, 1/rho) - 1 over the exponents; between and beyond the gauges at "
                  f"least the {PREDICTION_COVERAGE:.0%} Student-t prediction from the gauges' a; station at {x:g} m: {where}, "
                  f"at least {BAND_FLOOR:.0%}; band [DEL/(1+a), DEL*(1+a)] with a = {a:.4f}")
        bands.append(DelBand(1.0 / (1.0 + a), 1.0 + a, method))
    return bands, rows


#: Nominal two-sided coverage of a station's calibrated DEL band (:func:`outside_basis_bands`).
BAND_COVERAGE = 0.9
#: A station whose DEL band is wider than ±this (relative) has no damage or life figure: the DEL is
#: not known well enough for one (damage goes with DEL^m: ±50 % on the DEL is a factor 3.4 at m = 3).
WITHHOLD_HALF_WIDTH = 0.5


@dataclass(frozen=True)
class OutsideBasis:
    """What the structure does beyond the estimator's basis, where the band needs it.

    gauge_shapes : (G, K) strain per unit modal amplitude (−c ψ''_j) of K modes above the basis at
    the G gauges, in the order of the gauges given to :func:`outside_basis_bands`.
    station_shapes : (S, K) the same at the stations. station_rms : (S,) RMS of each station's
    virtual strain over the span the band is for (m/m).
    """

    gauge_shapes: np.ndarray
    station_shapes: np.ndarray
    station_rms: np.ndarray


def _conformal_max(scores: np.ndarray, coverage: float) -> float:
    """The split-conformal quantile of ``scores``: the ⌈(n + 1)·coverage⌉-th smallest; with too few
    scores for that coverage (the rank beyond n) the largest, whose coverage is n/(n + 1)."""
    s = np.sort(np.asarray(scores, dtype=float))
    n = s.size
    rank = int(math.ceil((n + 1) * coverage))
    return float(s[min(rank, n) - 1])


def outside_basis_bands(gauges: list[tuple[str, float, np.ndarray, np.ndarray, float]], stations: object,
                        outside: OutsideBasis, *, exponents: tuple[float, ...], n_eq: float,
                        half_cycles: HalfCyclePolicy = "half", coverage: float = BAND_COVERAGE,
                        windows: int = 1) -> tuple[list[DelBand] | None, list[dict]]:
    """Per-station DEL bands calibrated on the gauges' cross-validated residuals and carried along
    the beam by the modes above the basis.

    At gauge g the virtual strain v (leave-one-out: from an estimate without g, or the in-sample
    residual r widened to r/(1 − h)) misses e_g = m − v_loo of the measured m. Three steps:

    1. **The curvature outside the basis along the beam.** The residuals' variances σ_g² are
       fitted (non-negative least squares) by K modes above the basis and a floor,
       σ_g² = σ₀² + Σ_j λ_j φ_j(g)², φ_j = −c ψ''_j; at a station η the missing strain then has
       σ_e(η)² = σ₀² + Σ_j λ_j φ_j(η)², and its relative size q(η) = σ_e(η)/rms(v(η)).
    2. **What a relative residual does to the DEL, cross-validated.** At each gauge and in each of
       ``windows`` equal parts of the span (and over the whole span) the DEL factor
       ρ = DEL_m(m)/DEL_m(v_loo), its score |ln ρ| (largest over the exponents) over the gauge's
       q_g = rms(e_g)/rms(v_loo) is one sample of κ, the log-DEL error per unit relative
       residual. κ̂ is the split-conformal ``coverage`` quantile of the gauges' scores, each
       gauge's own the largest over its parts (the parts of one gauge are not independent); with
       fewer gauges than that coverage needs (4 gauges: 90 % needs 9) the largest score, a coverage
       of n/(n + 1) under exchangeable positions.
    3. **The band.** ln(1 + a) = κ̂·q(η), at least what the gauges saw there (whole-span |ln ρ|: at
       a gauge its own, between two gauges the larger of the two, beyond them the largest), at least
       ``BAND_FLOOR``. [DEL/(1 + a), DEL·(1 + a)].

    Where the structure lies in its basis the residuals are the estimate's noise: q and the band
    are small. Where modes above the basis carry curvature, the fitted λ put it where those modes
    bend, between and beyond the gauges too.

    Parameters
    ----------
    gauges : (name, position m, virtual strain (n,), measured strain (n,), leverage h in [0, 1)) per gauge.
    stations : (S,) positions, m. outside : :class:`OutsideBasis` (its gauge rows in the order of ``gauges``).
    exponents : Wöhler exponents (> 0). n_eq : equivalent cycles of the whole span (> 0); a part has its share.
    coverage : nominal two-sided coverage in (0, 1). windows : parts of the span per gauge (≥ 1).

    Returns
    -------
    (one DelBand per station, or None without a gauge that has cycles; per gauge its discrepancies).

    Raises
    ------
    ValueError : shapes that disagree with the gauges or stations, a leverage outside [0, 1), a
    non-finite sample, a coverage outside (0, 1).

    Examples
    --------
    One gauge reading 1.1 times the virtual strain, no mode above the basis (K = 0): the residual
    is the floor everywhere, q = 0.1 at a station whose virtual strain is as large; one gauge is
    too few scores for 90 % (coverage 1/2), κ̂ is its κ = ln 1.1/0.1: ln(1 + a) = ln 1.1, a = 0.1.

    >>> m = np.sin(np.linspace(0.0, 60.0, 3000))
    >>> o = OutsideBasis(np.zeros((1, 0)), np.zeros((1, 0)), np.array([np.sqrt(np.mean((m / 1.1) ** 2))]))
    >>> bands, _ = outside_basis_bands([("g1", 1.0, m / 1.1, m, 0.0)], [2.0], o, exponents=(3.0,), n_eq=10.0, windows=1)
    >>> round(bands[0].high, 3)
    1.1
    """
    from scipy.optimize import nnls

    if not 0.0 < coverage < 1.0:
        raise ValueError(f"{coverage=} must be in (0, 1)")
    if isinstance(windows, bool) or not isinstance(windows, int) or windows < 1:
        raise ValueError(f"{windows=} must be an integer >= 1")
    eta = as_signal("stations", stations, min_len=1, ndim=(1,))
    phi_g = np.asarray(outside.gauge_shapes, dtype=float)
    phi_s = np.asarray(outside.station_shapes, dtype=float)
    rms_s = np.asarray(outside.station_rms, dtype=float).reshape(-1)
    if (phi_g.ndim != 2 or phi_s.ndim != 2 or phi_g.shape[0] != len(gauges) or phi_s.shape[0] != eta.size
            or phi_g.shape[1] != phi_s.shape[1] or rms_s.size != eta.size):
        raise ValueError(f"outside: gauge shapes {phi_g.shape}, station shapes {phi_s.shape} and station RMS {rms_s.shape} "
                         f"disagree with {len(gauges)} gauges and {eta.size} stations")
    if not (np.all(np.isfinite(phi_g)) and np.all(np.isfinite(phi_s)) and np.all(np.isfinite(rms_s)) and np.all(rms_s >= 0)):
        raise ValueError("outside: shapes and station RMS must be finite (RMS >= 0)")
    rows, used = [], []
    for k, (name, position, virtual, measured, leverage) in enumerate(gauges):
        h, m, loo = _held_out_strain(name, virtual, measured, leverage)
        e = m - loo
        rms_v = float(np.sqrt(np.mean(loo**2)))
        rms_e = float(np.sqrt(np.mean(e**2)))
        whole = _log_factor(m, loo, exponents, n_eq, half_cycles, name)
        parts = [whole]
        if windows > 1:
            for sel in np.array_split(np.arange(m.size), windows):
                if sel.size >= 4:
                    parts.append(_log_factor(m[sel], loo[sel], exponents, n_eq * sel.size / m.size, half_cycles, name))
        found = [p for p in parts if p is not None]
        q = rms_e / rms_v if rms_v > 0 else np.inf
        score = None if not found or not np.isfinite(q) or q == 0 else max(found) / q
        rows.append({"name": name, "position_m": float(position), "leverage": h, "out_of_sample": h == 0.0,
                     "half_width": None if whole is None else float(np.expm1(whole)),
                     "strain_rms_discrepancy": rms_e / max(float(np.sqrt(np.mean(m**2))), 1e-300),
                     "relative_residual": None if not np.isfinite(q) else q, "score": score})
        if whole is not None:
            used.append((k, float(position), rms_e**2, whole, score))
    if not used:
        return None, rows
    # 1. the residual's variance along the beam: floor plus the modes above the basis (NNLS)
    idx = [k for k, *_ in used]
    A = np.column_stack([np.ones(len(idx)), phi_g[idx] ** 2])
    y = np.array([var for _, _, var, _, _ in used])
    scale = float(np.max(A)) or 1.0
    lam, _res = nnls(A / scale, y / scale) if y.max() > 0 else (np.zeros(A.shape[1]), 0.0)
    var_s = lam[0] + (phi_s**2) @ lam[1:]
    # 2. κ̂: the conformal quantile of the gauges' scores (each gauge's largest over its parts)
    scores = np.array([s for *_, s in used if s is not None])
    kappa = _conformal_max(scores, coverage) if scores.size else 0.0
    order = sorted(used, key=lambda u: u[1])
    pos_g = np.array([p for _, p, *_ in order])
    log_g = np.array([w for _, _, _, w, _ in order])
    bands = []
    names = ", ".join(f"{gauges[k][0]} {p:g} m" for k, p, *_ in used)
    for j, x in enumerate(eta):
        q = float(np.sqrt(var_s[j]) / rms_s[j]) if rms_s[j] > 0 else (0.0 if var_s[j] == 0 else np.inf)
        log_a = kappa * q
        log_a = max(log_a, _bracketing(pos_g, log_g, float(x)))
        a = max(BAND_FLOOR, float(np.expm1(log_a)) if np.isfinite(log_a) else np.inf)
        method = (f"calibrated on the gauges' cross-validated residuals ({names}): missing strain along the beam "
                  f"from {phi_s.shape[1]} modes above the basis and a floor fitted to the gauges' residual variances; "
                  f"q = its RMS over the station's virtual strain RMS = {q:.4f}; log-DEL error per unit q, the "
                  f"{coverage:.0%} conformal quantile over the gauges" + (f" (each its worst of {windows} parts and the whole)" if windows > 1 else "") + " "
                  f"kappa = {kappa:.4f}; ln(1+a) = kappa*q, at least the bracketing gauges' own, at least {BAND_FLOOR:.0%}: a = {a:.4f}")
        bands.append(DelBand(1.0 / (1.0 + a), 1.0 + a, method))
    return bands, rows


def _bracketing(positions: np.ndarray, logs: np.ndarray, x: float) -> float:
    """The gauges' own |ln ρ| a station at ``x`` takes at least: at a gauge its own, between two the
    larger of the two, beyond the outermost the largest of all (what the gauges saw there)."""
    at = np.abs(positions - x) <= 1e-9
    if at.any():
        return float(logs[at].max())
    if positions[0] < x < positions[-1]:
        k = int(np.searchsorted(positions, x))
        return float(max(logs[k - 1], logs[k]))
    return float(logs.max())


def _log_factor(measured: np.ndarray, virtual: np.ndarray, exponents: tuple[float, ...], n_eq: float,
                half_cycles: HalfCyclePolicy, name: str) -> float | None:
    """max over the exponents of |ln(DEL(measured)/DEL(virtual))|, or None without cycles."""
    g = signal_loads(measured, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"strain gauge {name}")
    w = signal_loads(virtual, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"virtual strain at {name}")
    logs = [abs(math.log(dg / dv)) if dv > 0 else math.inf for (_, _, dg), (_, _, dv) in zip(g.dels, w.dels) if dg > 0]
    return max(logs) if logs else None


@dataclass(frozen=True)
class SignalLoads:
    """Loads of one signal over its counted span.

    rms, range_max : of the signal (its unit). dels : ((m, n_eq, DEL), ...). cycles : Cycles.
    damage : Miner's D of the scaled signal (None without a detail). damage_band : (low, high) D with the
    ranges scaled by the band's ends (None without a band or detail).
    """

    rms: float
    range_max: float
    dels: tuple[tuple[float, float, float], ...]
    cycles: Cycles
    damage: float | None
    damage_band: tuple[float, float] | None

    def cycles_by_range(self) -> tuple[list[list[float]], float | None]:
        return cycles_by_range(self.cycles)


def signal_loads(x: object, *, exponents: tuple[float, ...] = (3.0, 5.0), n_eq: float, half_cycles: HalfCyclePolicy = "half",
                 detail: FatigueDetail | None = None, to_stress: float = 1.0, band: DelBand | None = None,
                 name: str = "signal") -> SignalLoads:
    """Rainflow count of a whole signal (ASTM E1049-85), its DELs and Miner damage.

    Parameters
    ----------
    x : (N,) finite signal (strain m/m or stress Pa). exponents : Wöhler exponents (> 0).
    n_eq : equivalent cycles of the DELs (> 0). detail : S–N curve and factors for the damage;
    ``to_stress`` converts the signal's ranges to stress ranges (Pa) for it (E for strain, 1 for stress).
    band : relative DEL band; the damage band is the damage with ranges scaled by its ends.

    Raises
    ------
    ValueError : a non-finite sample (named), a non-positive exponent or n_eq.
    """
    _half_weight(half_cycles)
    v = _finite_samples(name, x)  # names the first non-finite sample
    if v.size == 0:
        raise ValueError(f"{name} has no samples")
    cycles = rainflow_cycles(v, half_cycles=half_cycles)
    dels = tuple((float(m), float(n_eq), damage_equivalent_range(cycles.ranges, cycles.counts, m, n_eq)) for m in exponents)
    damage = damage_band = None
    if detail is not None:
        stress = cycles.scaled(to_stress)
        damage = detail.damage(stress)
        if band is not None:
            damage_band = (detail.damage(stress, band.low), detail.damage(stress, band.high))
    return SignalLoads(float(np.sqrt(np.mean(v**2))), float(np.ptp(v)), dels, cycles, damage, damage_band)


class VirtualLoads:
    """Virtual strain, stress and bending moment at stations along the beam, per estimate sample.

    ε(η, t) = −c(η) κ(η, t), κ = Σ b s''(η); σ = E(T) ε (None for a beam of table sections,
    which has no E); M = EI(η, T) κ; for a clamped support also the root bending moment
    M(0) = EI(0, T) κ(0). Built once per model (:meth:`from_rig`), applied per batch (``__call__``).

    Parameters
    ----------
    positions : (S,) stations, m. names : (S,) a hot spot's name or "" for a grid station.
    curvature_shapes : (S, Γ) s'' at the stations (1/m per unit b). fibre_distance : (S,) c, m.
    beam : contract.Beam (E(T), EI(η, T)). root_shape : (Γ,) s'' at η = 0 for a clamped support, or None.
    """

    def __init__(self, positions: object, names: list[str], curvature_shapes: object, fibre_distance: object, beam: Any,
                 root_shape: object | None = None) -> None:
        self.positions = as_signal("positions", positions, min_len=1, ndim=(1,))
        self.names = list(names)
        self.shapes = as_signal("curvature_shapes", curvature_shapes, min_len=1, ndim=(2,))
        self.fibre = as_signal("fibre_distance", fibre_distance, min_len=1, ndim=(1,))
        if not (len(self.names) == self.positions.size == self.shapes.shape[0] == self.fibre.size):
            raise ValueError(f"{len(self.names)} names, {self.positions.size} positions, {self.shapes.shape[0]} curvature shapes "
                             f"and {self.fibre.size} fibre distances must agree")
        if np.any(self.fibre <= 0):
            raise ValueError("fibre_distance must be > 0")
        self.beam = beam
        self.root_shape = None if root_shape is None else np.asarray(root_shape, dtype=float).reshape(-1)

    @classmethod
    def from_rig(cls, rig: Any, curvature_at: Callable[[np.ndarray], Any], *, grid: int | tuple[float, ...] = 16) -> "VirtualLoads":
        """The rig's hot spots and a grid (``grid`` evenly spaced stations from the support, the free end
        left out, or the positions given); ``curvature_at(η)`` gives s'' (len(η), Γ)."""
        beam = rig.beam
        if isinstance(grid, int):
            if grid < 0:
                raise ValueError(f"{grid=} must be >= 0")
            points = np.linspace(0.0, beam.length, grid + 1)[:-1]
        else:
            points = np.asarray(grid, dtype=float)
            bad = points[(points < 0) | (points > beam.length) | ~np.isfinite(points)]
            if bad.size:
                raise ValueError(f"station {bad[0]} m is outside the beam [0, {beam.length}] m")
        spots = list(rig.hot_spots)
        positions = np.concatenate([[h.position for h in spots], points])
        names: list[str] = [str(h.name) for h in spots] + [""] * points.size
        if positions.size == 0:
            raise ValueError("no stations: the rig names no hot spot and the grid is empty")
        shapes = np.asarray(curvature_at(positions), dtype=float)
        root = np.asarray(curvature_at(np.array([0.0])), dtype=float)[0] if rig.support == "clamped" else None
        return cls(positions, names, shapes, np.asarray(beam.fibre_distance(positions), dtype=float), beam, root)

    def __call__(self, b: object, temperature_c: float | None = None) -> dict[str, np.ndarray | None]:
        """{"strain": (N, S) m/m, "stress_pa": (N, S) or None, "moment_nm": (N, S), "root_moment_nm": (N,) or None} of b (N, Γ)."""
        B = as_signal("b", b, min_len=1, ndim=(2,))
        if B.shape[1] != self.shapes.shape[1]:
            raise ValueError(f"b has {B.shape[1]} unit deformations, the stations' shapes {self.shapes.shape[1]}")
        kappa = B @ self.shapes.T
        strain = -kappa * self.fibre
        stress = None
        if getattr(self.beam, "youngs_modulus", None) is not None:
            stress = strain * self.beam.youngs_modulus_at(temperature_c)
        ei = np.asarray(self.beam.bending_stiffness(self.positions, temperature_c), dtype=float)
        root = None
        if self.root_shape is not None:
            root = (B @ self.root_shape) * float(self.beam.bending_stiffness(0.0, temperature_c))
        return {"strain": strain, "stress_pa": stress, "moment_nm": kappa * ei, "root_moment_nm": root}
