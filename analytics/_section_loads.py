"""Loads around the section of a beam that bends in two planes: the strain at any point of the
outline from both planes' curvature, the worst point around a girth weld, the resultant bending
moment (recording-format.md, "Bending in two planes").

A point of the section at (ζp, ξp) (m, from ``contract.Beam.section_point``) strains by
ε = −(ζp·κζ + ξp·κξ); the bending moments are Mζ = EIζ·κζ and Mξ = EIξ·κξ, and their resultant
|M| = √(Mζ² + Mξ²). A planar beam is the case κξ = None: ε = −ζp·κζ, as ``virtual_strain`` has it.
Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

from collections.abc import Sequence
from collections.abc import Callable
from typing import Any

import numpy as np

from ._fatigue import FatigueDetail
from ._loads import SignalLoads, VirtualLoads, signal_loads
from ._rainflow import HalfCyclePolicy
from ._validate import as_signal

__all__ = ["AROUND_STEP_DEG", "WORST_EXPONENTS", "WORST_N_EQ", "BiaxialVirtualLoads", "outline_corners", "around_angles", "resultant_moment", "section_strain", "worst_around"]

#: Step (degrees) of the angles around the section at which a hot spot of ``angle_deg = "all"`` is
#: evaluated. On a round section the strain at θ is a projection of the curvature vector,
#: ε(θ) = −R (κζ cos θ + κξ sin θ), smooth in θ, and so are its DEL and damage: the worst angle lies
#: within half a step (2.5°) of a grid angle and the DEL is stationary there, so the grid misses it
#: by a second-order amount, 1 − cos 2.5° ≈ 0.1 % of the DEL for a load in one direction (about
#: 0.5 % of the damage at m = 5), well inside the DEL bands. On a rectangle (or a table station's
#: outline) the strain is linear along each face, so its extremes sit at the corners:
#: :func:`around_angles` adds them.
AROUND_STEP_DEG = 5.0


def section_strain(kappa_zeta: object, zeta_p: object, kappa_xi: object | None = None, xi_p: object | None = None) -> np.ndarray:
    """ε = −(ζp·κζ + ξp·κξ) at points of the section (the contract's strain around the outline).

    Parameters
    ----------
    kappa_zeta : (N, S) curvature in ζ at the stations, 1/m. zeta_p : (S,) the points' ζ coordinate, m.
    kappa_xi : (N, S) curvature in ξ, 1/m, or None (a planar beam: the ξ term left out).
    xi_p : (S,) the points' ξ coordinate, m (required with ``kappa_xi``).

    Returns
    -------
    (N, S) bending strain, m/m.

    Examples
    --------
    A tube of radius 0.05 m at 45°: (ζp, ξp) = (0.05, 0.05)/√2.

    >>> p = 0.05 / np.sqrt(2.0)
    >>> (1e6 * section_strain([[1e-3]], [p], [[1e-3]], [p])).round(6).tolist()  # µε: −0.05·√2·1e-3
    [[-70.710678]]
    """
    kz = as_signal("kappa_zeta", kappa_zeta, min_len=1, ndim=(2,))
    zp = np.asarray(zeta_p, dtype=float).reshape(-1)
    if zp.size != kz.shape[1] or not np.all(np.isfinite(zp)):
        raise ValueError(f"zeta_p has {zp.size} finite points, kappa_zeta {kz.shape[1]} stations (must agree)")
    if kappa_xi is None:
        if xi_p is not None and np.any(np.asarray(xi_p, dtype=float) != 0.0):
            raise ValueError("xi_p off the ζ axis needs kappa_xi: a point off the ζ faces strains with the ξ curvature too")
        return -(zp * kz)
    kx = as_signal("kappa_xi", kappa_xi, min_len=1, ndim=(2,))
    if kx.shape != kz.shape:
        raise ValueError(f"kappa_xi has shape {kx.shape}, kappa_zeta {kz.shape} (must agree)")
    if xi_p is None:
        raise ValueError("kappa_xi needs xi_p, the points' ξ coordinates")
    xp = np.asarray(xi_p, dtype=float).reshape(-1)
    if xp.size != kz.shape[1] or not np.all(np.isfinite(xp)):
        raise ValueError(f"xi_p has {xp.size} finite points, kappa_xi {kx.shape[1]} stations (must agree)")
    return -(zp * kz + xp * kx)


def resultant_moment(moment_zeta: object, moment_xi: object) -> np.ndarray:
    """|M| = √(Mζ² + Mξ²) (N·m) of the two planes' bending moments (equal shapes).

    >>> resultant_moment([3.0, -6.0], [4.0, 8.0]).tolist()
    [5.0, 10.0]
    """
    mz = np.asarray(moment_zeta, dtype=float)
    mx = np.asarray(moment_xi, dtype=float)
    if mz.shape != mx.shape:
        raise ValueError(f"moment_zeta has shape {mz.shape}, moment_xi {mx.shape} (must agree)")
    return np.hypot(mz, mx)


def around_angles(corners: Sequence[float] = (), step_deg: float = AROUND_STEP_DEG) -> np.ndarray:
    """The angles (degrees in [0, 360)) around the section a worst point is sought at: every
    ``step_deg`` from 0, and the outline's ``corners`` (a rectangle's, where its extremes lie).

    >>> around_angles([30.0, -30.0], step_deg=90.0).tolist()
    [0.0, 30.0, 90.0, 180.0, 270.0, 330.0]
    """
    if not (np.isfinite(step_deg) and 0.0 < step_deg <= 180.0):
        raise ValueError(f"{step_deg=} must be in (0, 180] degrees")
    grid = np.arange(0.0, 360.0 - 1e-9, step_deg)
    extra = np.mod(np.asarray(corners, dtype=float).reshape(-1), 360.0)
    if not np.all(np.isfinite(extra)):
        raise ValueError(f"corners {list(corners)} must be finite degrees")
    return np.unique(np.round(np.concatenate([grid, extra]), 12))


def worst_around(strain: object, angles: object, *, exponents: tuple[float, ...], n_eq: float,
                 half_cycles: HalfCyclePolicy = "half", detail: FatigueDetail | None = None,
                 to_stress: float = 1.0) -> tuple[int, list[SignalLoads], str]:
    """The worst of the points around a section: the column of ``strain`` with the largest Miner
    damage (with a ``detail``) or else the largest DEL at the largest Wöhler exponent (the one that
    weighs the large ranges, as damage does).

    Parameters
    ----------
    strain : (N, A) strain at the A points, m/m. angles : (A,) their angles, degrees (for the messages).
    exponents, n_eq, half_cycles : as :func:`signal_loads`. detail : S–N curve and factors, or None.
    to_stress : stress per unit strain for the damage (E, Pa).

    Returns
    -------
    (index of the worst point, the loads of every point, what "worst" was judged by).

    Examples
    --------
    >>> t = np.linspace(0.0, 20.0, 2001)
    >>> s = np.sin(t)[:, None] * np.cos(np.radians([0.0, 90.0, 180.0, 270.0]) - np.radians(100.0))[None, :]
    >>> worst_around(s, [0.0, 90.0, 180.0, 270.0], exponents=(3.0,), n_eq=10.0)[0]
    1
    """
    eps = as_signal("strain", strain, min_len=1, ndim=(2,))
    theta = np.asarray(angles, dtype=float).reshape(-1)
    if theta.size != eps.shape[1] or theta.size == 0:
        raise ValueError(f"{theta.size} angles for {eps.shape[1]} points (must agree, > 0)")
    loads = [signal_loads(eps[:, k], exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, detail=detail, to_stress=to_stress,
                          name=f"strain at {theta[k]:g} degrees") for k in range(theta.size)]
    top = max(range(len(exponents)), key=lambda j: exponents[j])
    by_damage = detail is not None

    def score(k: int) -> Any:
        return loads[k].damage if by_damage else loads[k].dels[top][2]

    worst = max(range(theta.size), key=score)
    judged = "the largest Miner damage" if by_damage else f"the largest DEL at m = {exponents[top]:g}"
    return worst, loads, judged


#: Wöhler exponents and equivalent cycles by which :class:`BiaxialVirtualLoads` judges the worst
#: point around an ``"all"`` hot spot (the ranking weighs the large ranges as damage does; n_eq
#: scales every DEL alike, so it does not change the ranking).
WORST_EXPONENTS, WORST_N_EQ = (3.0, 5.0), 1.0e7


class BiaxialVirtualLoads(VirtualLoads):
    """:class:`VirtualLoads` of a beam that bends in two planes: each station at its point of the
    section (``angle_deg`` from +ζ towards +ξ, ``contract.Beam.section_point``) strains by
    ε = −(ζp·κζ + ξp·κξ); the moments per plane Mζ = EIζ κζ, Mξ = EIξ κξ and their resultant;
    a hot spot of ``angle_deg = "all"`` at its worst point around the section (:func:`worst_around`
    over :func:`around_angles`, judged by :meth:`judge` on a stretch of estimates).

    Parameters
    ----------
    positions, names, curvature_shapes, beam, root_shape : as :class:`VirtualLoads` (the ζ plane).
    curvature_shapes_xi : (S, Γξ) s''ξ at the stations. root_shape_xi : (Γξ,) s''ξ at η = 0.
    angles : (S,) each station's angle, degrees, or "all".
    """

    def __init__(self, positions: object, names: list[str], curvature_shapes: object, curvature_shapes_xi: object,
                 angles: Sequence[float | str], beam: Any, root_shape: object, root_shape_xi: object) -> None:
        super().__init__(positions, names, curvature_shapes, beam.fibre_distance(np.asarray(positions, dtype=float)), beam,
                         root_shape)
        self.shapes_xi = as_signal("curvature_shapes_xi", curvature_shapes_xi, min_len=1, ndim=(2,))
        if self.shapes_xi.shape[0] != self.positions.size:
            raise ValueError(f"curvature_shapes_xi has {self.shapes_xi.shape[0]} stations, positions {self.positions.size}")
        self.angle_specs = list(angles)
        if len(self.angle_specs) != self.positions.size:
            raise ValueError(f"{len(self.angle_specs)} angles for {self.positions.size} stations (must agree)")
        self.worst_around = np.array([a == "all" for a in self.angle_specs], dtype=bool)
        # the angle each station is evaluated at: its own, and 0 for an "all" one until judged
        self.angles_deg = np.array([0.0 if a == "all" else float(a) for a in self.angle_specs])
        self.root_shape_xi = np.asarray(root_shape_xi, dtype=float).reshape(-1)
        self._rings = {int(j): around_angles(outline_corners(beam, float(self.positions[j]))) for j in np.flatnonzero(self.worst_around)}
        self._points()

    @classmethod
    def from_rig_biaxial(cls, rig: Any, curvature_at: Callable[[np.ndarray], Any], curvature_xi_at: Callable[[np.ndarray], Any],
                         *, grid: int = 16) -> "BiaxialVirtualLoads":
        """The rig's hot spots (at their ``angle_deg``) and a grid of ``grid`` stations at 0 degrees
        (the +ζ face, as a planar beam's), from a clamped biaxial rig's s''(η) and s''ξ(η)."""
        beam = rig.beam
        if not beam.biaxial:
            raise ValueError("BiaxialVirtualLoads needs a beam with beam.bending = 'biaxial'")
        planar = VirtualLoads.from_rig(rig, curvature_at, grid=grid)
        spots = list(rig.hot_spots)
        angles: list[float | str] = [h.angle_deg if h.angle_deg == "all" else float(h.angle_deg) for h in spots]
        angles += [0.0] * (planar.positions.size - len(spots))
        xi = np.asarray(curvature_xi_at(planar.positions), dtype=float)
        root_xi = np.asarray(curvature_xi_at(np.array([0.0])), dtype=float)[0]
        return cls(planar.positions, planar.names, planar.shapes, xi, angles, beam, planar.root_shape, root_xi)

    def _points(self) -> None:
        zeta_p, xi_p = self.beam.section_point(self.positions, self.angles_deg)
        self.zeta_p, self.xi_p = np.asarray(zeta_p, dtype=float), np.asarray(xi_p, dtype=float)

    def _kappas(self, b: object, b_xi: object) -> tuple[np.ndarray, np.ndarray]:
        B = as_signal("b", b, min_len=1, ndim=(2,))
        Bx = as_signal("b_xi", b_xi, min_len=1, ndim=(2,))
        if B.shape[1] != self.shapes.shape[1] or Bx.shape != (B.shape[0], self.shapes_xi.shape[1]):
            raise ValueError(f"b has shape {B.shape} and b_xi {Bx.shape}; the stations' shapes have {self.shapes.shape[1]} "
                             f"and {self.shapes_xi.shape[1]} unit deformations")
        return B @ self.shapes.T, Bx @ self.shapes_xi.T

    def judge(self, b: object, b_xi: object) -> np.ndarray:
        """Set (and return) the angle of each "all" station to its worst point around the section
        over the estimates b (N, Γ), bξ (N, Γξ): the largest DEL at m = 5 (``WORST_EXPONENTS``)."""
        kz, kx = self._kappas(b, b_xi)
        for j, ring in self._rings.items():
            zeta_p, xi_p = self.beam.section_point(np.full(ring.size, self.positions[j]), ring)
            strain = section_strain(np.repeat(kz[:, j:j + 1], ring.size, axis=1), zeta_p,
                                    np.repeat(kx[:, j:j + 1], ring.size, axis=1), xi_p)
            self.angles_deg[j] = ring[worst_around(strain, ring, exponents=WORST_EXPONENTS, n_eq=WORST_N_EQ)[0]]
        self._points()
        return self.angles_deg.copy()

    def __call__(self, b: object, temperature_c: float | None = None, *, b_xi: object = None) -> dict[str, np.ndarray | None]:
        """:class:`VirtualLoads`' figures of b (N, Γ) and bξ (N, Γξ) at the stations' points, with
        "moment_xi_nm" (N, S), "root_moment_xi_nm" and "root_moment_resultant_nm" (N,) and
        "angles_deg" (S,): the angle each station was evaluated at (an "all" one's worst as last judged)."""
        if b_xi is None:
            raise ValueError("a biaxial beam's loads need b_xi, the ξ plane's unit deformations")
        kz, kx = self._kappas(b, b_xi)
        strain = section_strain(kz, self.zeta_p, kx, self.xi_p)
        stress = None
        if getattr(self.beam, "youngs_modulus", None) is not None:
            stress = strain * self.beam.youngs_modulus_at(temperature_c)
        ei = np.asarray(self.beam.bending_stiffness(self.positions, temperature_c), dtype=float)
        ei_xi = np.asarray(self.beam.bending_stiffness_xi(self.positions, temperature_c), dtype=float)
        B, Bx = np.asarray(b, dtype=float), np.asarray(b_xi, dtype=float)
        root = (B @ self.root_shape) * float(self.beam.bending_stiffness(0.0, temperature_c))
        root_xi = (Bx @ self.root_shape_xi) * float(np.asarray(self.beam.bending_stiffness_xi([0.0], temperature_c))[0])
        return {"strain": strain, "stress_pa": stress, "moment_nm": kz * ei, "root_moment_nm": root,
                "moment_xi_nm": kx * ei_xi, "root_moment_xi_nm": root_xi,
                "root_moment_resultant_nm": resultant_moment(root, root_xi), "angles_deg": self.angles_deg.copy()}


def outline_corners(beam: Any, eta: float) -> list[float]:
    """The outline's corner angles at η (degrees): none for a tube, four for a rectangle or a table station."""
    sections = getattr(beam, "sections", None)
    if sections is not None:
        k = int(np.clip(np.searchsorted(beam.station_positions, eta, side="right") - 1, 0, len(sections) - 1))
        if sections[k].shape == "tube":
            return []
    corner = float(np.degrees(np.arctan2(float(beam.fibre_distance_xi(eta)), float(beam.fibre_distance(eta)))))
    return [corner, 180.0 - corner, 180.0 + corner, 360.0 - corner]
