"""S–N (Wöhler) curves for welded and plain steel details: EN 1993-1-9, DNV-RP-C203, user curves.

Every curve is a piecewise power law N = K·Δσ^(−m) over stress-range intervals, with a cut-off
below which a range consumes nothing. Stress ranges are in Pa here (the tables are in MPa).

* EN 1993-1-9 (Fig. 7.1), normal stress: Δσ_C at N_C = 2·10⁶, m = 3 down to the constant-amplitude
  fatigue limit Δσ_D = (2/5)^(1/3)·Δσ_C at 5·10⁶, m = 5 down to the cut-off Δσ_L = (5/100)^(1/5)·Δσ_D
  at 10⁸, nothing below. Shear (Fig. 7.2): Δτ_C at 2·10⁶, m = 5 to the cut-off at 10⁸.
  The asterisk of 36* marks details that may be upgraded one class with Δσ_D at 10⁷; the curve of
  "36*" here is the basic 36 curve (give an upgraded curve as points if you use the option).
* DNV-RP-C203 (2016, Tables 2-1 and 2-2): log N = log ā₁ − m₁ log Δσ for N ≤ 10⁷ (air) or
  N ≤ 10⁶ (seawater with cathodic protection), log N = log ā₂ − m₂ log Δσ beyond, Δσ in MPa; the
  table's values as printed (B1, B2 have m₁ = 4). No cut-off for variable amplitude. The thickness
  effect (t/t_ref)^k is not applied: fold it into the hot spot's SCF.
* User curves: points (N, Δσ in Pa), N increasing, Δσ decreasing, interpolated log–log; ranges above
  the first point follow the first segment's slope, below the last point nothing is consumed.

Partial factors: the design range is γ_Ff·SCF·Δσ against the curve divided by γ_Mf; for a power
law that is the curve at γ_Ff·γ_Mf·SCF·Δσ, which is what :func:`miner_damage` evaluates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from contract import DNV_RP_C203_CURVE_NAMES, EN1993_DETAIL_CATEGORIES, EN1993_SHEAR_CATEGORIES, check_curve_spec

__all__ = ["DNV_RP_C203_CURVES", "DNV_RP_C203_CURVE_NAMES", "EN1993_DETAIL_CATEGORIES", "EN1993_SHEAR_CATEGORIES", "SnCurve", "damage_equivalent_range", "miner_damage", "sn_curve"]

_MPA = 1e6


#: DNV-RP-C203 (2016) Table 2-1 (air): curve → (m₁, log ā₁ for N ≤ 10⁷, m₂, log ā₂ for N > 10⁷).
_DNV_AIR = {
    "B1": (4.0, 15.117, 5.0, 17.146), "B2": (4.0, 14.885, 5.0, 16.856),
    "C": (3.0, 12.592, 5.0, 16.320), "C1": (3.0, 12.449, 5.0, 16.081), "C2": (3.0, 12.301, 5.0, 15.835),
    "D": (3.0, 12.164, 5.0, 15.606), "E": (3.0, 12.010, 5.0, 15.350), "F": (3.0, 11.855, 5.0, 15.091),
    "F1": (3.0, 11.699, 5.0, 14.832), "F3": (3.0, 11.546, 5.0, 14.576), "G": (3.0, 11.398, 5.0, 14.330),
    "W1": (3.0, 11.261, 5.0, 14.101), "W2": (3.0, 11.107, 5.0, 13.845), "W3": (3.0, 10.970, 5.0, 13.617),
}
#: DNV-RP-C203 (2016) Table 2-2 (seawater, cathodic protection): (m₁, log ā₁ for N ≤ 10⁶, m₂, log ā₂ for N > 10⁶).
_DNV_SEAWATER_CP = {
    "B1": (4.0, 14.917, 5.0, 17.146), "B2": (4.0, 14.685, 5.0, 16.856),
    "C": (3.0, 12.192, 5.0, 16.320), "C1": (3.0, 12.049, 5.0, 16.081), "C2": (3.0, 11.901, 5.0, 15.835),
    "D": (3.0, 11.764, 5.0, 15.606), "E": (3.0, 11.610, 5.0, 15.350), "F": (3.0, 11.455, 5.0, 15.091),
    "F1": (3.0, 11.299, 5.0, 14.832), "F3": (3.0, 11.146, 5.0, 14.576), "G": (3.0, 10.998, 5.0, 14.330),
    "W1": (3.0, 10.861, 5.0, 14.101), "W2": (3.0, 10.707, 5.0, 13.845), "W3": (3.0, 10.570, 5.0, 13.617),
}
DNV_RP_C203_CURVES = {"air": (_DNV_AIR, 1e7), "seawater-cp": (_DNV_SEAWATER_CP, 1e6)}



@dataclass(frozen=True)
class SnCurve:
    """A piecewise power-law S–N curve.

    knees_pa : (k,) stress ranges (Pa), descending, where the slope changes; slopes : (k+1,) m of the
    segments from the highest ranges down; log10_k : (k+1,) log₁₀ K of N = K·Δσ^(−m) (Δσ in Pa);
    cutoff_pa : below it N = ∞ (0: none). name : as given in the rig description.
    """

    name: str
    knees_pa: tuple[float, ...]
    slopes: tuple[float, ...]
    log10_k: tuple[float, ...]
    cutoff_pa: float = 0.0

    def cycles_to_failure(self, stress_range_pa: object) -> np.ndarray:
        """N(Δσ) (cycles) for ranges in Pa; ∞ below the cut-off and for a zero range."""
        s = np.atleast_1d(np.asarray(stress_range_pa, dtype=float))
        if not np.all(np.isfinite(s)) or np.any(s < 0):
            raise ValueError(f"stress ranges must be finite and >= 0, got {s[~(np.isfinite(s) & (s >= 0))][:3].tolist()}")
        # segment index: 0 above the first knee, i above the i-th knee's lower side
        seg = np.searchsorted(-np.asarray(self.knees_pa, dtype=float), -s, side="left") if self.knees_pa else np.zeros(s.size, int)
        m = np.asarray(self.slopes)[seg]
        logk = np.asarray(self.log10_k)[seg]
        with np.errstate(divide="ignore"):
            n = 10.0 ** (logk - m * np.log10(s))
        n[(s < self.cutoff_pa) | (s == 0)] = np.inf
        return n

    def stress_range_at(self, cycles: float) -> float:
        """Δσ (Pa) with N(Δσ) = cycles on the curve (ignoring the cut-off)."""
        if not cycles > 0:
            raise ValueError(f"{cycles=} must be > 0")
        for i, (m, logk) in enumerate(zip(self.slopes, self.log10_k)):
            s = 10.0 ** ((logk - math.log10(cycles)) / m)
            if i == len(self.knees_pa) or s >= self.knees_pa[i] * (1 - 1e-12):
                return s
        raise AssertionError("unreachable")

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "knees_pa": list(self.knees_pa), "slopes": list(self.slopes),
                "log10_k": list(self.log10_k), "cutoff_pa": self.cutoff_pa}


def _en1993(category: float, name: str, *, shear: bool) -> SnCurve:
    c = category * _MPA
    if shear:
        cutoff = c * (2e6 / 1e8) ** (1 / 5)
        return SnCurve(name, (), (5.0,), (math.log10(2e6) + 5 * math.log10(c),), cutoff)
    d = c * (2.0 / 5.0) ** (1 / 3)
    cutoff = d * (5.0 / 100.0) ** (1 / 5)
    return SnCurve(name, (d,), (3.0, 5.0), (math.log10(2e6) + 3 * math.log10(c), math.log10(5e6) + 5 * math.log10(d)), cutoff)


def _dnv(row: tuple[float, float, float, float], n_knee: float, name: str) -> SnCurve:
    m1, loga1, m2, loga2 = row
    # log ā with Δσ in MPa → K with Δσ in Pa: log K = log ā + m·6.
    knee = 10.0 ** ((loga1 - math.log10(n_knee)) / m1) * _MPA
    return SnCurve(name, (knee,), (m1, m2), (loga1 + 6 * m1, loga2 + 6 * m2), 0.0)


def _user(points: object, name: str) -> SnCurve:
    check_curve_spec({"points": points})  # the contract's rules for a user curve, defined once
    p = np.asarray(points, dtype=float)
    n, s = p[:, 0], p[:, 1]
    slopes = -np.diff(np.log10(n)) / np.diff(np.log10(s))
    logk = np.log10(n[:-1]) + slopes * np.log10(s[:-1])
    return SnCurve(name, tuple(float(v) for v in s[1:-1]), tuple(float(v) for v in slopes), tuple(float(v) for v in logk),
                   float(s[-1]))


def sn_curve(spec: str | dict[str, Any]) -> SnCurve:
    """The S–N curve named in a rig description's hot spot.

    Parameters
    ----------
    spec : "EN1993-1-9:<Δσ_C MPa>" (e.g. "EN1993-1-9:71", "EN1993-1-9:36*"), "EN1993-1-9:shear:<Δτ_C>",
        "DNV-RP-C203:<B1…W3>:air" or "DNV-RP-C203:<B1…W3>:seawater-cp", or ``{"points": [[N, Δσ_Pa], ...]}``.

    Raises
    ------
    ValueError : an unknown standard, category or environment, or bad points; the message names the value.

    Examples
    --------
    >>> c = sn_curve("EN1993-1-9:71")
    >>> round(float(c.cycles_to_failure(71e6)[0]))
    2000000
    """
    check_curve_spec(spec)  # the contract's catalogue: one set of names for rig.json and here
    if isinstance(spec, dict):
        return _user(spec["points"], "user")
    parts = spec.split(":")
    if parts[0] == "EN1993-1-9":
        shear = parts[1] == "shear"
        return _en1993(float(parts[-1].rstrip("*")), spec, shear=shear)
    if parts[0] == "DNV-RP-C203":
        table, n_knee = DNV_RP_C203_CURVES[parts[2]]
        return _dnv(table[parts[1]], n_knee, spec)
    raise AssertionError(f"check_curve_spec passed {spec!r}")


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value!r} must be a finite number > 0")
    return float(value)


def miner_damage(ranges_pa: object, counts: object, curve: SnCurve, *, scf: float = 1.0, gamma_ff: float = 1.0,
                 gamma_mf: float = 1.0) -> float:
    """Palmgren–Miner damage D = Σ nᵢ / N(γ_Ff·γ_Mf·SCF·Δσᵢ) (dimensionless).

    Parameters
    ----------
    ranges_pa : (K,) nominal stress ranges (Pa) at the hot spot; counts : (K,) cycles (half cycles 0.5).
    curve : the detail's S–N curve; scf, gamma_ff, gamma_mf : > 0.

    Raises
    ------
    ValueError : shapes that disagree, negative counts, non-positive factors (named).
    """
    r = np.asarray(ranges_pa, dtype=float).ravel()
    n = np.asarray(counts, dtype=float).ravel()
    if r.shape != n.shape:
        raise ValueError(f"ranges_pa {r.shape} and counts {n.shape} disagree")
    if not np.all(np.isfinite(n)) or np.any(n < 0):
        raise ValueError("counts must be finite and >= 0")
    factor = _positive("scf", scf) * _positive("gamma_Ff", gamma_ff) * _positive("gamma_Mf", gamma_mf)
    if r.size == 0:
        return 0.0
    return float(np.sum(n / curve.cycles_to_failure(r * factor)))


def damage_equivalent_range(ranges: object, counts: object, m: float, n_eq: float) -> float:
    """DEL_m = (Σ nᵢ Sᵢ^m / N_eq)^(1/m), in the ranges' unit.

    Parameters
    ----------
    ranges : (K,) ranges; counts : (K,) cycles; m : Wöhler exponent > 0; n_eq : equivalent cycles > 0
    (1 Hz equivalent: the counted duration in s).

    Examples
    --------
    >>> damage_equivalent_range([2.0], [1.0], 3, 8.0)
    1.0
    """
    m = _positive("m", m)
    n_eq = _positive("n_eq", n_eq)
    r = np.asarray(ranges, dtype=float).ravel()
    n = np.asarray(counts, dtype=float).ravel()
    if r.shape != n.shape:
        raise ValueError(f"ranges {r.shape} and counts {n.shape} disagree")
    if r.size == 0:
        return 0.0
    return float((np.sum(n * np.abs(r) ** m) / n_eq) ** (1.0 / m))
