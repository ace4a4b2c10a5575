"""The plant of the virtual rig: the beam on a moving bearing, pinned (a flexible pendulum) or
clamped (a cantilever, hanging or standing as a mast).

Formulation (floating frame of reference, exact in the large rotation):
the frame sits at the bearing D and turns with the beam's tangent there (angle θ, positive
turning η towards ζ). In it the beam's lateral deflection is w(x, t) = Σ_i Φ_i(x) q_i(t), with
Φ_i the first modes of the beam clamped in the frame (w(0) = w'(0) = 0), mass-normalised,
computed with the nominal static axial force. Axial shortening u(x) = −½∫₀ˣ w'² (inextensible
beam) is kept in the sensor kinematics.

Gravity is the vector g_η·e_η of the inertial frame: g_η = +g for a hanging beam (η points down
along it), g_η = −g for a standing one (η points up along it). With y = [θ, q], bearing
displacement d(t) (prescribed, horizontal):

    I_D θ̈ + bᵀ q̈ = −S_D (d̈ cos θ + g_η sin θ) − (g_η cos θ − d̈ sin θ) cᵀ q + M_f − (C ẏ)_θ + F_θ
    b θ̈ + M_q q̈ = −[κ_E K_b + (g_η cos θ − d̈ sin θ) K_g + θ̇² K_c] q − c (d̈ cos θ + g_η sin θ) − (C ẏ)_q + F_q

where I_D, S_D are the beam's second and first moments of mass about D, b and c the modal
first moments (∫ m x Φ_i + J Φ_i', ∫ m Φ_i), K_b, K_g the bending and gravity-tension
stiffness, K_c the centrifugal tension stiffness minus the centrifugal softening, κ_E the
temperature factor of Young's modulus, M_f the bearing's Coulomb friction and C modal damping of
the linearised structure. K_g is the geometric stiffness of the weight beyond x per unit axial
gravity, so g_η < 0 makes it a compression (a mast softens and can buckle). Linearised at
θ = 0 this is the pinned FE beam projected on [θ, Φ], so the plant's eigenfrequencies are those
of ``linear_frequencies``.

A clamped support (the fixed bearing) holds the frame: θ ≡ 0, the θ row above becomes the clamp's
reaction moment and drops out, and only the q rows are integrated (the inverse mass matrix has a
zero θ row and column, so θ̈ = 0 exactly):

    M_q q̈ = −[κ_E K_b + g_η K_g] q − c d̈ − C_q q̇ + F_q

This model is the plant, not the estimator's kinematic model: more modes than unit
deformations, no small-angle shortcuts, foreshortening in the kinematics, exact sensor angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg

from estimator import BeamModel, NodalShapes

__all__ = ["Plant", "build_plant", "clamped_basis", "integrate"]


def clamped_basis(models: list[BeamModel], count: int) -> NodalShapes:
    """Mass-orthonormal basis spanning the first ``count`` clamped-in-frame modes of each model.

    With one model these are its clamped modes; with a healthy and a damaged model the basis
    holds both, so a stiffness change keeps its local curvature in the simulation.
    """
    reference = models[0]
    n_dof = reference.mass.shape[0]
    inner = np.arange(2, n_dof)
    columns = []
    for model in models:
        if model.mass.shape != reference.mass.shape or not np.allclose(model.nodes, reference.nodes):
            raise ValueError("the models of one plant must share their mesh")
        K = model.stiffness[np.ix_(inner, inner)]
        M = model.mass[np.ix_(inner, inner)]
        _, vectors = scipy.linalg.eigh(K, M, subset_by_index=(0, count - 1))
        columns.append(vectors)
    stacked = np.hstack(columns)
    K = reference.stiffness[np.ix_(inner, inner)]
    M = reference.mass[np.ix_(inner, inner)]
    # Rayleigh–Ritz on the span, dropping directions the stack repeats.
    gram = stacked.T @ M @ stacked
    eigval, eigvec = np.linalg.eigh(gram)
    keep = eigval > 1e-10 * eigval.max()
    orth = stacked @ (eigvec[:, keep] / np.sqrt(eigval[keep]))
    _, ritz = scipy.linalg.eigh(orth.T @ K @ orth, orth.T @ M @ orth)
    basis = orth @ ritz
    dofs = np.zeros((n_dof, basis.shape[1]))
    dofs[inner] = basis
    return NodalShapes(reference.nodes, dofs)


@dataclass(frozen=True)
class Plant:
    """Reduced matrices of one configuration of the plant (see module docstring)."""

    basis: NodalShapes
    clamped: bool  # θ ≡ 0 (fixed bearing) instead of a free rotation about D
    mass: np.ndarray  # (n, n), n = 1 + modes: [θ, q]
    inverse_mass: np.ndarray  # (n, n): of ``mass`` (pinned), or of the q block alone (clamped, θ̈ = 0)
    bending: np.ndarray  # (m, m) K_b at the reference temperature
    tension: np.ndarray  # (m, m) K_g per unit effective gravity
    centrifugal: np.ndarray  # (m, m) K_c per unit θ̇²
    first_moment: float  # S_D (kg·m)
    modal_first_moment: np.ndarray  # c (m,)
    damping: np.ndarray  # (n, n)
    gravity: float  # g_η: gravity's component along inertial η (+g hanging, −g standing), m/s²
    friction_torque: float  # Coulomb torque of the bearing (N·m)
    friction_smoothing: float  # rate (rad/s) over which the friction torque builds up
    temperature_coefficient: float
    reference_temperature: float
    linear_frequencies_hz: np.ndarray
    modal_damping: np.ndarray

    @property
    def size(self) -> int:
        return self.mass.shape[0]

    def youngs_factor(self, temperature_c: np.ndarray) -> np.ndarray:
        return 1.0 + self.temperature_coefficient * (np.asarray(temperature_c) - self.reference_temperature)


def _axial_gravity(model: BeamModel) -> float:
    """g_η: the plant's gravity along inertial η, from where the beam points (module docstring)."""
    orientation = model.rig.orientation
    if orientation == "hanging":
        return model.rig.gravity
    if orientation == "standing":
        return -model.rig.gravity
    raise ValueError(f"{orientation=} must be 'hanging' or 'standing'")


def _is_clamped(model: BeamModel) -> bool:
    support = model.rig.support
    if support not in ("pinned", "clamped"):
        raise ValueError(f"{support=} must be 'pinned' or 'clamped'")
    return support == "clamped"


def build_plant(
    model: BeamModel,
    basis: NodalShapes,
    *,
    damping_ratios: np.ndarray,
    friction_torque: float = 0.0,
    friction_smoothing: float = 2e-3,
) -> Plant:
    """Reduce ``model`` onto [θ, basis] and add modal damping ``damping_ratios`` (one per mode, the
    last value repeats for higher modes).

    A pinned support keeps θ free (the modes are those of [θ, q]); a clamped one holds θ ≡ 0
    (the modes are those of q alone, and a bearing friction torque has nothing to act on).
    """
    if np.any(np.asarray(damping_ratios) < 0):
        raise ValueError(f"{damping_ratios=} must be non-negative")
    if friction_torque < 0 or friction_smoothing <= 0:
        raise ValueError(f"{friction_torque=} must be >= 0 and {friction_smoothing=} > 0")
    clamped = _is_clamped(model)
    if clamped and friction_torque > 0:
        raise ValueError(f"{friction_torque=} acts on the pinned bearing's rotation: a clamped support has none")
    phi = basis.dofs
    rigid = model.rigid_rotation()
    translation = model.uniform_translation()
    T = np.column_stack([rigid, phi])
    M = T.T @ model.mass @ T
    M = 0.5 * (M + M.T)
    m_trans = model.mass - model.rotary_mass
    bending = phi.T @ model.bending_stiffness @ phi
    tension = phi.T @ model.tension_stiffness @ phi
    centrifugal = phi.T @ (model.centrifugal_stiffness - m_trans) @ phi
    c = phi.T @ model.mass @ translation
    first_moment = float(rigid @ model.mass @ translation)
    g = _axial_gravity(model)
    n = T.shape[1]
    K_lin = np.zeros((n, n))
    K_lin[0, 0] = g * first_moment
    K_lin[0, 1:] = K_lin[1:, 0] = g * c
    K_lin[1:, 1:] = bending + g * tension
    K_lin = 0.5 * (K_lin + K_lin.T)
    free = slice(1, n) if clamped else slice(0, n)  # the clamp removes θ
    K_free, M_free = K_lin[free, free], M[free, free]
    eigval, vectors = scipy.linalg.eigh(K_free, M_free)
    if eigval[0] < -1e-9 * np.abs(eigval).max():
        raise ValueError("the linearised plant is unstable (a negative eigenvalue): check gravity and support")
    omega = np.sqrt(np.clip(eigval, 0.0, None))  # a pinned beam without gravity keeps a zero-frequency rotation
    ratios = np.asarray(damping_ratios, dtype=float)
    m = omega.size
    zeta = np.concatenate([ratios, np.full(max(0, m - ratios.size), ratios[-1])])[:m]
    damping = np.zeros((n, n))
    damping[free, free] = M_free @ vectors @ np.diag(2.0 * zeta * omega) @ vectors.T @ M_free
    inverse = np.zeros((n, n))
    inverse[free, free] = np.linalg.inv(M_free)
    beam = model.rig.beam
    return Plant(
        basis=basis,
        clamped=clamped,
        mass=M,
        inverse_mass=inverse,
        bending=bending / beam.stiffness_factor_at(model.temperature_c),
        tension=tension,
        centrifugal=centrifugal,
        first_moment=first_moment,
        modal_first_moment=c,
        damping=0.5 * (damping + damping.T),
        gravity=g,
        friction_torque=float(friction_torque),
        friction_smoothing=float(friction_smoothing),
        temperature_coefficient=beam.youngs_modulus_temperature_coefficient,
        reference_temperature=beam.reference_temperature,
        linear_frequencies_hz=omega / (2 * np.pi),
        modal_damping=zeta,
    )


# Reassociation lets the compiler vectorize the short dot products below (the sums' order is the
# only freedom taken: no assumption about NaN or infinity, which stay visible in the output).
_FAST = {"reassoc", "contract"}


@numba.njit(cache=True, nogil=True, fastmath=_FAST)
def _acceleration(y, yd, ddot, kappa, mf, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, out):
    """ÿ of the plant into ``out``: M⁻¹ times the generalized forces minus damping, gravity along
    and across the beam, the stiffness of bending (temperature factor kappa), of the axial load and
    of the centrifugal field, and bearing friction on θ. M⁻¹ is folded into the matrices once per
    block (``_folded``): ``mf`` = M⁻¹F of the sample, AC = M⁻¹C, AK* = M⁻¹[:, q] K*, u0 = M⁻¹[:, θ],
    ug = M⁻¹ [S_D, c], so one call costs n² + 3nm products instead of 2n² + 3m²."""
    theta = y[0]
    omega = yd[0]
    ct = np.cos(theta)
    st = np.sin(theta)
    g_axial = g * ct - ddot * st
    g_lateral = ddot * ct + g * st
    n = y.shape[0]
    m = n - 1
    cq = 0.0
    for i in range(m):
        cq += c[i] * y[1 + i]
    s0 = g_axial * cq + Tc * np.tanh(omega / Ws)
    w2 = omega * omega
    for i in range(n):
        damp = 0.0
        for j in range(n):
            damp += AC[i, j] * yd[j]
        kb = 0.0
        kg = 0.0
        kc = 0.0
        for j in range(m):
            qj = y[1 + j]
            kb += AKb[i, j] * qj
            kg += AKg[i, j] * qj
            kc += AKc[i, j] * qj
        out[i] = mf[i] - damp - kappa * kb - g_axial * kg - w2 * kc - g_lateral * ug[i] - s0 * u0[i]


@numba.njit(cache=True, nogil=True, fastmath=_FAST)
def _integrate(y0, yd0, ddot_fine, kappa, mf, substeps, h, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, out_y, out_yd, out_ydd):
    # Classical RK4 on preallocated state vectors (no allocation per stage), without the GIL:
    # the simulations of a fleet integrate side by side on every core.
    n_samples = out_y.shape[0]
    n = y0.shape[0]
    y = y0.copy()
    yd = yd0.copy()
    y2 = np.empty(n)
    yd2 = np.empty(n)
    y3 = np.empty(n)
    yd3 = np.empty(n)
    y4 = np.empty(n)
    yd4 = np.empty(n)
    k1a = np.empty(n)
    k2a = np.empty(n)
    k3a = np.empty(n)
    k4a = np.empty(n)
    for k in range(n_samples):
        out_y[k] = y
        out_yd[k] = yd
        f = mf[k]
        kk = kappa[k]
        _acceleration(y, yd, ddot_fine[2 * substeps * k], kk, f, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, out_ydd[k])
        for s in range(substeps):
            base = 2 * (substeps * k + s)
            a0 = ddot_fine[base]
            a1 = ddot_fine[base + 1]
            a2 = ddot_fine[base + 2]
            _acceleration(y, yd, a0, kk, f, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, k1a)
            for i in range(n):
                y2[i] = y[i] + 0.5 * h * yd[i]
                yd2[i] = yd[i] + 0.5 * h * k1a[i]
            _acceleration(y2, yd2, a1, kk, f, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, k2a)
            for i in range(n):
                y3[i] = y[i] + 0.5 * h * yd2[i]
                yd3[i] = yd[i] + 0.5 * h * k2a[i]
            _acceleration(y3, yd3, a1, kk, f, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, k3a)
            for i in range(n):
                y4[i] = y[i] + h * yd3[i]
                yd4[i] = yd[i] + h * k3a[i]
            _acceleration(y4, yd4, a2, kk, f, AC, AKb, AKg, AKc, u0, ug, c, g, Tc, Ws, k4a)
            for i in range(n):
                y[i] = y[i] + h / 6.0 * (yd[i] + 2.0 * yd2[i] + 2.0 * yd3[i] + yd4[i])
                yd[i] = yd[i] + h / 6.0 * (k1a[i] + 2.0 * k2a[i] + 2.0 * k3a[i] + k4a[i])
    return y, yd


def _folded(plant: Plant) -> tuple[np.ndarray, ...]:
    """The plant's matrices with M⁻¹ applied (``_acceleration``), C-contiguous."""
    Minv = plant.inverse_mass
    Mq = Minv[:, 1:]
    ug = plant.first_moment * Minv[:, 0] + Mq @ plant.modal_first_moment
    return tuple(np.ascontiguousarray(a, dtype=float) for a in (
        Minv @ plant.damping, Mq @ plant.bending, Mq @ plant.tension, Mq @ plant.centrifugal, Minv[:, 0], ug))


def integrate(
    plant: Plant,
    y0: np.ndarray,
    yd0: np.ndarray,
    bearing_acceleration_fine: np.ndarray,
    temperature_c: np.ndarray,
    generalized_force: np.ndarray,
    *,
    sample_period: float,
    substeps: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate the plant over len(temperature_c) samples with classical Runge–Kutta.

    ``bearing_acceleration_fine`` holds d̈ on the half-step grid (2·substeps·samples + 1 values,
    starting at the first sample); temperature and the generalized force (samples, n) are held
    over each sample period. Returns y, ẏ, ÿ at the samples (samples, n) and the state after the
    last sample (y, ẏ).
    """
    n_samples = len(temperature_c)
    n = plant.size
    if bearing_acceleration_fine.shape != (2 * substeps * n_samples + 1,):
        raise ValueError(f"bearing_acceleration_fine has shape {bearing_acceleration_fine.shape}, "
                         f"expected ({2 * substeps * n_samples + 1},)")
    if generalized_force.shape != (n_samples, n):
        raise ValueError(f"generalized_force has shape {generalized_force.shape}, expected ({n_samples}, {n})")
    out_y = np.empty((n_samples, n))
    out_yd = np.empty((n_samples, n))
    out_ydd = np.empty((n_samples, n))
    kappa = plant.youngs_factor(temperature_c).astype(float)
    AC, AKb, AKg, AKc, u0, ug = _folded(plant)
    mf = np.ascontiguousarray(np.asarray(generalized_force, float) @ plant.inverse_mass.T)  # M⁻¹F, held over each sample
    y_end, yd_end = _integrate(
        np.asarray(y0, float), np.asarray(yd0, float), np.ascontiguousarray(bearing_acceleration_fine, float),
        kappa, mf, int(substeps), sample_period / substeps, AC, AKb, AKg, AKc, u0, ug,
        np.ascontiguousarray(plant.modal_first_moment, float), plant.gravity,
        plant.friction_torque, plant.friction_smoothing, out_y, out_yd, out_ydd,
    )
    return out_y, out_yd, out_ydd, y_end, yd_end
