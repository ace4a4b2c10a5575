"""Damage signatures: what a local damage would do to the modal figures the analytics can see.

For candidate damage locations along the beam the FE model of the rig predicts

* the relative shift of the eigenfrequencies of modes 1..n (df/f), and
* the change of each mode's operational curvature shape *as the estimator sees it*: the
  perturbed mode's body-frame deflection w̃ = w − w'(0)·η is projected (least squares over the
  beam) onto the healthy rig's unit deformations s_χ, b = argmin ‖S·b − w̃‖, and its curvature
  is S''(stations)·b, normalised to unit RMS over the stations and signed so that b of the
  mode's own unit deformation is positive (the convention of ``analytics.curvature_shape``).

Two damage kinds per candidate: a bending-stiffness loss (EI × ``stiffness_factor``) over a
segment of ``segment_length`` m centred at the candidate, and a point mass of ``mass_fraction``
of the beam's mass at the candidate. The arrays are the input of the model-assisted location
index in ``analytics`` (damage location assurance criterion, Messina et al. 1998, extended by
the curvature-shape change); analytics itself stays free of FE.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ._beam import NodalShapes, assemble_beam, element_bending_stiffness, natural_modes
from contract import RigDescription
from ._unit_deformations import unit_deformations

__all__ = ["DamageSignatures", "damage_signatures"]

_GRID = 401  # projection grid along the beam


@dataclass(frozen=True)
class DamageSignatures:
    """Predicted changes of modal figures for M candidate damages (plain arrays).

    eta : (M,) m, centre of each candidate damage (from the bearing).
    kind : (M,) "stiffness" | "mass".
    frequency_shift : (M, n_modes) relative eigenfrequency change f_damaged/f_healthy − 1.
    curvature_change : (M, n_modes, n_stations) change of the unit-RMS curvature shapes
        (dimensionless) in the unit-deformation span, at ``stations``.
    stations : (n_stations,) m; length : beam length, m; units : per mode the 0-based unit
        deformation it belongs to (the sign reference of its shape); severity : per candidate
        the stiffness factor or the added mass (kg) the signature was computed for.
    healthy_hz : (n_modes,) eigenfrequencies of the healthy model, Hz.
    healthy_shapes : (n_modes, n_stations) its unit-RMS curvature shapes.
    temperature_slope : (n_modes,) relative eigenfrequency change per K of the healthy model
        (E(T) of the rig; gravity-dominated modes barely move), 1/K: the prior of the
        analytics' temperature normalisation.
    """

    eta: np.ndarray
    kind: tuple[str, ...]
    frequency_shift: np.ndarray
    curvature_change: np.ndarray
    stations: np.ndarray
    length: float
    units: tuple[int, ...]
    severity: np.ndarray
    healthy_hz: np.ndarray
    healthy_shapes: np.ndarray
    temperature_slope: np.ndarray | None = None

    @property
    def n_modes(self) -> int:
        return self.frequency_shift.shape[1]

    def to_dict(self) -> dict:
        """JSON-safe form (lists)."""
        return {
            "eta": self.eta.tolist(), "kind": list(self.kind), "frequency_shift": self.frequency_shift.tolist(),
            "curvature_change": self.curvature_change.tolist(), "stations": self.stations.tolist(), "length": self.length,
            "units": list(self.units), "severity": self.severity.tolist(), "healthy_hz": self.healthy_hz.tolist(),
            "healthy_shapes": self.healthy_shapes.tolist(),
            "temperature_slope": None if self.temperature_slope is None else self.temperature_slope.tolist(),
        }


def _element_bending(l: float) -> np.ndarray:
    return np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
                     [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]]) / l**3


def _element_tension(l: float) -> np.ndarray:
    return np.array([[36, 3 * l, -36, 3 * l], [3 * l, 4 * l * l, -3 * l, -l * l],
                     [-36, -3 * l, 36, -3 * l], [3 * l, -l * l, -3 * l, 4 * l * l]]) / (30 * l)




def _shapes(dofs: np.ndarray, nodes: np.ndarray, unit_of: list[int], grid: np.ndarray, S_grid_pinv: np.ndarray,
            S2_st: np.ndarray) -> np.ndarray:
    """Unit-RMS curvature shapes (modes, stations) of nodal mode fields as the unit-deformation span shows them."""
    shapes = NodalShapes(nodes, dofs)
    body = shapes.evaluate(grid, 0) - np.outer(grid, shapes.evaluate(0.0, 1))
    b = S_grid_pinv @ body  # (Γ, n)
    k = (S2_st @ b).T
    rms = np.sqrt(np.mean(k**2, axis=1, keepdims=True))
    rms[rms == 0] = 1.0
    sign = np.sign(b[unit_of, np.arange(len(unit_of))])
    sign[sign == 0] = 1.0
    return k / rms * sign[:, None]


def damage_signatures(
    rig: RigDescription,
    stations: object | None = None,
    *,
    gamma: int = 4,
    step: float | None = None,
    stiffness_factor: float = 0.8,
    segment_length: float = 0.2,
    mass_fraction: float = 0.01,
    kinds: tuple[str, ...] = ("stiffness", "mass"),
    elements: int = 40,
    basis: int = 20,
) -> DamageSignatures:
    """Signatures of candidate damages every ``step`` m (default segment_length/2) along the beam of ``rig``.

    stations : η (m) where curvature shapes are compared (default rig.truth_stations, else 8
    equidistant); gamma : unit deformations of the estimator (modes 1..gamma+1 are predicted,
    modes 1 and 2 sharing the combimode). Stiffness candidates (EI × stiffness_factor over
    segment_length) are centred on [segment_length/2, L − segment_length/2], mass candidates
    (mass_fraction of the beam's mass, with its weight's tension) on [step, L], tip last.
    The perturbed modes come from a Rayleigh–Ritz solve in the first ``basis`` healthy modes
    augmented by the residual static flexibility at the perturbed DOFs (the first-order
    correction of a local change), which reproduces an exact solve's shifts to 4 significant digits.
    """
    if not isinstance(rig, RigDescription):
        raise ValueError(f"rig must be a RigDescription, got {type(rig).__name__}")
    L = rig.beam.length
    if not (isinstance(segment_length, (int, float)) and 0 < segment_length < L):
        raise ValueError(f"{segment_length=} must be in (0, {L}) m")
    step = 0.5 * segment_length if step is None else step
    if not (isinstance(step, (int, float)) and 0 < step <= L / 2):
        raise ValueError(f"{step=} must be in (0, {L / 2}] m")
    if not (isinstance(stiffness_factor, (int, float)) and stiffness_factor > 0 and stiffness_factor != 1.0):
        raise ValueError(f"{stiffness_factor=} must be > 0 and != 1")
    if not (isinstance(mass_fraction, (int, float)) and mass_fraction > 0):
        raise ValueError(f"{mass_fraction=} must be > 0")
    if not kinds or any(k not in ("stiffness", "mass") for k in kinds):
        raise ValueError(f"{kinds=} must name 'stiffness' and/or 'mass'")
    if not isinstance(gamma, (int, np.integer)) or not 1 <= gamma <= 5:
        raise ValueError(f"{gamma=} must be an integer in [1, 5]")
    if stations is None:
        st = np.asarray(rig.truth_stations if rig.truth_stations else np.linspace(0, L, 9)[1:], dtype=float)
    else:
        st = np.asarray(stations, dtype=float)
    if st.ndim != 1 or st.size < 2 or not np.all(np.isfinite(st)) or st.min() < 0 or st.max() > L:
        raise ValueError(f"stations must be >= 2 finite positions on [0, {L}] m")
    half = 0.5 * segment_length
    n_stiff = int(np.floor((L - 2 * half) / step + 1e-9)) + 1
    centres = {"stiffness": half + step * np.arange(n_stiff), "mass": L - step * np.arange(int(np.floor(L / step + 1e-9)))[::-1]}
    extra = set()
    if "stiffness" in kinds:
        extra.update(np.round(np.concatenate([centres["stiffness"] - half, centres["stiffness"] + half]), 12).tolist())
    if "mass" in kinds:
        extra.update(np.round(centres["mass"], 12).tolist())
    model = assemble_beam(rig, elements=elements, extra_nodes=sorted(x for x in extra if 0 < x < L))
    nodes = model.nodes
    units = unit_deformations(model, gamma)
    unit_of = [u for u, group in enumerate(units.modes) for _ in group]
    n_modes = len(unit_of)
    nb = int(min(max(basis, n_modes + 5), len(model.free_dofs)))
    healthy = natural_modes(model, nb)
    phi = healthy.shapes.dofs  # (ndof, nb) mass-normalised
    lam = (2 * np.pi * healthy.frequencies_hz) ** 2
    grid = np.linspace(0.0, L, _GRID)
    S_pinv = np.linalg.pinv(units.shape(grid))
    S2 = units.curvature(st)
    f0 = healthy.frequencies_hz[:n_modes].copy()
    k0 = _shapes(phi[:, :n_modes], nodes, unit_of, grid, S_pinv, S2)
    if rig.beam.uniform:
        EI = model.youngs_modulus * rig.beam.second_moment_of_area

        def element_bending(e: int) -> np.ndarray:
            return EI * _element_bending(lengths[e])
    else:

        def element_bending(e: int) -> np.ndarray:
            return element_bending_stiffness(rig.beam, nodes[e], nodes[e + 1], model.temperature_c)
    mids = 0.5 * (nodes[:-1] + nodes[1:])
    lengths = np.diff(nodes)
    existing = np.ones(mids.size)
    for seg in rig.beam.stiffness_segments:
        existing[(mids >= seg.start) & (mids <= seg.end)] *= seg.factor

    # residual flexibility of the truncated basis at the perturbed DOFs (static correction)
    free = model.free_dofs
    K = model.stiffness
    M = model.mass
    Kinv = np.zeros_like(K)
    Kinv[np.ix_(free, free)] = np.linalg.inv(K[np.ix_(free, free)])

    etas, kind_list, sev, dfs, dks = [], [], [], [], []
    for kind in kinds:
        for c in centres[kind]:
            dK = np.zeros_like(K)
            dM = np.zeros_like(M)
            if kind == "stiffness":
                sel = np.flatnonzero((mids >= c - half) & (mids <= c + half))
                for e in sel:
                    dK[2 * e : 2 * e + 4, 2 * e : 2 * e + 4] += (stiffness_factor - 1.0) * existing[e] * element_bending(e)
                idx = np.unique(np.concatenate([np.arange(2 * e, 2 * e + 4) for e in sel]))
                s = float(stiffness_factor)
            else:
                m = mass_fraction * rig.beam.mass
                j = int(np.argmin(np.abs(nodes - c)))
                dM[2 * j, 2 * j] += m
                for e in np.flatnonzero(mids < nodes[j]):
                    dK[2 * e : 2 * e + 4, 2 * e : 2 * e + 4] += m * model.axial_gravity * _element_tension(lengths[e])
                idx = np.array([2 * j, 2 * j + 1])
                s = m
            idx = idx[np.isin(idx, free)]  # the support's constrained DOFs carry no residual
            R = Kinv[:, idx] - phi @ (phi[idx].T / lam[:, None])
            R = R / np.maximum(np.sqrt(np.einsum("ij,ij->j", R, M @ R)), 1e-300)
            Bs = np.column_stack([phi, R])[free]
            Kd = (K + dK)[np.ix_(free, free)]
            Md = (M + dM)[np.ix_(free, free)]
            w, q = scipy.linalg.eigh(Bs.T @ Kd @ Bs, Bs.T @ Md @ Bs)
            fd = np.sqrt(np.clip(w[:n_modes], 0, None)) / (2 * np.pi)
            full = np.zeros((phi.shape[0], n_modes))
            full[free] = Bs @ q[:, :n_modes]
            kd = _shapes(full, nodes, unit_of, grid, S_pinv, S2)
            etas.append(float(c))
            kind_list.append(kind)
            sev.append(s)
            dfs.append(fd / f0 - 1.0)
            dks.append(kd - k0)
    t_ref = rig.beam.reference_temperature
    warm = natural_modes(assemble_beam(rig, elements=elements, temperature_c=t_ref + 1.0), n_modes).frequencies_hz
    cold = natural_modes(assemble_beam(rig, elements=elements, temperature_c=t_ref - 1.0), n_modes).frequencies_hz
    slope = 0.5 * (warm - cold) / f0
    return DamageSignatures(np.array(etas), tuple(kind_list), np.array(dfs), np.array(dks), st, float(L), tuple(unit_of),
                            np.array(sev), f0, k0, slope)
