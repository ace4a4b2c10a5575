"""The planar IMMS kinematics (Eq. 4–9), aiding equations (Eq. 13–22) and the event loop.

Everything here is compiled with numba and works on plain arrays; ``_filter.py`` holds the
Python-facing class. Frames and signs follow the recording contract (see planar-imms.md).

State layout (``x``): ``contract.StateLayout``, read through its ``StateIndex`` (no offset is
written here)::

    gyro: [d, h, ḋ, ḣ, φ, b_1..b_Γ, r_1..r_R, ṙ_1..ṙ_R, β_1..β_ν, β_D]
    acc:  [d, h, ḋ, ḣ, φ, b_1..b_Γ, r_1..r_R, v_1..v_Γ, ṙ_1..ṙ_R, β_D]

Residual modes r (R ≥ 0, the eigenmodes after the Γ unit deformations, for a support that does
not turn) are carried with their FE dynamics, r̈ + 2ζω ṙ + ω² r = −p·a_D (p the participation of
the support's lateral acceleration a_D), integrated exactly over each step. Their share of the
peripheral readings (S_r ṙ of the gyros, S_r r̈ of the accelerometers) is taken out before the
least squares for b, so a driven mode the unit deformations do not cover does not alias into b;
the aiding equations see b and r alike (one modal block of Γ + R).

β_D is the bias of the gyroscope at D and β_j those of the peripheral gyroscopes (random walks:
what the rest phase cannot calibrate, the wander of low-cost MEMS, goes straight into ḃ). For accelerometers the velocity state is
v = ḃ + c·ω_D with c = S⁺η: Eq. (8) contains ω̇·η_j with ω̇ the numerical derivative of ω_D,
and integrating that term once gives exactly c·(ω_D,k − ω_D,k−1). Carrying v keeps the
differentiated gyro noise what it is — a difference of two samples, not white noise of
1/dt size — and ḃ = v − c·ω_D is reported. A layout without an attitude state (φ ≡ 0) has
neither φ nor β_D; the kernels then read φ = 0 and ω = 0 (the gyro at D is not used: a clamp
does not turn) and write no entry of theirs. Gravity is g_η along inertial η (+g for a hanging
beam, −g for a standing one), so the model holds for both orientations.

Events (``kind``): 0 IMU at D, 1 peripheral IMU, 2 ToF, 3 strain gauge, 4 bearing displacement.
IMU values are [f_x, f_y, ω_z] in the sensor frame; the others carry their value in column 0.

A biaxial beam (``StateIndex.gamma_xi`` > 0, clamped) carries its ξ plane in the same state
(bξ, rξ right after b, r; vξ, ṙξ and the gyro-y biases beside their ζ twins): IMU values are then
[f_x, f_y, ω_z, f_z, ω_y]; accel z relates to Δξ as accel y to Δζ and gyro y is minus the ξ
tangent's rate (``_propagate_xi_into``); a gauge's row covers both modal blocks (ε = −(ζp κζ + ξp κξ)).

The event loop takes named structures (numba-compiled namedtuples), not long positional lists:
``EventArrays`` (the batch), ``ModelArrays`` (the model, calibration and tuning: read only),
``FilterState`` (the state and the held inputs: updated in place), ``FilterOutputs`` (the
states at the D samples) and ``AidingCounters`` (per-channel counters: updated in place).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from contract import StateIndex

from ._ekf import predict_covariance_into, update_scalar_into

__all__ = [
    "EVENT_BEARING",
    "EVENT_IMU_D",
    "EVENT_IMU_PERIPHERAL",
    "EVENT_STRAIN",
    "EVENT_TOF",
    "KIND_ACC",
    "KIND_GYRO",
    "AidingCounters",
    "EventArrays",
    "FilterOutputs",
    "FilterParams",
    "FilterState",
    "LeastSquares",
    "ModelArrays",
    "input_weights",
    "least_squares_map",
    "propagate",
    "propagate_into",
    "run_events",
    "tip_variance",
    "tof_measurement",
    "tof_measurement_into",
]

KIND_GYRO = 0
KIND_ACC = 1
EVENT_IMU_D, EVENT_IMU_PERIPHERAL, EVENT_TOF, EVENT_STRAIN, EVENT_BEARING = 0, 1, 2, 3, 4


class FilterParams(NamedTuple):
    """Scalar tuning and rig constants of the loop (SI units; variances in the unit squared)."""

    gravity_eta: float  # m/s², gravity along inertial η: +g hanging, −g standing (η up the beam)
    reflector_distance: float  # m
    gate: float  # innovation gate, squared Mahalanobis distance
    stale_after: float  # s
    sigma_f_d_x: float  # m/s², noise of the D accelerometer
    sigma_f_d_y: float
    sigma_omega_d: float  # rad/s
    q_b: float
    q_v: float
    q_beta: float
    q_rigid: float
    bearing_var: float  # m²
    pseudo_h_var: float  # m²
    pseudo_h_rate_var: float  # m²/s²
    max_step: float  # s
    q_null: float
    q_beta_peripheral: float
    q_residual: float  # random walk of the residual modes' rates (model error of their dynamics), 1/s³
    bearing_gate: float  # gate of the bearing channel: ``gate`` for a sensor, 1e300 for the fixed support's d = 0
    sigma_f_d_z: float = 0.0  # m/s², noise of the D accelerometer's z axis (a biaxial beam's ξ support acceleration)


class ModelArrays(NamedTuple):
    """What the loop reads and never changes: layout, configuration, calibration, tuning.

    Shapes: ν peripheral IMUs, Γ unit deformations, T ToFs, G gauges. bias_D (3,) and bias_j
    (ν, 3) as [f_x, f_y, ω_z]; imu_eta (ν,); imu_S, imu_S1 (ν, Γ) shape and slope at the IMUs;
    sig_fj (ν, 2), sig_wj (ν,) noise; tof_eta (T,), tof_S, tof_S1 (T, Γ), tof_offset, tof_var (T,);
    strain_K (G, Γ) of Eq. (19), strain_offset, strain_var (G,); aided (Γ,) 1 for unit
    deformations the gauges aid; tip_row (Γ,) = s(L). The modal block has Γ + R columns (b, then
    the R residual modes) in imu_S, imu_S1, tof_S, tof_S1, strain_K, aided and tip_row.
    strain_pair (G, K): the strain the combimode cannot represent of each of the K = 2 modes it
    merges, per unit b_1 (K = 0 without a combimode): the gauges taken at one time share the model
    error Σ_k ψ_k strain_pair[:, k] b_1, ψ_k ~ N(0, 1) (a correlated error, not one per gauge); res_omega,
    res_damping, res_participation (R,) are the residual modes' ω (rad/s), damping ratio and
    participation p of the support's lateral acceleration.

    A biaxial beam (``index.gamma_xi`` > 0) adds its ξ plane: imu_S_xi, imu_S1_xi (ν, Γξ + Rξ) the ξ
    shapes and slopes at the IMUs, sig_xi (ν, 2) the noise of accel z and gyro y; the residual
    arrays hold the R ζ modes, then the Rξ ξ modes (driven by the support's ξ acceleration, accel z
    at D); strain_K and aided have Γ + R + Γξ + Rξ columns (a gauge at θ sees both planes). A planar
    model has zero-width ξ arrays.
    """

    index: StateIndex
    kind: int  # KIND_GYRO | KIND_ACC
    params: FilterParams
    bias_D: np.ndarray
    bias_j: np.ndarray
    imu_eta: np.ndarray
    imu_S: np.ndarray
    imu_S1: np.ndarray
    sig_fj: np.ndarray
    sig_wj: np.ndarray
    tof_eta: np.ndarray
    tof_S: np.ndarray
    tof_S1: np.ndarray
    tof_offset: np.ndarray
    tof_var: np.ndarray
    strain_K: np.ndarray
    strain_offset: np.ndarray
    strain_var: np.ndarray
    aided: np.ndarray
    tip_row: np.ndarray
    strain_pair: np.ndarray
    res_omega: np.ndarray
    res_damping: np.ndarray
    res_participation: np.ndarray
    imu_S_xi: np.ndarray
    imu_S1_xi: np.ndarray
    sig_xi: np.ndarray


class EventArrays(NamedTuple):
    """A batch of events in time order: t (N,) s, kind (N,) event code, index (N,) sensor,
    values (N, 3) (a biaxial model's (N, 5): IMUs [f_x, f_y, ω_z, f_z, ω_y]); next_d (N,) the index of the first D-IMU event at or after each (−1: none)."""

    t: np.ndarray
    kind: np.ndarray
    index: np.ndarray
    values: np.ndarray
    next_d: np.ndarray


class FilterState(NamedTuple):
    """The filter between batches, updated in place: x (n,), P (n, n); clock = [t_now, held_t,
    prev_t] (s: the filter's time, the time of the held D sample, that of the sample before it;
    NaN: none); the held inputs held_fD (2,), held_wD (1,), held_fj (ν, 2), held_wj (ν,) and the
    ones before them prev_fD, prev_wD, prev_fj, prev_wj (same shapes); held_real (1,) the held
    inputs are a sample (not the initial rest guess); last_seen (ν,) s; active (ν,) peripheral IMUs in
    the solution; pending (1,) a D sample whose state is not output yet. A biaxial model holds its ξ
    inputs beside the ζ ones: held_fD (3,) [f_x, f_y, f_z], held_fj (ν, 4) [f_x, f_y, f_z, ω_y]."""

    x: np.ndarray
    P: np.ndarray
    clock: np.ndarray
    held_fD: np.ndarray
    held_wD: np.ndarray
    held_fj: np.ndarray
    held_wj: np.ndarray
    prev_fD: np.ndarray
    prev_wD: np.ndarray
    prev_fj: np.ndarray
    prev_wj: np.ndarray
    held_real: np.ndarray
    last_seen: np.ndarray
    active: np.ndarray
    pending: np.ndarray


class FilterOutputs(NamedTuple):
    """Buffers of the states at the D samples: t (M,), x (M, n), P (M, n) diagonal, var_e (M,)."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    var_e: np.ndarray


class AidingCounters(NamedTuple):
    """Per aiding channel [ToF..., strain..., bearing, pseudo h, pseudo ḣ]: accepted, rejected,
    nis_sum, last_innovation; degraded_time (ν,) s each peripheral IMU was out of the solution."""

    accepted: np.ndarray
    rejected: np.ndarray
    nis_sum: np.ndarray
    last_innovation: np.ndarray
    degraded_time: np.ndarray


class LeastSquares(NamedTuple):
    """The least-squares map of the active peripheral IMUs: Pinv (Γ, ν) = S⁺ (zero columns for
    inactive sensors), null_proj (Γ, Γ) the projector on what they cannot see, c_acc (Γ,) = S⁺η,
    c_res (Γ, R) = S⁺ S_r, what the residual modes' readings add to the solution. The ξ plane's
    Pinv_xi (Γξ, ν), null_proj_xi (Γξ, Γξ) and c_res_xi (Γξ, Rξ) likewise (zero-size when planar)."""

    Pinv: np.ndarray
    null_proj: np.ndarray
    c_acc: np.ndarray
    c_res: np.ndarray
    Pinv_xi: np.ndarray
    null_proj_xi: np.ndarray
    c_res_xi: np.ndarray


@numba.njit(cache=True, inline="always")
def input_weights(tau, t_prev, t_held, t_next):
    """Weights (w_prev, w_held, w_next) of three input samples for their value at ``tau`` (s),
    clipped to [t_held, t_next] (t_next > t_held): the quadratic through the samples at t_prev,
    t_held and t_next where the previous sample is there (t_prev finite) and spaced like the
    others (within a factor 2), else the straight line between held and next (w_prev = 0).

    The line's value half way between 200 Hz samples falls short of a sinusoid's by (ω dt)²/8,
    and the accelerometers' tilt feedback (g·α_j on the estimated b, unstable without aiding)
    amplifies that shortfall: a swing in mode 2 integrated over two periods from the true state
    drifts by 0.37 % with the line, by 0.001 % with the quadratic (the state's midpoint rule
    then leaves 0.2 %). The quadratic uses only samples already received: no added delay.
    """
    tau = min(max(tau, t_held), t_next)
    h1 = t_next - t_held
    h0 = t_held - t_prev
    if h0 > 0.0 and h0 <= 2.0 * h1 and h1 <= 2.0 * h0:
        w_prev = (tau - t_held) * (tau - t_next) / ((t_prev - t_held) * (t_prev - t_next))
        w_held = (tau - t_prev) * (tau - t_next) / ((t_held - t_prev) * (t_held - t_next))
        w_next = (tau - t_prev) * (tau - t_held) / ((t_next - t_prev) * (t_next - t_held))
        return w_prev, w_held, w_next
    w = (tau - t_held) / h1
    return 0.0, 1.0 - w, w


@numba.njit(cache=True, inline="always")
def _residual_modes_into(m, x, dt, a_lat, first, count, i_r, i_vr, column, xn, F, Q, Gm, res_ws):
    """The ``count`` residual modes from entry ``first`` of the model's residual arrays (states at
    ``i_r``, rates at ``i_vr``) over dt: r̈ + 2ζω ṙ + ω² r = −p a_lat, exactly for the held lateral
    acceleration ``a_lat`` of the support (input column ``column`` of Gm); what the least squares
    needs of the step goes into rows first.. of ``res_ws``."""
    p = m.params
    for i in range(count):
        w = m.res_omega[first + i]
        zeta = m.res_damping[first + i]
        part = m.res_participation[first + i]
        sigma = zeta * w
        wd = w * np.sqrt(1.0 - zeta * zeta)
        decay = np.exp(-sigma * dt)
        c, s = np.cos(wd * dt), np.sin(wd * dt)
        f00 = decay * (c + sigma / wd * s)
        f01 = decay * s / wd
        f10 = -decay * w * w * s / wd
        f11 = decay * (c - sigma / wd * s)
        static = -part * a_lat / (w * w)  # the deflection the acceleration holds
        r0, v0 = x[i_r + i], x[i_vr + i]
        r1 = f00 * (r0 - static) + f01 * v0 + static
        v1 = f10 * (r0 - static) + f11 * v0
        xn[i_r + i] = r1
        xn[i_vr + i] = v1
        F[i_r + i, i_r + i] = f00
        F[i_r + i, i_vr + i] = f01
        F[i_vr + i, i_r + i] = f10
        F[i_vr + i, i_vr + i] = f11
        dr_da = -part * (1.0 - f00) / (w * w)
        dv_da = part * f10 / (w * w)
        Gm[i_r + i, column] = dr_da
        Gm[i_vr + i, column] = dv_da
        Q[i_vr + i, i_vr + i] += p.q_residual * dt
        row = first + i
        res_ws[row, 0] = f00 - 1.0
        res_ws[row, 1] = f01
        res_ws[row, 2] = f10
        res_ws[row, 3] = f11 - 1.0
        res_ws[row, 4] = r1 - r0  # ∫ṙ over the step
        res_ws[row, 5] = v1 - v0  # ∫r̈ over the step
        res_ws[row, 6] = dr_da
        res_ws[row, 7] = dv_da


@numba.njit(cache=True, inline="always")
def propagate_into(m, x, dt, fD, omegaD, fj, omegaj, active, lsq, xn, F, Q, Gm, sig, acc_ws, res_ws):
    """Propagate x over dt with the given inputs into the buffers xn (n,), F (n, n), Q (n, n).

    ``m`` is the ``ModelArrays``; fD (2,), omegaD: bias-corrected inputs at D; fj (ν, 2),
    omegaj (ν,): bias-corrected peripheral inputs of the ``active`` (ν,) sensors, whose
    ``LeastSquares`` map is ``lsq``. Gm (n, n_in), sig (n_in,), acc_ws (Γ, Γ + R + 2) and res_ws
    (R, 8) are scratch buffers (n_in = 3 + ν for gyro, 3 + 2ν for acc).
    """
    ix = m.index
    p = m.params
    gamma = ix.gamma  # unit deformations: what the least squares solves for
    n_res = ix.residual
    n_modal = gamma + n_res  # b and r: the modal amplitudes the readings see
    n = x.shape[0]
    g = p.gravity_eta
    i_phi, i_bd, i_b = ix.phi, ix.bias_d, ix.b
    # Fields read into locals once: each access of a structure's array field in a loop costs a
    # reference count (atomic) in compiled code.
    imu_S, imu_S1, sig_fj, sig_wj = m.imu_S, m.imu_S1, m.sig_fj, m.sig_wj
    Pinv, c_acc, null_proj, c_res = lsq.Pinv, lsq.c_acc, lsq.null_proj, lsq.c_res
    phi = x[i_phi] if i_phi >= 0 else 0.0
    # Without an attitude state the support fixes φ ≡ 0, so ω ≡ 0 exactly: the gyro at D would
    # only add its noise and bias wander to ḃ.
    omega = (omegaD - (x[i_bd] if i_bd >= 0 else 0.0)) if i_phi >= 0 else 0.0
    cp, sp = np.cos(phi), np.sin(phi)
    for i in range(n):
        xn[i] = x[i]
        for j in range(n):
            F[i, j] = 0.0
            Q[i, j] = 0.0
        F[i, i] = 1.0
    n_in = sig.shape[0]
    for i in range(n):
        for j in range(n_in):
            Gm[i, j] = 0.0
    for j in range(n_in):
        sig[j] = 0.0
    # Rigid part: inertial acceleration of D from its specific force (gravity g_η along η).
    i_d, i_h, i_dr, i_hr = ix.d, ix.h, ix.d_rate, ix.h_rate
    acc_h = cp * fD[0] - sp * fD[1] + g
    acc_d = sp * fD[0] + cp * fD[1]
    dacc_h = -sp * fD[0] - cp * fD[1]
    dacc_d = cp * fD[0] - sp * fD[1]
    half = 0.5 * dt * dt
    xn[i_d] = x[i_d] + dt * x[i_dr] + half * acc_d
    xn[i_h] = x[i_h] + dt * x[i_hr] + half * acc_h
    xn[i_dr] = x[i_dr] + dt * acc_d
    xn[i_hr] = x[i_hr] + dt * acc_h
    F[i_d, i_dr] = dt
    F[i_h, i_hr] = dt
    if i_phi >= 0:
        xn[i_phi] = phi + dt * omega
        F[i_d, i_phi] = half * dacc_d
        F[i_h, i_phi] = half * dacc_h
        F[i_dr, i_phi] = dt * dacc_d
        F[i_hr, i_phi] = dt * dacc_h
        if i_bd >= 0:
            F[i_phi, i_bd] = -dt
        Gm[i_phi, 2] = dt
    nu = fj.shape[0]
    sig[0] = p.sigma_f_d_x
    sig[1] = p.sigma_f_d_y
    sig[2] = p.sigma_omega_d if i_phi >= 0 else 0.0
    Gm[i_d, 0] = half * sp
    Gm[i_d, 1] = half * cp
    Gm[i_h, 0] = half * cp
    Gm[i_h, 1] = -half * sp
    Gm[i_dr, 0] = dt * sp
    Gm[i_dr, 1] = dt * cp
    Gm[i_hr, 0] = dt * cp
    Gm[i_hr, 1] = -dt * sp
    # Residual modes: r̈ + 2ζω ṙ + ω² r = −p a_D over the step, a_D = f_D,y (held constant), exactly.
    i_r, i_vr = i_b + gamma, ix.residual_rate
    _residual_modes_into(m, x, dt, fD[1], 0, n_res, i_r, i_vr, 1, xn, F, Q, Gm, res_ws)
    if m.kind == KIND_GYRO:
        # Eq. (9): ω_j − ω_D = Σ ḃ s'_χ(η_j), solved in the least-squares sense.
        ibj = ix.peripheral_bias
        for k in range(gamma):
            bdot = 0.0
            row_sum = 0.0
            for j in range(nu):
                if active[j]:
                    bdot += Pinv[k, j] * (omegaj[j] - x[ibj + j] - omega)
                row_sum += Pinv[k, j]
                Gm[i_b + k, 3 + j] = dt * Pinv[k, j]
                F[i_b + k, ibj + j] = -dt * Pinv[k, j]
            xn[i_b + k] = x[i_b + k] + dt * bdot
            if i_bd >= 0:
                F[i_b + k, i_bd] = dt * row_sum
            Gm[i_b + k, 2] = -dt * row_sum
            # The residual modes turn the gyros by s'_r ṙ: their share, integrated, is Δr.
            for i in range(n_res):
                cr = c_res[k, i]
                xn[i_b + k] -= cr * res_ws[i, 4]
                F[i_b + k, i_r + i] -= cr * res_ws[i, 0]
                F[i_b + k, i_vr + i] -= cr * res_ws[i, 1]
                Gm[i_b + k, 1] -= cr * res_ws[i, 6]
            Q[i_b + k, i_b + k] += p.q_b * dt
        for j in range(nu):
            sig[3 + j] = sig_wj[j]
            Q[ibj + j, ibj + j] += p.q_beta_peripheral * dt
    else:
        # Eq. (8) per sensor: Δ̈_j = f_j,ζ − f_D,ζ − ω̇ η_j + ω² Δ_j with f_j,ζ = sin α_j f_j,x + cos α_j f_j,y.
        iv = ix.v
        for k in range(gamma):
            for mm in range(n_modal + 2):
                acc_ws[k, mm] = 0.0  # [dB (Γ + R) | b̈ | ∂b̈/∂β_D]
        w2 = omega * omega
        for j in range(nu):
            if not active[j]:
                continue
            alpha = 0.0
            delta = 0.0
            for k in range(n_modal):
                # The tilt g·α_j is as large as the elastic acceleration: taken at the step's start it
                # would lag by half a step (dt/2 = 2.5 ms, a 0.5 % error of e at the second mode), so
                # α and Δ are taken at the midpoint, like the inputs.
                rate = (x[iv + k] - c_acc[k] * omega) if k < gamma else x[i_vr + k - gamma]
                b_mid = x[i_b + k] + 0.5 * dt * rate
                alpha += imu_S1[j, k] * b_mid
                delta += imu_S[j, k] * b_mid
            ca, sa = np.cos(alpha), np.sin(alpha)
            ddelta = sa * fj[j, 0] + ca * fj[j, 1] - fD[1] + w2 * delta
            tilt = ca * fj[j, 0] - sa * fj[j, 1]
            dbeta = -2.0 * omega * delta
            sig[3 + 2 * j] = sig_fj[j, 0]
            sig[4 + 2 * j] = sig_fj[j, 1]
            for k in range(gamma):
                pk = Pinv[k, j]
                acc_ws[k, n_modal] += pk * ddelta
                acc_ws[k, n_modal + 1] += pk * dbeta
                for mm in range(n_modal):
                    acc_ws[k, mm] += pk * (tilt * imu_S1[j, mm] + w2 * imu_S[j, mm])
                Gm[iv + k, 3 + 2 * j] = dt * pk * sa
                Gm[iv + k, 4 + 2 * j] = dt * pk * ca
        for k in range(gamma):
            v = x[iv + k]
            bddot = acc_ws[k, n_modal]
            xn[i_b + k] = x[i_b + k] + dt * (v - c_acc[k] * omega) + half * bddot
            xn[iv + k] = v + dt * bddot
            F[i_b + k, iv + k] += dt
            if i_bd >= 0:
                F[i_b + k, i_bd] = dt * c_acc[k] + half * acc_ws[k, n_modal + 1]
                F[iv + k, i_bd] = dt * acc_ws[k, n_modal + 1]
            for mm in range(n_modal):
                F[i_b + k, i_b + mm] += half * acc_ws[k, mm]
                F[iv + k, i_b + mm] += dt * acc_ws[k, mm]
                # ... and through the midpoint on the rates (v − c ω, ṙ) the tilt is taken at.
                if mm < gamma:
                    F[i_b + k, iv + mm] += half * acc_ws[k, mm] * 0.5 * dt
                    F[iv + k, iv + mm] += dt * acc_ws[k, mm] * 0.5 * dt
                    if i_bd >= 0:
                        F[i_b + k, i_bd] += half * acc_ws[k, mm] * 0.5 * dt * c_acc[mm]
                        F[iv + k, i_bd] += dt * acc_ws[k, mm] * 0.5 * dt * c_acc[mm]
                else:
                    F[i_b + k, i_vr + mm - gamma] += half * acc_ws[k, mm] * 0.5 * dt
                    F[iv + k, i_vr + mm - gamma] += dt * acc_ws[k, mm] * 0.5 * dt
            # The residual modes move the accelerometers by s_r r̈: their share, integrated once
            # (Δṙ) for v and twice (Δr − dt ṙ) for b.
            for i in range(n_res):
                cr = c_res[k, i]
                xn[i_b + k] -= cr * (res_ws[i, 4] - dt * x[i_vr + i])
                xn[iv + k] -= cr * res_ws[i, 5]
                F[i_b + k, i_r + i] -= cr * res_ws[i, 0]
                F[i_b + k, i_vr + i] -= cr * (res_ws[i, 1] - dt)
                F[iv + k, i_r + i] -= cr * res_ws[i, 2]
                F[iv + k, i_vr + i] -= cr * res_ws[i, 3]
                Gm[i_b + k, 1] -= cr * res_ws[i, 6]
                Gm[iv + k, 1] -= cr * res_ws[i, 7]
            Gm[i_b + k, 2] = -dt * c_acc[k]
            row_sum = 0.0
            for j in range(nu):
                row_sum += Pinv[k, j]
            # f_D,y enters every Δ̈_j with −1.
            Gm[iv + k, 1] += -dt * row_sum
            Q[i_b + k, i_b + k] += p.q_b * dt
            Q[iv + k, iv + k] += p.q_v * dt
    # Unobservable directions of b (fewer active sensors than Γ) random-walk instead of freezing.
    if p.q_null > 0:
        for k in range(gamma):
            for mm in range(gamma):
                Q[i_b + k, i_b + mm] += p.q_null * dt * null_proj[k, mm]
    if ix.gamma_xi > 0:
        _propagate_xi_into(m, x, dt, fD, fj, active, lsq, xn, F, Q, Gm, sig, acc_ws, res_ws, 3 + (nu if m.kind == KIND_GYRO else 2 * nu))
    for i in range(n_in):
        s2 = sig[i] * sig[i]
        if s2 == 0.0:
            continue
        for a in range(n):
            ga = Gm[a, i]
            if ga == 0.0:
                continue
            for bb in range(n):
                Q[a, bb] += ga * s2 * Gm[bb, i]
    Q[i_dr, i_dr] += p.q_rigid * dt
    Q[i_hr, i_hr] += p.q_rigid * dt
    if i_bd >= 0:
        Q[i_bd, i_bd] += p.q_beta * dt


@numba.njit(cache=True, inline="always")
def _propagate_xi_into(m, x, dt, fD, fj, active, lsq, xn, F, Q, Gm, sig, acc_ws, res_ws, c_fdz):
    """The ξ plane of a biaxial beam over dt, into xn, F, Q and the input map Gm, sig (its columns
    from ``c_fdz``: accel z at D, then per peripheral IMU gyro y (gyro) or accel z (acc)).

    A biaxial beam is clamped, so the body frame does not turn (ω ≡ 0) and D moves along ζ only:
    accel z at D is the support's ξ vibration. Accel z relates to Δξ as accel y to Δζ:
    Δ̈ξ_j = sin αξ_j f_j,x + cos αξ_j f_j,z − f_D,z with αξ_j = Δξ'(η_j); gyro y is minus the
    turn of the ξ tangent: ω_j,y = −Σ ḃξ s'ξ(η_j) (the contract's signs, recording-format.md).
    fD is [f_x, f_y, f_z], fj (ν, 4) [f_x, f_y, f_z, ω_y], bias-corrected.
    """
    ix = m.index
    p = m.params
    gamma = ix.gamma_xi
    n_res = ix.residual_xi
    n_modal = gamma + n_res
    nu = fj.shape[0]
    i_b = ix.b_xi
    i_r, i_vr = i_b + gamma, ix.residual_rate_xi
    S1 = m.imu_S1_xi  # the slopes: gyro y's least squares (its map is lsq's), accel z's tilt
    Pinv, null_proj, c_res = lsq.Pinv_xi, lsq.null_proj_xi, lsq.c_res_xi
    r0 = ix.residual  # the ξ residual modes' rows in the residual arrays and res_ws
    half = 0.5 * dt * dt
    sig[c_fdz] = p.sigma_f_d_z
    _residual_modes_into(m, x, dt, fD[2], r0, n_res, i_r, i_vr, c_fdz, xn, F, Q, Gm, res_ws)
    if m.kind == KIND_GYRO:
        ibj = ix.peripheral_bias_xi
        for k in range(gamma):
            bdot = 0.0
            for j in range(nu):
                if active[j]:
                    bdot -= Pinv[k, j] * (fj[j, 3] - x[ibj + j])
                Gm[i_b + k, c_fdz + 1 + j] = -dt * Pinv[k, j]
                F[i_b + k, ibj + j] = dt * Pinv[k, j]
            xn[i_b + k] = x[i_b + k] + dt * bdot
            for i in range(n_res):
                cr = c_res[k, i]
                xn[i_b + k] -= cr * res_ws[r0 + i, 4]
                F[i_b + k, i_r + i] -= cr * res_ws[r0 + i, 0]
                F[i_b + k, i_vr + i] -= cr * res_ws[r0 + i, 1]
                Gm[i_b + k, c_fdz] -= cr * res_ws[r0 + i, 6]
            Q[i_b + k, i_b + k] += p.q_b * dt
        for j in range(nu):
            sig[c_fdz + 1 + j] = m.sig_xi[j, 1]
            Q[ibj + j, ibj + j] += p.q_beta_peripheral * dt
    else:
        iv = ix.v_xi
        for k in range(gamma):
            for mm in range(n_modal + 1):
                acc_ws[k, mm] = 0.0  # [dB (Γξ + Rξ) | b̈ξ]
        for j in range(nu):
            if not active[j]:
                continue
            alpha = 0.0
            for k in range(n_modal):
                # α at the step's midpoint, as in ζ (the tilt g·α is as large as the elastic acceleration)
                rate = x[iv + k] if k < gamma else x[i_vr + k - gamma]
                alpha += S1[j, k] * (x[i_b + k] + 0.5 * dt * rate)
            ca, sa = np.cos(alpha), np.sin(alpha)
            ddelta = sa * fj[j, 0] + ca * fj[j, 2] - fD[2]
            tilt = ca * fj[j, 0] - sa * fj[j, 2]
            sig[c_fdz + 1 + j] = m.sig_xi[j, 0]
            for k in range(gamma):
                pk = Pinv[k, j]
                acc_ws[k, n_modal] += pk * ddelta
                for mm in range(n_modal):
                    acc_ws[k, mm] += pk * tilt * S1[j, mm]
                Gm[iv + k, 3 + 2 * j] = dt * pk * sa  # accel x: the input the ζ plane reads too
                Gm[iv + k, c_fdz + 1 + j] = dt * pk * ca
        for k in range(gamma):
            v = x[iv + k]
            bddot = acc_ws[k, n_modal]
            xn[i_b + k] = x[i_b + k] + dt * v + half * bddot
            xn[iv + k] = v + dt * bddot
            F[i_b + k, iv + k] += dt
            for mm in range(n_modal):
                F[i_b + k, i_b + mm] += half * acc_ws[k, mm]
                F[iv + k, i_b + mm] += dt * acc_ws[k, mm]
                col = iv + mm if mm < gamma else i_vr + mm - gamma
                F[i_b + k, col] += half * acc_ws[k, mm] * 0.5 * dt
                F[iv + k, col] += dt * acc_ws[k, mm] * 0.5 * dt
            for i in range(n_res):
                cr = c_res[k, i]
                xn[i_b + k] -= cr * (res_ws[r0 + i, 4] - dt * x[i_vr + i])
                xn[iv + k] -= cr * res_ws[r0 + i, 5]
                F[i_b + k, i_r + i] -= cr * res_ws[r0 + i, 0]
                F[i_b + k, i_vr + i] -= cr * (res_ws[r0 + i, 1] - dt)
                F[iv + k, i_r + i] -= cr * res_ws[r0 + i, 2]
                F[iv + k, i_vr + i] -= cr * res_ws[r0 + i, 3]
                Gm[i_b + k, c_fdz] -= cr * res_ws[r0 + i, 6]
                Gm[iv + k, c_fdz] -= cr * res_ws[r0 + i, 7]
            row_sum = 0.0
            for j in range(nu):
                row_sum += Pinv[k, j]
            Gm[iv + k, c_fdz] += -dt * row_sum  # f_D,z enters every Δ̈ξ_j with −1
            Q[i_b + k, i_b + k] += p.q_b * dt
            Q[iv + k, iv + k] += p.q_v * dt
    if p.q_null > 0:
        for k in range(gamma):
            for mm in range(gamma):
                Q[i_b + k, i_b + mm] += p.q_null * dt * null_proj[k, mm]


@numba.njit(cache=True)
def _input_count(m, nu):
    planar = 3 + (nu if m.kind == KIND_GYRO else 2 * nu)
    return planar + (1 + nu if m.index.gamma_xi > 0 else 0)


@numba.njit(cache=True)
def _work_buffers(ix):
    """The scratch buffers acc_ws and res_ws of ``propagate_into`` for state index ``ix`` (sized for
    the larger plane; the ξ residual modes' rows follow the ζ ones)."""
    rows = max(ix.gamma, ix.gamma_xi)
    cols = max(ix.gamma + ix.residual, ix.gamma_xi + ix.residual_xi) + 2
    return np.empty((rows, cols)), np.empty((ix.residual + ix.residual_xi, 8))


@numba.njit(cache=True)
def propagate(m, x, dt, fD, omegaD, fj, omegaj, active, lsq):
    """Pure form of ``propagate_into``: returns (x⁺, F, Q) as new arrays."""
    n = x.shape[0]
    n_in = _input_count(m, fj.shape[0])
    xn = np.empty(n)
    F = np.empty((n, n))
    Q = np.empty((n, n))
    acc_ws, res_ws = _work_buffers(m.index)
    propagate_into(m, x, dt, fD, omegaD, fj, omegaj, active, lsq, xn, F, Q, np.empty((n, n_in)), np.empty(n_in), acc_ws, res_ws)
    return xn, F, Q


@numba.njit(cache=True)
def tip_variance(P, tip_row, b0):
    """Variance of e = Σ b_χ s_χ(L) from the full covariance (off-diagonal terms included); b
    starts at index ``b0`` of the state."""
    gamma = tip_row.shape[0]
    v = 0.0
    for k in range(gamma):
        for mm in range(gamma):
            v += tip_row[k] * P[b0 + k, b0 + mm] * tip_row[mm]
    return v


@numba.njit(cache=True)
def tof_measurement_into(ix, x, eta, S_row, S1_row, d_ref, H):
    """Eq. (18): predicted distance ρ̂ (m) of a ToF at arc length ``eta``; its Jacobian row into H (n,).

    ``ix`` is the state's ``StateIndex``."""
    gamma = S_row.shape[0]
    i_phi, i_b = ix.phi, ix.b
    phi = x[i_phi] if i_phi >= 0 else 0.0
    delta = 0.0
    alpha = 0.0
    for k in range(gamma):
        delta += S_row[k] * x[i_b + k]
        alpha += S1_row[k] * x[i_b + k]
    cp, sp = np.cos(phi), np.sin(phi)
    zeta = x[ix.d] + sp * eta + cp * delta
    phij = phi + alpha
    cj, sj = np.cos(phij), np.sin(phij)
    gap = d_ref - zeta
    for i in range(H.shape[0]):
        H[i] = 0.0
    H[ix.d] = -1.0 / cj
    if i_phi >= 0:
        H[i_phi] = (-(cp * eta - sp * delta) * cj + gap * sj) / (cj * cj)
    for k in range(gamma):
        H[i_b + k] = (-cp * S_row[k] * cj + gap * sj * S1_row[k]) / (cj * cj)
    return gap / cj


@numba.njit(cache=True)
def tof_measurement(ix, x, eta, S_row, S1_row, d_ref):
    """Eq. (18): predicted distance ρ̂ (m) and its Jacobian row (pure form)."""
    H = np.empty(x.shape[0])
    rho = tof_measurement_into(ix, x, eta, S_row, S1_row, d_ref, H)
    return rho, H


@numba.njit(cache=True)
def _least_squares_map(S, active, gamma):
    """S⁺ restricted to the active rows (inactive columns zero) and the null-space projector."""
    nu = S.shape[0]
    n_act = 0
    for j in range(nu):
        if active[j]:
            n_act += 1
    Pinv = np.zeros((gamma, nu))
    null_proj = np.eye(gamma)
    if n_act == 0:
        return Pinv, null_proj
    A = np.zeros((n_act, gamma))
    idx = np.zeros(n_act, dtype=np.int64)
    r = 0
    for j in range(nu):
        if active[j]:
            A[r] = S[j]
            idx[r] = j
            r += 1
    Ap = np.linalg.pinv(A)
    for r in range(n_act):
        Pinv[:, idx[r]] = Ap[:, r]
    null_proj = np.eye(gamma) - Ap @ A
    return Pinv, null_proj


@numba.njit(cache=True)
def least_squares_map(m, active):
    """The ``LeastSquares`` map of the ``active`` peripheral IMUs of model ``m``: gyroscopes see
    the slopes s'(η_j) (Eq. 9), accelerometers the deflections s(η_j) (Eq. 8). The least squares
    solves for the Γ unit deformations; the residual modes' share of the readings is known from
    their states and taken out through ``c_res`` = S⁺ S_r."""
    gamma = m.index.gamma
    S_all = m.imu_S1 if m.kind == KIND_GYRO else m.imu_S
    Pinv, null_proj = _least_squares_map(np.ascontiguousarray(S_all[:, :gamma]), active, gamma)
    c_acc = np.zeros(gamma)
    if m.kind == KIND_ACC:
        c_acc = Pinv @ m.imu_eta
    c_res = Pinv @ np.ascontiguousarray(S_all[:, gamma:])
    gamma_xi = m.index.gamma_xi
    nu = S_all.shape[0]
    if gamma_xi > 0:
        # ξ: gyro y sees minus the slopes (its sign is the kernel's), accel z the deflections, as in ζ.
        S_xi = m.imu_S1_xi if m.kind == KIND_GYRO else m.imu_S_xi
        Pinv_xi, null_xi = _least_squares_map(np.ascontiguousarray(S_xi[:, :gamma_xi]), active, gamma_xi)
        c_res_xi = Pinv_xi @ np.ascontiguousarray(S_xi[:, gamma_xi:])
    else:
        Pinv_xi, null_xi, c_res_xi = np.zeros((0, nu)), np.zeros((0, 0)), np.zeros((0, 0))
    return LeastSquares(Pinv, null_proj, c_acc, c_res, Pinv_xi, null_xi, c_res_xi)


@numba.njit(cache=True, inline="always")
def _aid(x, P, innovation, H, R, gate, ubuf, channel, accepted, rejected, nis_sum, last_innovation):
    """One gated aiding update of channel ``channel`` with its counters."""
    S, d2, ok = update_scalar_into(x, P, innovation, H, R, gate, ubuf)
    last_innovation[channel] = innovation
    if ok:
        accepted[channel] += 1
        nis_sum[channel] += d2
    else:
        rejected[channel] += 1


@numba.njit(cache=True, nogil=True)  # the source thread decodes meanwhile
def run_events(ev, m, st, out, counters):
    """Process the events ``ev`` (``EventArrays``) in time order with model ``m``
    (``ModelArrays``) from filter state ``st`` (``FilterState``, updated in place); the states
    at the D samples go into ``out`` (``FilterOutputs``), the aiding counts into ``counters``
    (``AidingCounters``). Returns the number of states written to ``out``.

    ``ev.next_d[e]`` is the index of the first D-IMU event at or after event e (−1: none in this
    batch). Between two IMU samples the inputs are interpolated (midpoint rule; ``input_weights``:
    the quadratic through the previous, held and next samples, or the straight line): holding
    the last sample would delay the integrated φ and b by half a sample period, which for the
    beam's swinging is the largest error of all. Without a next sample the inputs are held.
    Counters are per aiding channel: [ToF..., strain..., bearing, pseudo h, pseudo ḣ].
    """
    ix = m.index
    p = m.params
    gamma = m.strain_K.shape[1]  # the modal blocks (b and r; a biaxial beam's bξ and rξ too) the gauges see
    wide = ix.gamma_xi > 0  # a biaxial model: IMU events carry f_z and ω_y in columns 3 and 4
    nu = ix.nu
    n_tof = m.tof_eta.shape[0]  # channels: [ToF..., strain..., bearing, pseudo h, pseudo ḣ]
    i_b = ix.b
    x, P = st.x, st.P
    held_fD, held_wD, held_fj, held_wj = st.held_fD, st.held_wD, st.held_fj, st.held_wj
    prev_fD, prev_wD, prev_fj, prev_wj, held_real = st.prev_fD, st.prev_wD, st.prev_fj, st.prev_wj, st.held_real
    last_seen, active = st.last_seen, st.active
    t_ev, kind_ev, index_ev, values_ev, next_d = ev.t, ev.kind, ev.index, ev.values, ev.next_d
    bias_D, bias_j, tip_row = m.bias_D, m.bias_j, m.tip_row
    tof_eta, tof_S, tof_S1, tof_offset, tof_var = m.tof_eta, m.tof_S, m.tof_S1, m.tof_offset, m.tof_var
    strain_K, strain_offset, strain_var, aided = m.strain_K, m.strain_offset, m.strain_var, m.aided
    strain_pair = m.strain_pair
    n_pair = strain_pair.shape[1]
    accepted, rejected, nis_sum, last_innovation = counters.accepted, counters.rejected, counters.nis_sum, counters.last_innovation
    degraded_time, clock = counters.degraded_time, st.clock
    out_t, out_x, out_P, out_var_e = out.t, out.x, out.P, out.var_e
    t_now = clock[0]
    pending = st.pending[0]
    n_out = 0
    lsq = least_squares_map(m, active)
    stale_after = p.stale_after
    max_step = p.max_step
    i_bear = n_tof + m.strain_K.shape[0]
    n = x.shape[0]
    n_ev = t_ev.shape[0]
    n_fD, n_fj = held_fD.shape[0], held_fj.shape[1]  # 2 and 2; biaxial 3 and 4
    next_fD = np.zeros(n_fD)
    next_fj = np.zeros((nu, n_fj))
    next_wj = np.zeros(nu)
    u_fD = np.zeros(n_fD)
    u_fj = np.zeros((nu, n_fj))
    u_wj = np.zeros(nu)
    # Work buffers: the loop allocates nothing per event.
    n_in = _input_count(m, nu)
    xn = np.empty(n)
    F = np.empty((n, n))
    Q = np.empty((n, n))
    Gm = np.empty((n, n_in))
    sig = np.empty(n_in)
    acc_ws, res_ws = _work_buffers(ix)
    work = np.empty((n, n))
    H = np.zeros(n)
    ubuf = np.empty(n)
    # The gauges of one time stamp are updated on the state augmented by the ψ of their shared
    # model error, then ψ is marginalised out: exactly the vector update with R = D + U Uᵀ.
    n_aug = n + n_pair
    xa = np.empty(n_aug)
    Pa = np.empty((n_aug, n_aug))
    Ha = np.zeros(n_aug)
    ua = np.empty(n_aug)
    b1_group = 0.0
    for e in range(n_ev):
        t = t_ev[e]
        if t > t_now:
            if pending:
                out_t[n_out] = t_now
                out_x[n_out] = x
                for i in range(n):
                    out_P[n_out, i] = P[i, i]
                out_var_e[n_out] = tip_variance(P, tip_row, i_b)
                n_out += 1
                pending = False
            held_t = clock[1]
            nd = next_d[e]
            have_next = nd >= 0 and t_ev[nd] > held_t
            t_next = t
            next_wD = 0.0
            if have_next:
                t_next = t_ev[nd]
                next_fD[0] = values_ev[nd, 0] - bias_D[0]
                next_fD[1] = values_ev[nd, 1] - bias_D[1]
                next_wD = values_ev[nd, 2] - bias_D[2]
                ok_D = np.isfinite(next_fD[0]) and np.isfinite(next_fD[1]) and np.isfinite(next_wD)
                if wide:
                    next_fD[2] = values_ev[nd, 3] - bias_D[3]
                    ok_D = ok_D and np.isfinite(next_fD[2])
                if not ok_D:
                    for c in range(n_fD):
                        next_fD[c] = held_fD[c]
                    next_wD = held_wD[0]
                next_fj[:, :] = held_fj
                next_wj[:] = held_wj
                q = nd + 1
                while q < n_ev and t_ev[q] == t_next and kind_ev[q] == EVENT_IMU_PERIPHERAL:
                    jj = index_ev[q]
                    a0 = values_ev[q, 0] - bias_j[jj, 0]
                    a1 = values_ev[q, 1] - bias_j[jj, 1]
                    a2 = values_ev[q, 2] - bias_j[jj, 2]
                    ok_j = np.isfinite(a0) and np.isfinite(a1) and np.isfinite(a2)
                    a3 = a4 = 0.0
                    if wide:
                        a3 = values_ev[q, 3] - bias_j[jj, 3]
                        a4 = values_ev[q, 4] - bias_j[jj, 4]
                        ok_j = ok_j and np.isfinite(a3) and np.isfinite(a4)
                    if ok_j:
                        next_fj[jj, 0] = a0
                        next_fj[jj, 1] = a1
                        next_wj[jj] = a2
                        if wide:
                            next_fj[jj, 2] = a3
                            next_fj[jj, 3] = a4
                    q += 1
            start = t_now
            remaining = t - t_now
            while remaining > 1e-12:
                dt = remaining if remaining < max_step else max_step
                if have_next:
                    wp, wh, wn = input_weights(start + 0.5 * dt, clock[2], held_t, t_next)
                    for c in range(n_fD):
                        u_fD[c] = wp * prev_fD[c] + wh * held_fD[c] + wn * next_fD[c]
                    u_wD = wp * prev_wD[0] + wh * held_wD[0] + wn * next_wD
                    for jj in range(nu):
                        for c in range(n_fj):
                            u_fj[jj, c] = wp * prev_fj[jj, c] + wh * held_fj[jj, c] + wn * next_fj[jj, c]
                        u_wj[jj] = wp * prev_wj[jj] + wh * held_wj[jj] + wn * next_wj[jj]
                else:
                    for c in range(n_fD):
                        u_fD[c] = held_fD[c]
                    u_wD = held_wD[0]
                    u_fj[:, :] = held_fj
                    u_wj[:] = held_wj
                propagate_into(m, x, dt, u_fD, u_wD, u_fj, u_wj, active, lsq, xn, F, Q, Gm, sig, acc_ws, res_ws)
                x[:] = xn
                predict_covariance_into(P, F, Q, work)
                start += dt
                remaining -= dt
            t_now = t
        k = kind_ev[e]
        j = index_ev[e]
        if k == EVENT_IMU_D:
            v0 = values_ev[e, 0] - bias_D[0]
            v1 = values_ev[e, 1] - bias_D[1]
            v2 = values_ev[e, 2] - bias_D[2]
            ok = np.isfinite(v0) and np.isfinite(v1) and np.isfinite(v2)
            v3 = 0.0
            if wide:
                v3 = values_ev[e, 3] - bias_D[3]
                ok = ok and np.isfinite(v3)
            if ok:
                # The held sample becomes the previous one (for the quadratic of the inputs).
                for c in range(n_fD):
                    prev_fD[c] = held_fD[c]
                prev_wD[0] = held_wD[0]
                clock[2] = clock[1] if held_real[0] else np.nan
                held_fD[0] = v0
                held_fD[1] = v1
                if wide:
                    held_fD[2] = v3
                held_wD[0] = v2
                held_real[0] = True
            else:
                clock[2] = np.nan  # the held value stands for this time: back to the straight line
            clock[1] = t
            pending = True
            # Peripheral sensors that stopped delivering leave the least-squares solution.
            changed = False
            for jj in range(nu):
                if active[jj] and (t - last_seen[jj]) > stale_after:
                    active[jj] = False
                    changed = True
            if changed:
                lsq = least_squares_map(m, active)
        elif k == EVENT_IMU_PERIPHERAL:
            v0 = values_ev[e, 0] - bias_j[j, 0]
            v1 = values_ev[e, 1] - bias_j[j, 1]
            v2 = values_ev[e, 2] - bias_j[j, 2]
            ok = np.isfinite(v0) and np.isfinite(v1) and np.isfinite(v2)
            v3 = v4 = 0.0
            if wide:
                v3 = values_ev[e, 3] - bias_j[j, 3]
                v4 = values_ev[e, 4] - bias_j[j, 4]
                ok = ok and np.isfinite(v3) and np.isfinite(v4)
            if ok:
                if not active[j]:
                    degraded_time[j] += t - last_seen[j]
                    active[j] = True
                    lsq = least_squares_map(m, active)
                for c in range(n_fj):
                    prev_fj[j, c] = held_fj[j, c]
                prev_wj[j] = held_wj[j]
                held_fj[j, 0] = v0
                held_fj[j, 1] = v1
                if wide:
                    held_fj[j, 2] = v3
                    held_fj[j, 3] = v4
                held_wj[j] = v2
                last_seen[j] = t
        elif k == EVENT_TOF:
            z = values_ev[e, 0] - tof_offset[j]
            if not np.isfinite(z):
                rejected[j] += 1
                continue
            rho = tof_measurement_into(ix, x, tof_eta[j], tof_S[j], tof_S1[j], p.reflector_distance, H)
            _aid(x, P, z - rho, H, tof_var[j], p.gate, ubuf, j, accepted, rejected, nis_sum, last_innovation)
        elif k == EVENT_STRAIN:
            ch = n_tof + j
            if n_pair > 0:
                first = e == 0 or kind_ev[e - 1] != EVENT_STRAIN or t_ev[e - 1] != t
                last = e + 1 >= n_ev or kind_ev[e + 1] != EVENT_STRAIN or t_ev[e + 1] != t
                if first:
                    for i in range(n):
                        xa[i] = x[i]
                        for jj in range(n):
                            Pa[i, jj] = P[i, jj]
                    for i in range(n, n_aug):
                        xa[i] = 0.0
                        for jj in range(n_aug):
                            Pa[i, jj] = 0.0
                            Pa[jj, i] = 0.0
                        Pa[i, i] = 1.0
                    b1_group = x[i_b]
                z = values_ev[e, 0] - strain_offset[j]
                if np.isfinite(z):
                    Ha[:] = 0.0
                    pred = 0.0
                    for mm in range(gamma):
                        if aided[mm] > 0:
                            Ha[i_b + mm] = strain_K[j, mm]
                        pred += strain_K[j, mm] * xa[i_b + mm]
                    for q in range(n_pair):
                        Ha[n + q] = strain_pair[j, q] * b1_group
                        pred += Ha[n + q] * xa[n + q]  # the shared error as the group's earlier gauges told it
                    _aid(xa, Pa, z - pred, Ha, strain_var[j], p.gate, ua, ch, accepted, rejected, nis_sum, last_innovation)
                else:
                    rejected[ch] += 1
                if last:
                    for i in range(n):
                        x[i] = xa[i]
                        for jj in range(n):
                            P[i, jj] = Pa[i, jj]
                continue
            z = values_ev[e, 0] - strain_offset[j]
            if not np.isfinite(z):
                rejected[ch] += 1
                continue
            H[:] = 0.0
            pred = 0.0
            for mm in range(gamma):
                if aided[mm] > 0:
                    H[i_b + mm] = strain_K[j, mm]
                # Eq. (22): the strain of unaided unit deformations is subtracted at its estimate.
                pred += strain_K[j, mm] * x[i_b + mm]
            _aid(x, P, z - pred, H, strain_var[j], p.gate, ubuf, ch, accepted, rejected, nis_sum, last_innovation)
        elif k == EVENT_BEARING:
            z = values_ev[e, 0]
            if not np.isfinite(z):
                rejected[i_bear] += 1
                continue
            H[:] = 0.0
            H[ix.d] = 1.0
            _aid(x, P, z - x[ix.d], H, p.bearing_var, p.bearing_gate, ubuf, i_bear, accepted, rejected, nis_sum,
                 last_innovation)
            # The bearing runs on a rail: h = 0 and ḣ = 0 as pseudo-measurements.
            H[:] = 0.0
            H[ix.h] = 1.0
            S, d2, ok = update_scalar_into(x, P, -x[ix.h], H, p.pseudo_h_var, 1e300, ubuf)
            accepted[i_bear + 1] += 1
            H[:] = 0.0
            H[ix.h_rate] = 1.0
            S, d2, ok = update_scalar_into(x, P, -x[ix.h_rate], H, p.pseudo_h_rate_var, 1e300, ubuf)
            accepted[i_bear + 2] += 1
    clock[0] = t_now
    st.pending[0] = pending
    return n_out
