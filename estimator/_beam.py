"""Euler–Bernoulli finite-element model of the hanging beam.

The beam hangs from the bearing D (η = 0, pinned: no lateral displacement, free rotation) and
is free at the tip (η = L). Lateral displacement w(η) is across the thickness, in the plane.
Cubic Hermite elements carry [w, w'] at each node. Besides the bending stiffness the model holds
the geometric stiffness of the axial tension: the self-weight of the beam and of every attached
mass below η, per unit gravity (``tension_stiffness``), and the centrifugal tension per unit
ω² (``centrifugal_stiffness``, used by the virtual rig for large pendulum swings).

Units: SI throughout (m, kg, s, N, Pa). Matrices are over all 2(n+1) nodal DOFs in the order
[w_0, w'_0, w_1, w'_1, ...]; the pinned support removes DOF 0 (``free_dofs``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg

from contract import RigDescription

__all__ = ["BeamModel", "NodalShapes", "NaturalModes", "assemble_beam", "natural_modes"]

_GAUSS_XI, _GAUSS_W = np.polynomial.legendre.leggauss(5)
_GAUSS_XI = 0.5 * (_GAUSS_XI + 1.0)  # on [0, 1]
_GAUSS_W = 0.5 * _GAUSS_W


def _hermite(xi: np.ndarray, length: float | np.ndarray, derivative: int) -> np.ndarray:
    """Cubic Hermite shape functions (or their d/dη derivatives) at local coordinates xi ∈ [0, 1].

    Returns an array of shape (len(xi), 4) for the DOFs [w_a, w'_a, w_b, w'_b].
    ``length`` may be a scalar or an array matching ``xi``.
    """
    xi = np.asarray(xi, dtype=float)
    l = np.broadcast_to(np.asarray(length, dtype=float), xi.shape)
    if derivative == 0:
        cols = (1 - 3 * xi**2 + 2 * xi**3, l * (xi - 2 * xi**2 + xi**3), 3 * xi**2 - 2 * xi**3, l * (-(xi**2) + xi**3))
    elif derivative == 1:
        cols = ((-6 * xi + 6 * xi**2) / l, 1 - 4 * xi + 3 * xi**2, (6 * xi - 6 * xi**2) / l, -2 * xi + 3 * xi**2)
    elif derivative == 2:
        cols = ((-6 + 12 * xi) / l**2, (-4 + 6 * xi) / l, (6 - 12 * xi) / l**2, (-2 + 6 * xi) / l)
    elif derivative == 3:
        cols = (12 / l**3, 6 / l**2, -12 / l**3, 6 / l**2)
        cols = tuple(np.broadcast_to(c, xi.shape) for c in cols)
    else:
        raise ValueError(f"{derivative=} must be 0, 1, 2 or 3")
    return np.stack(cols, axis=-1)


def _locate(nodes: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Element index, local coordinate and element length of each η (η on a node goes to the element above it)."""
    n_el = len(nodes) - 1
    element = np.clip(np.searchsorted(nodes, eta, side="right") - 1, 0, n_el - 1)
    length = nodes[element + 1] - nodes[element]
    xi = (eta - nodes[element]) / length
    return element, xi, length


@dataclass(frozen=True)
class NodalShapes:
    """Fields along the beam given by their Hermite nodal values.

    ``dofs`` has shape (2 * len(nodes), k): column c is the field [w_0, w'_0, w_1, w'_1, ...].
    Evaluation interpolates exactly within the elements (no finite differences).
    """

    nodes: np.ndarray
    dofs: np.ndarray

    def __post_init__(self) -> None:
        if self.dofs.ndim != 2 or self.dofs.shape[0] != 2 * len(self.nodes):
            raise ValueError(f"dofs shape {self.dofs.shape} does not match {len(self.nodes)} nodes")

    @property
    def count(self) -> int:
        return self.dofs.shape[1]

    def evaluate(self, eta: np.ndarray | float, derivative: int = 0) -> np.ndarray:
        """Field (derivative 0), slope (1), curvature (2) or its derivative (3) at arc lengths η (m).

        Returns shape (len(η), k) for array η, (k,) for a scalar.
        """
        scalar = np.ndim(eta) == 0
        eta = np.atleast_1d(np.asarray(eta, dtype=float))
        length_total = self.nodes[-1]
        if np.any(~np.isfinite(eta)) or np.any(eta < -1e-12) or np.any(eta > length_total * (1 + 1e-12)):
            raise ValueError(f"eta must lie on the beam [0, {length_total}], got {eta.min()}..{eta.max()}")
        eta = np.clip(eta, 0.0, length_total)
        element, xi, length = _locate(self.nodes, eta)
        shape = _hermite(xi, length, derivative)  # (m, 4)
        index = 2 * element[:, None] + np.arange(4)[None, :]  # (m, 4)
        values = np.einsum("mj,mjk->mk", shape, self.dofs[index])
        return values[0] if scalar else values

    def with_dofs(self, dofs: np.ndarray) -> "NodalShapes":
        return NodalShapes(self.nodes, dofs)


@dataclass(frozen=True)
class BeamModel:
    """Assembled FE matrices of the hanging beam (all nodal DOFs, see module docstring)."""

    rig: RigDescription
    nodes: np.ndarray
    mass: np.ndarray
    rotary_mass: np.ndarray  # the part of ``mass`` from rotary inertia of attached masses
    bending_stiffness: np.ndarray
    tension_stiffness: np.ndarray  # geometric stiffness of the static tension per unit gravity
    centrifugal_stiffness: np.ndarray  # geometric stiffness of the centrifugal tension per unit ω²
    youngs_modulus: float
    temperature_c: float | None
    free_dofs: np.ndarray = field(repr=False)

    @property
    def gravity(self) -> float:
        return self.rig.gravity

    @property
    def stiffness(self) -> np.ndarray:
        """Linear stiffness about the hanging equilibrium: bending plus gravity tension."""
        return self.bending_stiffness + self.gravity * self.tension_stiffness

    def rigid_rotation(self) -> np.ndarray:
        """Nodal field of a unit rotation about D: w = η, w' = 1."""
        field_ = np.zeros(2 * len(self.nodes))
        field_[0::2] = self.nodes
        field_[1::2] = 1.0
        return field_

    def uniform_translation(self) -> np.ndarray:
        """Nodal field w = 1, w' = 0."""
        field_ = np.zeros(2 * len(self.nodes))
        field_[0::2] = 1.0
        return field_

    @property
    def total_mass(self) -> float:
        t = self.uniform_translation()
        return float(t @ self.mass @ t)


def _mesh(rig: RigDescription, elements: int, extra_nodes: Sequence[float] = ()) -> np.ndarray:
    """Uniform nodes with extra nodes at attached masses and stiffness-segment ends.

    Grid nodes closer than 0.3 element lengths to such a point give way to it, so no
    element is much shorter than the rest.
    """
    length = rig.beam.length
    grid = np.linspace(0.0, length, elements + 1)
    h = length / elements
    special = {m.position for m in rig.point_masses} | {float(x) for x in extra_nodes}
    for segment in rig.beam.stiffness_segments:
        special.update((segment.start, segment.end))
    special = np.array(sorted(p for p in special if 1e-9 < p < length - 1e-9))
    if special.size:
        keep = np.ones(grid.size, dtype=bool)
        distance = np.min(np.abs(grid[:, None] - special[None, :]), axis=1)
        keep[1:-1] = distance[1:-1] >= 0.3 * h
        grid = np.union1d(grid[keep], special)
    return grid


def assemble_beam(
    rig: RigDescription,
    *,
    temperature_c: float | None = None,
    elements: int = 40,
    extra_nodes: Sequence[float] = (),
) -> BeamModel:
    """Assemble the FE matrices of the beam described by ``rig`` at ``temperature_c`` (°C).

    ``elements`` is the number of uniform elements before nodes are added at attached masses,
    stiffness-segment ends and ``extra_nodes`` (m; e.g. where a later damage will sit, so two
    models share one mesh). ``temperature_c=None`` uses the beam's reference temperature.
    """
    if not isinstance(elements, (int, np.integer)) or elements < 2:
        raise ValueError(f"{elements=} must be an integer >= 2")
    beam = rig.beam
    nodes = _mesh(rig, int(elements), extra_nodes)
    n_dof = 2 * len(nodes)
    E = beam.youngs_modulus_at(temperature_c)
    EI = E * beam.second_moment_of_area
    mu = beam.mass_per_length
    length = beam.length

    masses = np.array([(m.position, m.mass) for m in rig.point_masses], dtype=float).reshape(-1, 2)

    def static_tension(x: np.ndarray) -> np.ndarray:
        below = (masses[None, :, 0] > x[:, None]) * masses[None, :, 1]
        return mu * (length - x) + below.sum(axis=1)

    def centrifugal_tension(x: np.ndarray) -> np.ndarray:
        below = (masses[None, :, 0] > x[:, None]) * masses[None, :, 1] * masses[None, :, 0]
        return mu * 0.5 * (length**2 - x**2) + below.sum(axis=1)

    M = np.zeros((n_dof, n_dof))
    M_rot = np.zeros((n_dof, n_dof))
    K = np.zeros((n_dof, n_dof))
    KG = np.zeros((n_dof, n_dof))
    KC = np.zeros((n_dof, n_dof))
    for e in range(len(nodes) - 1):
        a, b = nodes[e], nodes[e + 1]
        l = b - a
        x = a + l * _GAUSS_XI
        w = l * _GAUSS_W
        N0 = _hermite(_GAUSS_XI, l, 0)
        N1 = _hermite(_GAUSS_XI, l, 1)
        N2 = _hermite(_GAUSS_XI, l, 2)
        factor = 1.0
        mid = 0.5 * (a + b)
        for segment in beam.stiffness_segments:
            if segment.start <= mid <= segment.end:
                factor *= segment.factor
        idx = np.arange(2 * e, 2 * e + 4)
        sl = np.ix_(idx, idx)
        M[sl] += mu * np.einsum("g,gi,gj->ij", w, N0, N0)
        K[sl] += EI * factor * np.einsum("g,gi,gj->ij", w, N2, N2)
        KG[sl] += np.einsum("g,g,gi,gj->ij", w, static_tension(x), N1, N1)
        KC[sl] += np.einsum("g,g,gi,gj->ij", w, centrifugal_tension(x), N1, N1)

    for point in rig.point_masses:
        element, xi, l = _locate(nodes, np.array([point.position]))
        idx = np.arange(2 * element[0], 2 * element[0] + 4)
        sl = np.ix_(idx, idx)
        n0 = _hermite(xi, l, 0)[0]
        n1 = _hermite(xi, l, 1)[0]
        M[sl] += point.mass * np.outer(n0, n0)
        rot = point.rotary_inertia * np.outer(n1, n1)
        M[sl] += rot
        M_rot[sl] += rot

    return BeamModel(
        rig=rig,
        nodes=nodes,
        mass=M,
        rotary_mass=M_rot,
        bending_stiffness=K,
        tension_stiffness=KG,
        centrifugal_stiffness=KC,
        youngs_modulus=E,
        temperature_c=temperature_c,
        free_dofs=np.arange(1, n_dof),
    )


@dataclass(frozen=True)
class NaturalModes:
    """Eigenfrequencies (Hz) and mass-normalised eigenmodes of the pinned hanging beam."""

    frequencies_hz: np.ndarray
    shapes: NodalShapes

    @property
    def angular_frequencies(self) -> np.ndarray:
        return 2.0 * np.pi * self.frequencies_hz


def natural_modes(model: BeamModel, count: int = 6) -> NaturalModes:
    """The first ``count`` modes of the beam linearised about the hanging equilibrium.

    Shapes are mass-normalised (φᵀ M φ = 1) and signed so that the tip displacement is positive.
    """
    free = model.free_dofs
    if not isinstance(count, (int, np.integer)) or not 1 <= count <= len(free):
        raise ValueError(f"{count=} must be an integer in [1, {len(free)}]")
    K = model.stiffness[np.ix_(free, free)]
    M = model.mass[np.ix_(free, free)]
    eigenvalues, vectors = scipy.linalg.eigh(K, M, subset_by_index=(0, int(count) - 1))
    # Without gravity the pinned beam keeps a rigid rotation at (numerically) zero frequency.
    if np.any(eigenvalues < -1e-9 * abs(eigenvalues).max()):
        raise ValueError("the beam model is not positive semi-definite: check gravity, masses and stiffness")
    eigenvalues = np.clip(eigenvalues, 0.0, None)
    dofs = np.zeros((2 * len(model.nodes), int(count)))
    dofs[free] = vectors
    tip = dofs[-2]
    dofs *= np.where(tip < 0, -1.0, 1.0)
    return NaturalModes(np.sqrt(eigenvalues) / (2 * np.pi), NodalShapes(model.nodes, dofs))
