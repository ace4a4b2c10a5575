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

from ._fatigue import FatigueDetail
from ._rainflow import Cycles, HalfCyclePolicy, _finite_samples, _half_weight, cycles_by_range, rainflow_cycles
from ._sn_curves import damage_equivalent_range
from ._validate import as_signal

__all__ = ["BAND_FLOOR", "IN_SAMPLE_FACTOR", "DelBand", "SignalLoads", "VirtualLoads", "bending_moment", "signal_loads", "truncation_band", "virtual_strain"]


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
#: The gauges pulled the estimate towards themselves: their in-sample discrepancy is scaled by this.
IN_SAMPLE_FACTOR = 2.0


def truncation_band(gauges: list[tuple[str, float, np.ndarray, np.ndarray]], *, exponents: tuple[float, ...], n_eq: float,
                    in_sample: tuple[str, ...], half_cycles: HalfCyclePolicy = "half") -> tuple[DelBand | None, list[dict]]:
    """The DEL band of virtual stations: the modal truncation seen at the strain gauges.

    At each gauge the DEL of the virtual strain (from b) is compared with the DEL of the measured
    strain; the largest relative discrepancy over the gauges and exponents, times ``IN_SAMPLE_FACTOR``
    at a gauge that aided the estimate (the estimate was pulled towards it, so its discrepancy
    understates the one between gauges), at least ``BAND_FLOOR``, is the half-width a of the band
    [DEL/(1 + a), DEL·(1 + a)].

    Parameters
    ----------
    gauges : (name, position m, virtual strain (n,), measured strain (n,)) per gauge.
    exponents : Wöhler exponents. n_eq : equivalent cycles. in_sample : the gauges that aided the estimate.

    Returns
    -------
    (DelBand, or None without gauges; per gauge its discrepancies).
    """
    if not gauges:
        return None, []
    worst, rows = 0.0, []
    for name, position, virtual, measured in gauges:
        v = signal_loads(virtual, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"virtual strain at {name}")
        g = signal_loads(measured, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"strain gauge {name}")
        rel = {m: (dv / dg - 1.0) if dg > 0 else 0.0 for (m, _, dv), (_, _, dg) in zip(v.dels, g.dels)}
        rms = float(np.sqrt(np.mean((np.asarray(virtual) - np.asarray(measured)) ** 2)) / max(g.rms, 1e-300))
        aided = name in in_sample
        rows.append({"name": name, "position_m": position, "aided_the_estimate": aided,
                     "del_discrepancy": [{"m": m, "relative": r} for m, r in rel.items()], "strain_rms_discrepancy": rms})
        worst = max(worst, (IN_SAMPLE_FACTOR if aided else 1.0) * max(abs(r) for r in rel.values()))
    a = max(BAND_FLOOR, worst)
    method = (f"modal truncation seen at the strain gauges ({', '.join(str(g[0]) for g in gauges)}): largest relative DEL "
              f"discrepancy of the virtual against the measured strain, x{IN_SAMPLE_FACTOR:g} at a gauge that aided the estimate, "
              f"at least {BAND_FLOOR:.0%}; band [DEL/(1+a), DEL*(1+a)] with a = {a:.4f}")
    return DelBand(1.0 / (1.0 + a), 1.0 + a, method), rows


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
