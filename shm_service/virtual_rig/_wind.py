"""The ambient (wind) load of the virtual rig scaled to the structure, and the section figures
it needs from any rig description.

A random distributed load p(η, t) (N/m) acts along the beam (:class:`DistributedLoad`). For the
built-in laboratory sheet its level is the operational settings' ``load_rms``; for a rig given
as a file (``shm simulate --rig``) a fixed level in N/m would be a breeze for a 20 m mast and a
storm for a 35 cm cantilever, so unless the user sets it (``wind_load_rms``, N/m RMS) the level
is scaled to the structure: the load whose quasi-static bending strain at the support has the RMS
``wind_base_strain`` (default 50 µε, 10.5 MPa on steel; the resonant response adds to it, so the
peaks at a mast's base reach tens of MPa). With a spatial correlation (exponential kernel of
length λ) the support moment of a load of RMS σ is M(0) = ∫₀ᴸ p(η) η dη with variance
σ² ∫∫ η ξ e^{−|η−ξ|/λ} dη dξ, and the strain there is M(0) c(0) / EI(0): pure statics, valid for
any section (the beam model's own EI and fibre distance, not a uniform sheet's).
"""

from __future__ import annotations

import math

import numpy as np

from estimator import RigDescription

__all__ = ["DEFAULT_WIND_BASE_STRAIN", "bending_stiffness_at", "fibre_distance_at", "scaled_wind_load",
           "storm_factor", "support_moment_factor"]

#: Quasi-static RMS bending strain at the support that the scaled wind load gives (50 µε): a strong
#: wind, enough signal for any rig file's modal identification. It is not a structure's everyday
#: wind: with the resonant response (about 2.7 times on the 20 m mast) it is ~130 µε RMS, 28 MPa on
#: steel, at which a welded base would use its 20-year fatigue life in days. A rig file that stands
#: for a real structure states its everyday wind in its ``simulator`` key (``wind_base_strain``),
#: as examples/mast does: a mast's section is sized by its design (50-year) storm, whose peak base
#: stress is about f_y/(γ_M γ_F) ≈ 240 MPa; the everyday mean wind is about a quarter of the design
#: speed, so its load (∝ V²) is ~1/16 of the design load and its gusts' quasi-static part a few µε
#: (5 µε = 1 MPa; ~3 MPa RMS with resonance), which uses the life at or below the design rate.
DEFAULT_WIND_BASE_STRAIN = 5e-5


def fibre_distance_at(rig: RigDescription, positions: np.ndarray | list[float]) -> np.ndarray:
    """c(η) (m) at ``positions``, from the rig description's sections (or its uniform sheet)."""
    positions = np.asarray(positions, dtype=float)
    return np.asarray(rig.beam.fibre_distance(positions), dtype=float).reshape(positions.shape)


def bending_stiffness_at(rig: RigDescription, positions: np.ndarray | list[float]) -> np.ndarray:
    """EI(η) (N·m²) at ``positions`` at the reference temperature, from the rig description."""
    positions = np.asarray(positions, dtype=float)
    return np.asarray(rig.beam.bending_stiffness(positions), dtype=float).reshape(positions.shape)


def support_moment_factor(length_m: float, correlation_m: float, points: int = 801) -> float:
    """sqrt(∫₀ᴸ∫₀ᴸ η ξ e^{−|η−ξ|/λ} dη dξ) (m²): the RMS moment at the support per N/m RMS of a
    load with correlation length λ (L²/2 for λ → ∞).

    Examples
    --------
    >>> round(support_moment_factor(2.0, 1e9), 6)
    2.0
    """
    if not (math.isfinite(length_m) and length_m > 0 and correlation_m > 0):
        raise ValueError(f"{length_m=} and {correlation_m=} must be positive")
    x = np.linspace(0.0, length_m, points)
    w = np.full(points, x[1] - x[0])
    w[[0, -1]] *= 0.5
    kernel = np.exp(-np.abs(x[:, None] - x[None, :]) / correlation_m)
    value = (w * x) @ kernel @ (w * x)
    return float(math.sqrt(max(value, 0.0)))


def scaled_wind_load(rig: RigDescription, correlation_m: float, base_strain: float = DEFAULT_WIND_BASE_STRAIN) -> float:
    """The RMS load per metre (N/m) whose quasi-static RMS bending strain at the support is
    ``base_strain``, for a load of correlation length ``correlation_m`` (m) on ``rig``'s beam.

    Raises
    ------
    ValueError
        For a non-positive strain or correlation length, or a section without stiffness at D.
    """
    if not base_strain > 0:
        raise ValueError(f"{base_strain=} must be positive")
    c0 = float(fibre_distance_at(rig, [0.0])[0])
    ei0 = float(bending_stiffness_at(rig, [0.0])[0])
    if not (c0 > 0 and ei0 > 0):
        raise ValueError(f"the section at the support has fibre distance {c0} m and EI {ei0} N·m²: both must be positive")
    return base_strain * ei0 / (c0 * support_moment_factor(rig.beam.length, correlation_m))


def storm_factor(t: np.ndarray | list[float], start_s: float, end_s: float, peak: float) -> np.ndarray:
    """The wind load's RMS relative to its ambient level while a storm passes: 1 before ``start_s``
    and after ``end_s`` (s), rising smoothly to ``peak`` halfway and falling back,
    1 + (peak − 1) sin²(π (t − start)/(end − start)) (continuous with its slope at both ends, so the
    load has no step a real storm front would not have).

    Parameters
    ----------
    t : array_like
        Times, s.
    start_s, end_s : float
        When the storm begins and has passed, s (start < end).
    peak : float
        The load's RMS at the storm's peak over its ambient RMS (> 0; the load goes with the wind
        speed squared, so 4 is twice the wind speed).

    Returns
    -------
    numpy.ndarray
        The factor at ``t`` (same shape).

    Raises
    ------
    ValueError
        For start ≥ end or a non-positive or non-finite peak.

    Examples
    --------
    >>> np.round(storm_factor([0.0, 150.0, 200.0, 250.0, 400.0], 100.0, 300.0, 3.0), 12).tolist()
    [1.0, 2.0, 3.0, 2.0, 1.0]
    """
    if not (math.isfinite(start_s) and math.isfinite(end_s) and start_s < end_s):
        raise ValueError(f"the storm's start_s={start_s} must come before its end_s={end_s}")
    if not (math.isfinite(peak) and peak > 0):
        raise ValueError(f"the storm's peak={peak} must be a positive factor")
    t = np.asarray(t, dtype=float)
    phase = np.clip((t - start_s) / (end_s - start_s), 0.0, 1.0)
    return 1.0 + (peak - 1.0) * np.sin(np.pi * phase) ** 2
