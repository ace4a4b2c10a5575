"""Euler–Bernoulli finite-element model of the beam held at D, hanging or standing.

The beam is held at the bearing D (η = 0) and free at the tip (η = L). The rig's ``support`` says
how: ``pinned`` (the paper's plain bearing: no lateral displacement, free rotation) or
``clamped`` (the fixed bearing of Section 3.5, a mast's or blade's root: no displacement, no
rotation). Lateral displacement w(η) is across the thickness, in the plane. Cubic Hermite
elements carry [w, w'] at each node.

Besides the bending stiffness the model holds the geometric stiffness of the static axial
force: the weight of the beam and of every attached mass beyond η, per unit gravity along +η
(from D towards the tip; ``tension_stiffness``). A hanging beam has gravity +g along η, so its
self-weight is a tension that stiffens it; a standing beam (a mast) has gravity −g along η, so
the same law becomes a compression that softens it, and the beam buckles where the compression
reaches the critical load (``critical_load_factor``, refused with ``BucklingError``). The
centrifugal tension per unit ω² (``centrifugal_stiffness``) serves the virtual rig's large
pendulum swings.

Units: SI throughout (m, kg, s, N, Pa). Matrices are over all 2(n+1) nodal DOFs in the order
[w_0, w'_0, w_1, w'_1, ...]; the pinned support removes DOF 0, the clamp DOFs 0 and 1
(``free_dofs``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.special

from contract import PLANES, RigDescription, RigError

__all__ = [
    "GREENHILL_COEFFICIENT",
    "BeamModel",
    "BucklingError",
    "NodalShapes",
    "NaturalModes",
    "assemble_beam",
    "critical_load_factor",
    "greenhill_length",
    "natural_modes",
]

#: q L³ / EI at which a uniform column clamped at its foot buckles under its own weight q per
#: length (Greenhill 1881): 9 j² / 4 with j the first zero of the Bessel function J_{−1/3}.
GREENHILL_COEFFICIENT = 2.25 * scipy.optimize.brentq(lambda z: scipy.special.jv(-1.0 / 3.0, z), 1.5, 2.2, xtol=1e-14) ** 2


class BucklingError(RigError):
    """A standing beam that buckles under its own weight and attached masses.

    ``critical_load_factor`` is the multiplier of the gravity load at which it buckles (< 1 here);
    ``bare_critical_length`` the length (m) above which a bare uniform beam of the same section
    buckles under its own weight (Greenhill).
    """

    def __init__(self, message: str, *, critical_load_factor: float, bare_critical_length: float):
        super().__init__(message)
        self.critical_load_factor = critical_load_factor
        self.bare_critical_length = bare_critical_length

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
    """Assembled FE matrices of the beam (all nodal DOFs, see module docstring)."""

    rig: RigDescription
    nodes: np.ndarray
    mass: np.ndarray
    rotary_mass: np.ndarray  # the part of ``mass`` from rotary inertia of attached masses
    bending_stiffness: np.ndarray
    tension_stiffness: np.ndarray  # geometric stiffness of the weight beyond η per unit gravity along +η
    centrifugal_stiffness: np.ndarray  # geometric stiffness of the centrifugal tension per unit ω²
    youngs_modulus: float | None  # E(T) in Pa; None for a beam of table sections only
    temperature_c: float | None
    free_dofs: np.ndarray = field(repr=False)
    critical_load_factor: float = float("inf")  # gravity-load multiplier at which it buckles (inf: no compression)
    plane: str = "zeta"  # the bending plane: "zeta" (w = Δζ) or "xi" (w = Δξ of a biaxial beam, EI_ξ)

    @property
    def gravity(self) -> float:
        """|g| (m/s²)."""
        return self.rig.gravity

    @property
    def support(self) -> str:
        return self.rig.support

    @property
    def orientation(self) -> str:
        return self.rig.orientation

    @property
    def axial_gravity(self) -> float:
        """Gravity's component along +η (m/s²): +g hanging (tension), −g standing (compression)."""
        return _axial_gravity(self.rig)

    @property
    def geometric_stiffness(self) -> np.ndarray:
        """Geometric stiffness of the static axial force: tension (hanging) or compression (standing)."""
        return self.axial_gravity * self.tension_stiffness

    @property
    def stiffness(self) -> np.ndarray:
        """Linear stiffness about the static equilibrium: bending plus the geometric stiffness of the weight."""
        return self.bending_stiffness + self.geometric_stiffness

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


def _axial_gravity(rig: RigDescription) -> float:
    if rig.orientation == "hanging":
        return rig.gravity
    if rig.orientation == "standing":
        return -rig.gravity
    raise RigError(f"orientation={rig.orientation!r} must be 'hanging' or 'standing'")


def _free_dofs(rig: RigDescription, n_dof: int) -> np.ndarray:
    if rig.support == "pinned":
        return np.arange(1, n_dof)  # w(0) = 0
    if rig.support == "clamped":
        return np.arange(2, n_dof)  # w(0) = w'(0) = 0
    raise RigError(f"support={rig.support!r} must be 'pinned' or 'clamped'")


def greenhill_length(bending_stiffness: float, mass_per_length: float, gravity: float) -> float:
    """Length (m) above which a uniform column clamped at its foot buckles under its own weight.

    Parameters
    ----------
    bending_stiffness : EI (N·m²), > 0.
    mass_per_length : ρA (kg/m), > 0.
    gravity : g (m/s²), ≥ 0.

    Returns
    -------
    L_cr = (7.837 EI / (ρ A g))^(1/3) in m; ``inf`` without gravity.
    """
    for name, value in (("bending_stiffness", bending_stiffness), ("mass_per_length", mass_per_length)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}={value} must be positive and finite")
    if not (np.isfinite(gravity) and gravity >= 0):
        raise ValueError(f"{gravity=} must be non-negative and finite")
    if gravity == 0:
        return float("inf")
    return float((GREENHILL_COEFFICIENT * bending_stiffness / (mass_per_length * gravity)) ** (1.0 / 3.0))


def critical_load_factor(
    bending_stiffness: np.ndarray, tension_stiffness: np.ndarray, free_dofs: np.ndarray, compression: float
) -> float:
    """Smallest λ > 0 with det(K_b − λ·compression·K_G) = 0 over ``free_dofs``: the multiplier of
    the static compression at which the beam buckles.

    Parameters
    ----------
    bending_stiffness, tension_stiffness : (n, n) K_b and K_G (geometric stiffness per unit axial load).
    free_dofs : indices the support leaves free; K_b must be positive definite on them.
    compression : the load that compresses the beam (for gravity: g of a standing beam), ≥ 0.

    Returns
    -------
    λ_cr (dimensionless; ``inf`` if nothing compresses the beam). The beam is stable for λ_cr > 1.
    """
    if not (np.isfinite(compression) and compression >= 0):
        raise ValueError(f"{compression=} must be non-negative and finite")
    if compression == 0:
        return float("inf")
    Kb = bending_stiffness[np.ix_(free_dofs, free_dofs)]
    KG = compression * tension_stiffness[np.ix_(free_dofs, free_dofs)]
    n = Kb.shape[0]
    # K_G x = μ K_b x: the largest μ is 1/λ_cr (K_b is definite, K_G of a compression semi-definite).
    mu = scipy.linalg.eigh(0.5 * (KG + KG.T), 0.5 * (Kb + Kb.T), eigvals_only=True, subset_by_index=(n - 1, n - 1))[0]
    return float("inf") if mu <= 0 else float(1.0 / mu)


def element_bending_stiffness(beam, start: float, end: float, temperature_c: float | None = None) -> np.ndarray:
    """The 4×4 bending stiffness ∫ EI(η) N''ᵀ N'' dη (N/m … N·m) of one Hermite element [start, end] (m)
    of ``beam`` (a ``contract.Beam``), nominal (without stiffness segments), E at ``temperature_c`` (°C).

    Gauss quadrature on 5 points: exact for the polynomial EI of rectangles, tubes and tables
    within one stretch between stations.

    Raises
    ------
    ValueError
        ``end <= start`` or an element off the beam.
    """
    if not (np.isfinite(start) and np.isfinite(end) and 0.0 <= start < end <= beam.length * (1 + 1e-12)):
        raise ValueError(f"element [{start}, {end}] must satisfy 0 <= start < end <= length={beam.length}")
    l = end - start
    x = np.minimum(start + l * _GAUSS_XI, beam.length)
    N2 = _hermite(_GAUSS_XI, l, 2)
    return np.einsum("g,g,gi,gj->ij", l * _GAUSS_W, beam.bending_stiffness(x, temperature_c), N2, N2)


def _beyond(beam) -> tuple:
    """Functions x ↦ ∫_x^L μ dη (the beam's mass beyond x, kg) and x ↦ ∫_x^L μ η dη (kg·m) of a
    sectioned beam, exact for its polynomial μ (Gauss–Legendre on each stretch between stations)."""
    positions = beam.station_positions
    xi, weights = np.polynomial.legendre.leggauss(4)
    mass_stretch = beam._segment_integrals(0)
    moment_stretch = beam._segment_integrals(1)
    # totals of the whole stretches beyond each station
    mass_after = np.concatenate([np.cumsum(mass_stretch[::-1])[::-1], [0.0]])
    moment_after = np.concatenate([np.cumsum(moment_stretch[::-1])[::-1], [0.0]])

    def partial(x: np.ndarray, moment: int, after: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        last = len(positions) - 1
        j = np.clip(np.searchsorted(positions, x, side="right") - 1, 0, last)
        out = np.zeros_like(x)
        for k in np.unique(j):
            at = j == k
            if k == last:
                continue
            a, b = x[at], positions[k + 1]
            pts = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * xi[None, :]
            mu = beam.mass_per_length_at(pts.ravel()).reshape(pts.shape)
            out[at] = 0.5 * (b - a) * np.sum(weights * mu * pts**moment, axis=1) + after[k + 1]
        return out

    return (lambda x: partial(x, 0, mass_after)), (lambda x: partial(x, 1, moment_after))


def _mesh(rig: RigDescription, elements: int, extra_nodes: Sequence[float] = ()) -> np.ndarray:
    """Uniform nodes with extra nodes at attached masses and stiffness-segment ends.

    Grid nodes closer than 0.3 element lengths to such a point give way to it, so no
    element is much shorter than the rest.
    """
    length = rig.beam.length
    grid = np.linspace(0.0, length, elements + 1)
    h = length / elements
    special = {m.position for m in rig.point_masses} | {float(x) for x in extra_nodes}
    special.update(float(x) for x in rig.beam.station_positions)  # no element straddles a kink or a step
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
    plane: str = "zeta",
) -> BeamModel:
    """Assemble the FE matrices of the beam described by ``rig`` at ``temperature_c`` (°C).

    ``elements`` is the number of uniform elements before nodes are added at attached masses,
    stiffness-segment ends and ``extra_nodes`` (m; e.g. where a later damage will sit, so two
    models share one mesh). ``temperature_c=None`` uses the beam's reference temperature.

    ``plane`` is the bending plane the model's lateral field w lies in: ``"zeta"`` (the planar
    contract's, the default) or ``"xi"`` (the second plane of a biaxial beam). The ξ model differs
    only by its bending stiffness EI_ξ (``Beam.bending_stiffness_xi``): the mass, the attached masses
    and their rotary inertia, the axial load's geometric stiffness and the clamp are the same.

    Raises
    ------
    BucklingError
        A standing beam whose weight and attached masses exceed its critical load (λ_cr ≤ 1).
    RigError
        ``plane="xi"`` for a planar beam (it does not bend in ξ); a table station without ``bending_stiffness_xi``.
    """
    if not isinstance(elements, (int, np.integer)) or elements < 2:
        raise ValueError(f"{elements=} must be an integer >= 2")
    if plane not in PLANES:
        raise ValueError(f"plane={plane!r} must be one of {PLANES}")
    beam = rig.beam
    xi = plane == "xi"
    if xi and not beam.biaxial:
        raise RigError("plane='xi' is the second bending plane of a biaxial beam; this beam has beam.bending='planar'")
    nodes = _mesh(rig, int(elements), extra_nodes)
    n_dof = 2 * len(nodes)
    length = beam.length
    uniform = beam.uniform
    stiffness_along = beam.bending_stiffness_xi if xi else beam.bending_stiffness
    if uniform:
        E = beam.youngs_modulus_at(temperature_c)
        EI = E * (beam.second_moment_of_area_xi if xi else beam.second_moment_of_area)
        mu = beam.mass_per_length
    else:
        E = None if beam.youngs_modulus is None else beam.youngs_modulus_at(temperature_c)
        stiffness_factor = beam.stiffness_factor_at(temperature_c)
        weight_beyond, moment_beyond = _beyond(beam)

    masses = np.array([(m.position, m.mass) for m in rig.point_masses], dtype=float).reshape(-1, 2)

    def static_tension(x: np.ndarray) -> np.ndarray:
        below = (masses[None, :, 0] > x[:, None]) * masses[None, :, 1]
        own = mu * (length - x) if uniform else weight_beyond(x)
        return own + below.sum(axis=1)

    def centrifugal_tension(x: np.ndarray) -> np.ndarray:
        below = (masses[None, :, 0] > x[:, None]) * masses[None, :, 1] * masses[None, :, 0]
        own = mu * 0.5 * (length**2 - x**2) if uniform else moment_beyond(x)
        return own + below.sum(axis=1)

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
        if uniform:
            M[sl] += mu * np.einsum("g,gi,gj->ij", w, N0, N0)
            K[sl] += EI * factor * np.einsum("g,gi,gj->ij", w, N2, N2)
        else:
            # The section varies within the element: EI and μ at the Gauss points (exact for the
            # polynomial tapers of rectangles, tubes and tables, so a taper converges with the mesh).
            EI_g = stiffness_along(x) * stiffness_factor
            mu_g = beam.mass_per_length_at(x)
            M[sl] += np.einsum("g,g,gi,gj->ij", w, mu_g, N0, N0)
            K[sl] += factor * np.einsum("g,g,gi,gj->ij", w, EI_g, N2, N2)
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

    free = _free_dofs(rig, n_dof)
    compression = max(0.0, -_axial_gravity(rig))
    factor = critical_load_factor(K, KG, free, compression)
    if factor <= 1.0:
        at = "" if temperature_c is None else f" at {temperature_c:g} °C"
        load = "its own weight and attached masses" if any(m.mass > 0 and m.position > 0 for m in rig.point_masses) else "its own weight"
        message = (
            f"the standing beam buckles{' in the ξ plane' if xi else ''} under {load}{at}: its critical load factor is "
            f"λ_cr = {factor:.4g} (it would stand only up to {factor * rig.gravity:.4g} m/s² of the {rig.gravity:g} m/s² "
            "gravity)"
        )
        if uniform:
            bare = greenhill_length(EI, mu, rig.gravity)
            message += (
                f"; a bare standing beam of this section (EI = {EI:.4g} N·m², ρA = {mu:.4g} kg/m) buckles under "
                f"its own weight above the critical length L_cr = {bare:.4g} m (Greenhill), this one is {length:g} m long"
            )
        else:
            bare = float("nan")  # no single section: Greenhill's length of a uniform column does not apply
            message += f"; the beam of beam.sections is {length:g} m long and weighs {beam.mass:.4g} kg"
        raise BucklingError(message, critical_load_factor=factor, bare_critical_length=bare)
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
        free_dofs=free,
        critical_load_factor=factor,
        plane=plane,
    )


@dataclass(frozen=True)
class NaturalModes:
    """Eigenfrequencies (Hz) and mass-normalised eigenmodes of the beam on its support."""

    frequencies_hz: np.ndarray
    shapes: NodalShapes
    support: str = "pinned"  # the support they belong to: "pinned" or "clamped"

    @property
    def angular_frequencies(self) -> np.ndarray:
        return 2.0 * np.pi * self.frequencies_hz


def natural_modes(model: BeamModel, count: int = 6) -> NaturalModes:
    """The first ``count`` modes of the beam linearised about its static equilibrium.

    The equilibrium is the straight beam, hanging (stretched by its weight) or standing
    (compressed by it). Shapes are mass-normalised (φᵀ M φ = 1) and signed so that the tip
    displacement is positive.

    Examples
    --------
    A 1 m steel strip (50 × 5 mm) clamped at D, without gravity: the cantilever's closed form
    f_k = (β_k L)² / (2π L²) · √(EI / ρA) gives 4.18, 26.18 and 73.31 Hz.

    >>> import numpy as np
    >>> from contract import parse_rig
    >>> from estimator import assemble_beam, natural_modes
    >>> rig = parse_rig({"beam": {"length": 1.0, "width": 0.05, "thickness": 0.005,
    ...                           "youngs_modulus": 210e9, "density": 7850.0},
    ...                  "gravity": 0.0, "reflector_distance": 0.5, "support": "clamped",
    ...                  "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]})
    >>> np.round(natural_modes(assemble_beam(rig), 3).frequencies_hz, 2)
    array([ 4.18, 26.18, 73.31])
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
    return NaturalModes(np.sqrt(eigenvalues) / (2 * np.pi), NodalShapes(model.nodes, dofs), model.support)
