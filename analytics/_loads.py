"""Virtual strain, stress and bending moment along the beam from the deformation variables, and the
loads summary of one signal (rainflow, DELs, Miner damage) — the paper's Section 6 outlook.

ε(η, t) = −c(η)·κ(η, t) with κ = Σ_χ b_χ s''_χ(η) (the contract's sign: the +ζ face), σ = E(T)·ε,
M = EI(η, T)·κ. Pure numerics: arrays in, arrays and frozen results out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from ._fatigue import FatigueDetail
from ._rainflow import Cycles, HalfCyclePolicy, _finite_samples, _half_weight, cycles_by_range, rainflow_cycles
from ._sn_curves import damage_equivalent_range
from ._validate import as_signal

__all__ = ["BAND_FLOOR", "UNKNOWN_LEVERAGE", "DelBand", "SignalLoads", "VirtualLoads", "bending_moment", "gauge_bands", "signal_loads", "virtual_strain"]


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
    >>> bands, _ = gauge_bands([("g1", 1.0, m / 1.1, m, 0.0)], [0.5], exponents=(3.0,), n_eq=10.0)
    >>> round(bands[0].high, 6)
    1.1
    """
    eta = as_signal("stations", stations, min_len=1, ndim=(1,))
    rows, found = [], []
    for name, position, virtual, measured, leverage in gauges:
        h = float(leverage)
        if not 0.0 <= h < 1.0:
            raise ValueError(f"leverage of gauge {name} must be in [0, 1), got {leverage}")
        m = _finite_samples(f"strain gauge {name}", measured)
        v = _finite_samples(f"virtual strain at {name}", virtual)
        if m.size != v.size or m.size == 0:
            raise ValueError(f"gauge {name}: virtual strain has {v.size} samples, measured {m.size} (must agree, > 0)")
        loo = m - (m - v) / (1.0 - h)
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
