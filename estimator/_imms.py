"""The planar IMMS kinematics (Eq. 4–9), aiding equations (Eq. 13–22) and the event loop.

Everything here is compiled with numba and works on plain arrays; ``_filter.py`` holds the
Python-facing class. Frames and signs follow the recording contract (see planar-imms.md).

State layout (``x``)
    gyro: [d, h, ḋ, ḣ, φ, b_1..b_Γ, β_1..β_ν, β_D]
    acc:  [d, h, ḋ, ḣ, φ, b_1..b_Γ, v_1..v_Γ, β_D]
β_D is the bias of the gyroscope at D and β_j those of the peripheral gyroscopes (random walks:
what the rest phase cannot calibrate, the wander of low-cost MEMS, goes straight into ḃ). For accelerometers the velocity state is
v = ḃ + c·ω_D with c = S⁺η: Eq. (8) contains ω̇·η_j with ω̇ the numerical derivative of ω_D,
and integrating that term once gives exactly c·(ω_D,k − ω_D,k−1). Carrying v keeps the
differentiated gyro noise what it is — a difference of two samples, not white noise of
1/dt size — and ḃ = v − c·ω_D is reported.

Events (``kind``): 0 IMU at D, 1 peripheral IMU, 2 ToF, 3 strain gauge, 4 bearing displacement.
IMU values are [f_x, f_y, ω_z] in the sensor frame; the others carry their value in column 0.
"""

from __future__ import annotations

import numba
import numpy as np

from ._ekf import predict_covariance_into, update_scalar_into

__all__ = [
    "EVENT_BEARING",
    "EVENT_IMU_D",
    "EVENT_IMU_PERIPHERAL",
    "EVENT_STRAIN",
    "EVENT_TOF",
    "FLOAT_PARAMS",
    "INT_PARAMS",
    "KIND_ACC",
    "KIND_GYRO",
    "propagate",
    "propagate_into",
    "run_events",
    "state_size",
    "tip_variance",
    "tof_measurement",
    "tof_measurement_into",
]

KIND_GYRO = 0
KIND_ACC = 1
EVENT_IMU_D, EVENT_IMU_PERIPHERAL, EVENT_TOF, EVENT_STRAIN, EVENT_BEARING = 0, 1, 2, 3, 4

# Layout of the float parameter vector.
FLOAT_PARAMS = (
    "gravity", "reflector_distance", "gate", "stale_after", "sigma_f_d_x", "sigma_f_d_y", "sigma_omega_d",
    "q_b", "q_v", "q_beta", "q_rigid", "bearing_var", "pseudo_h_var", "pseudo_h_rate_var", "max_step", "q_null",
    "q_beta_peripheral",
)
INT_PARAMS = ("kind", "gamma", "nu", "n_tof", "n_gauge")
(P_G, P_DREF, P_GATE, P_STALE, P_SFX, P_SFY, P_SWD, P_QB, P_QV, P_QBETA, P_QRIGID, P_RBEAR, P_RH, P_RHD, P_MAXSTEP, P_QNULL,
 P_QBETAJ) = range(17)


@numba.njit(cache=True)
def state_size(kind: int, gamma: int, nu: int) -> int:
    return 5 + gamma + nu + 1 if kind == KIND_GYRO else 5 + 2 * gamma + 1


@numba.njit(cache=True)
def propagate_into(x, dt, kind, gamma, fD, omegaD, fj, omegaj, active, Pinv, c_acc, imu_S, imu_S1, sig_fj, sig_wj,
                   params, null_proj, xn, F, Q, Gm, sig, acc_ws):
    """Propagate x over dt with the given inputs into the buffers xn (n,), F (n, n), Q (n, n).

    fD (2,), omegaD: bias-corrected inputs at D; fj (ν, 2), omegaj (ν,): bias-corrected
    peripheral inputs; ``Pinv`` (Γ, ν) the least-squares map of the active peripheral sensors
    (zero columns for inactive ones); ``c_acc`` (Γ,) = S⁺η for accelerometers. Gm (n, n_in),
    sig (n_in,) and acc_ws (Γ, Γ + 2) are scratch buffers.
    """
    n = x.shape[0]
    g = params[P_G]
    ib = n - 1  # β_D
    phi = x[4]
    omega = omegaD - x[ib]
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
    # Rigid part: inertial acceleration of D from its specific force (η down, gravity +g).
    acc_h = cp * fD[0] - sp * fD[1] + g
    acc_d = sp * fD[0] + cp * fD[1]
    dacc_h = -sp * fD[0] - cp * fD[1]
    dacc_d = cp * fD[0] - sp * fD[1]
    half = 0.5 * dt * dt
    xn[0] = x[0] + dt * x[2] + half * acc_d
    xn[1] = x[1] + dt * x[3] + half * acc_h
    xn[2] = x[2] + dt * acc_d
    xn[3] = x[3] + dt * acc_h
    xn[4] = phi + dt * omega
    F[0, 2] = dt
    F[1, 3] = dt
    F[0, 4] = half * dacc_d
    F[1, 4] = half * dacc_h
    F[2, 4] = dt * dacc_d
    F[3, 4] = dt * dacc_h
    F[4, ib] = -dt
    nu = fj.shape[0]
    sig[0] = params[P_SFX]
    sig[1] = params[P_SFY]
    sig[2] = params[P_SWD]
    Gm[0, 0] = half * sp
    Gm[0, 1] = half * cp
    Gm[1, 0] = half * cp
    Gm[1, 1] = -half * sp
    Gm[2, 0] = dt * sp
    Gm[2, 1] = dt * cp
    Gm[3, 0] = dt * cp
    Gm[3, 1] = -dt * sp
    Gm[4, 2] = dt
    if kind == KIND_GYRO:
        # Eq. (9): ω_j − ω_D = Σ ḃ s'_χ(η_j), solved in the least-squares sense.
        ibj = 5 + gamma
        for k in range(gamma):
            bdot = 0.0
            row_sum = 0.0
            for j in range(nu):
                if active[j]:
                    bdot += Pinv[k, j] * (omegaj[j] - x[ibj + j] - omega)
                row_sum += Pinv[k, j]
                Gm[5 + k, 3 + j] = dt * Pinv[k, j]
                F[5 + k, ibj + j] = -dt * Pinv[k, j]
            xn[5 + k] = x[5 + k] + dt * bdot
            F[5 + k, ib] = dt * row_sum
            Gm[5 + k, 2] = -dt * row_sum
            Q[5 + k, 5 + k] += params[P_QB] * dt
        for j in range(nu):
            sig[3 + j] = sig_wj[j]
            Q[ibj + j, ibj + j] += params[P_QBETAJ] * dt
    else:
        # Eq. (8) per sensor: Δ̈_j = f_j,ζ − f_D,ζ − ω̇ η_j + ω² Δ_j with f_j,ζ = sin α_j f_j,x + cos α_j f_j,y.
        iv = 5 + gamma
        for k in range(gamma):
            for m in range(gamma + 2):
                acc_ws[k, m] = 0.0  # [dB (Γ) | b̈ | ∂b̈/∂β_D]
        w2 = omega * omega
        for j in range(nu):
            if not active[j]:
                continue
            alpha = 0.0
            delta = 0.0
            for k in range(gamma):
                alpha += imu_S1[j, k] * x[5 + k]
                delta += imu_S[j, k] * x[5 + k]
            ca, sa = np.cos(alpha), np.sin(alpha)
            ddelta = sa * fj[j, 0] + ca * fj[j, 1] - fD[1] + w2 * delta
            tilt = ca * fj[j, 0] - sa * fj[j, 1]
            dbeta = -2.0 * omega * delta
            sig[3 + 2 * j] = sig_fj[j, 0]
            sig[4 + 2 * j] = sig_fj[j, 1]
            for k in range(gamma):
                pk = Pinv[k, j]
                acc_ws[k, gamma] += pk * ddelta
                acc_ws[k, gamma + 1] += pk * dbeta
                for m in range(gamma):
                    acc_ws[k, m] += pk * (tilt * imu_S1[j, m] + w2 * imu_S[j, m])
                Gm[iv + k, 3 + 2 * j] = dt * pk * sa
                Gm[iv + k, 4 + 2 * j] = dt * pk * ca
        for k in range(gamma):
            v = x[iv + k]
            bddot = acc_ws[k, gamma]
            xn[5 + k] = x[5 + k] + dt * (v - c_acc[k] * omega) + half * bddot
            xn[iv + k] = v + dt * bddot
            F[5 + k, iv + k] += dt
            F[5 + k, ib] = dt * c_acc[k] + half * acc_ws[k, gamma + 1]
            F[iv + k, ib] = dt * acc_ws[k, gamma + 1]
            for m in range(gamma):
                F[5 + k, 5 + m] += half * acc_ws[k, m]
                F[iv + k, 5 + m] += dt * acc_ws[k, m]
            Gm[5 + k, 2] = -dt * c_acc[k]
            row_sum = 0.0
            for j in range(nu):
                row_sum += Pinv[k, j]
            # f_D,y enters every Δ̈_j with −1.
            Gm[iv + k, 1] += -dt * row_sum
            Q[5 + k, 5 + k] += params[P_QB] * dt
            Q[iv + k, iv + k] += params[P_QV] * dt
    # Unobservable directions of b (fewer active sensors than Γ) random-walk instead of freezing.
    if params[P_QNULL] > 0:
        for k in range(gamma):
            for m in range(gamma):
                Q[5 + k, 5 + m] += params[P_QNULL] * dt * null_proj[k, m]
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
    Q[2, 2] += params[P_QRIGID] * dt
    Q[3, 3] += params[P_QRIGID] * dt
    Q[ib, ib] += params[P_QBETA] * dt


@numba.njit(cache=True)
def propagate(x, dt, kind, gamma, fD, omegaD, fj, omegaj, active, Pinv, c_acc, imu_S, imu_S1, sig_fj, sig_wj, params, null_proj):
    """Pure form of ``propagate_into``: returns (x⁺, F, Q) as new arrays."""
    n = x.shape[0]
    n_in = 3 + (fj.shape[0] if kind == KIND_GYRO else 2 * fj.shape[0])
    xn = np.empty(n)
    F = np.empty((n, n))
    Q = np.empty((n, n))
    propagate_into(x, dt, kind, gamma, fD, omegaD, fj, omegaj, active, Pinv, c_acc, imu_S, imu_S1, sig_fj, sig_wj,
                   params, null_proj, xn, F, Q, np.empty((n, n_in)), np.empty(n_in), np.empty((gamma, gamma + 2)))
    return xn, F, Q


@numba.njit(cache=True)
def tip_variance(P, tip_row):
    """Variance of e = Σ b_χ s_χ(L) from the full covariance (off-diagonal terms included)."""
    gamma = tip_row.shape[0]
    v = 0.0
    for k in range(gamma):
        for m in range(gamma):
            v += tip_row[k] * P[5 + k, 5 + m] * tip_row[m]
    return v


@numba.njit(cache=True)
def tof_measurement_into(x, eta, S_row, S1_row, d_ref, H):
    """Eq. (18): predicted distance ρ̂ (m) of a ToF at arc length ``eta``; its Jacobian row into H (n,)."""
    gamma = S_row.shape[0]
    phi = x[4]
    delta = 0.0
    alpha = 0.0
    for k in range(gamma):
        delta += S_row[k] * x[5 + k]
        alpha += S1_row[k] * x[5 + k]
    cp, sp = np.cos(phi), np.sin(phi)
    zeta = x[0] + sp * eta + cp * delta
    phij = phi + alpha
    cj, sj = np.cos(phij), np.sin(phij)
    gap = d_ref - zeta
    for i in range(H.shape[0]):
        H[i] = 0.0
    H[0] = -1.0 / cj
    H[4] = (-(cp * eta - sp * delta) * cj + gap * sj) / (cj * cj)
    for k in range(gamma):
        H[5 + k] = (-cp * S_row[k] * cj + gap * sj * S1_row[k]) / (cj * cj)
    return gap / cj


@numba.njit(cache=True)
def tof_measurement(x, eta, S_row, S1_row, d_ref):
    """Eq. (18): predicted distance ρ̂ (m) and its Jacobian row (pure form)."""
    H = np.empty(x.shape[0])
    rho = tof_measurement_into(x, eta, S_row, S1_row, d_ref, H)
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
def _aid(x, P, innovation, H, R, gate, ubuf, channel, counts_accepted, counts_rejected, nis_sum, last_innovation):
    """One gated aiding update of channel ``channel`` with its counters."""
    S, d2, ok = update_scalar_into(x, P, innovation, H, R, gate, ubuf)
    last_innovation[channel] = innovation
    if ok:
        counts_accepted[channel] += 1
        nis_sum[channel] += d2
    else:
        counts_rejected[channel] += 1


@numba.njit(cache=True)
def run_events(
    t_ev, kind_ev, index_ev, values_ev, next_d,
    x, P, t_now, held_t, held_fD, held_wD, held_fj, held_wj, last_seen, active,
    iparams, params,
    bias_D, bias_j, imu_eta, imu_S, imu_S1, sig_fj, sig_wj,
    tof_eta, tof_S, tof_S1, tof_offset, tof_var,
    strain_K, strain_offset, strain_var, aided,
    tip_row, out_t, out_x, out_P, out_var_e, n_out_start, pending_in,
    counts_accepted, counts_rejected, nis_sum, last_innovation, degraded_time,
):
    """Process events in time order; returns (x, P, t_now, n_out, pending).

    ``next_d[e]`` is the index of the first D-IMU event at or after event e (−1: none in this
    batch). Between two IMU samples the inputs are interpolated linearly (midpoint rule): holding
    the last sample would delay the integrated φ and b by half a sample period, which for the
    beam's swinging is the largest error of all. Without a next sample the inputs are held.

    Mutates ``held_t`` (time of the held IMU sample), the held inputs, ``last_seen``,
    ``active``, the outputs and the counters in place. Counters are per aiding channel:
    [ToF..., strain..., bearing, pseudo h, pseudo ḣ].
    """
    kind = iparams[0]
    gamma = iparams[1]
    nu = iparams[2]
    n_tof = iparams[3]
    n_gauge = iparams[4]
    n_out = n_out_start
    pending = pending_in
    c_acc = np.zeros(gamma)
    S_map = imu_S1 if kind == KIND_GYRO else imu_S
    Pinv, null_proj = _least_squares_map(S_map, active, gamma)
    if kind == KIND_ACC:
        c_acc = Pinv @ imu_eta
    stale_after = params[P_STALE]
    max_step = params[P_MAXSTEP]
    i_bear = n_tof + n_gauge
    n = x.shape[0]
    n_ev = t_ev.shape[0]
    next_fD = np.zeros(2)
    next_fj = np.zeros((nu, 2))
    next_wj = np.zeros(nu)
    u_fD = np.zeros(2)
    u_fj = np.zeros((nu, 2))
    u_wj = np.zeros(nu)
    # Work buffers: the loop allocates nothing per event.
    n_in = 3 + (nu if kind == KIND_GYRO else 2 * nu)
    xn = np.empty(n)
    F = np.empty((n, n))
    Q = np.empty((n, n))
    Gm = np.empty((n, n_in))
    sig = np.empty(n_in)
    acc_ws = np.empty((gamma, gamma + 2))
    work = np.empty((n, n))
    H = np.zeros(n)
    ubuf = np.empty(n)
    for e in range(n_ev):
        t = t_ev[e]
        if t > t_now:
            if pending:
                out_t[n_out] = t_now
                out_x[n_out] = x
                for i in range(n):
                    out_P[n_out, i] = P[i, i]
                out_var_e[n_out] = tip_variance(P, tip_row)
                n_out += 1
                pending = False
            nd = next_d[e]
            have_next = nd >= 0 and t_ev[nd] > held_t[0]
            t_next = t
            if have_next:
                t_next = t_ev[nd]
                next_fD[0] = values_ev[nd, 0] - bias_D[0]
                next_fD[1] = values_ev[nd, 1] - bias_D[1]
                next_wD = values_ev[nd, 2] - bias_D[2]
                if not (np.isfinite(next_fD[0]) and np.isfinite(next_fD[1]) and np.isfinite(next_wD)):
                    next_fD[0] = held_fD[0]
                    next_fD[1] = held_fD[1]
                    next_wD = held_wD[0]
                next_fj[:, :] = held_fj
                next_wj[:] = held_wj
                q = nd + 1
                while q < n_ev and t_ev[q] == t_next and kind_ev[q] == EVENT_IMU_PERIPHERAL:
                    jj = index_ev[q]
                    a0 = values_ev[q, 0] - bias_j[jj, 0]
                    a1 = values_ev[q, 1] - bias_j[jj, 1]
                    a2 = values_ev[q, 2] - bias_j[jj, 2]
                    if np.isfinite(a0) and np.isfinite(a1) and np.isfinite(a2):
                        next_fj[jj, 0] = a0
                        next_fj[jj, 1] = a1
                        next_wj[jj] = a2
                    q += 1
            start = t_now
            remaining = t - t_now
            while remaining > 1e-12:
                dt = remaining if remaining < max_step else max_step
                if have_next:
                    w = (start + 0.5 * dt - held_t[0]) / (t_next - held_t[0])
                    w = min(max(w, 0.0), 1.0)
                    u_fD[0] = held_fD[0] + w * (next_fD[0] - held_fD[0])
                    u_fD[1] = held_fD[1] + w * (next_fD[1] - held_fD[1])
                    u_wD = held_wD[0] + w * (next_wD - held_wD[0])
                    for jj in range(nu):
                        u_fj[jj, 0] = held_fj[jj, 0] + w * (next_fj[jj, 0] - held_fj[jj, 0])
                        u_fj[jj, 1] = held_fj[jj, 1] + w * (next_fj[jj, 1] - held_fj[jj, 1])
                        u_wj[jj] = held_wj[jj] + w * (next_wj[jj] - held_wj[jj])
                else:
                    u_fD[0] = held_fD[0]
                    u_fD[1] = held_fD[1]
                    u_wD = held_wD[0]
                    u_fj[:, :] = held_fj
                    u_wj[:] = held_wj
                propagate_into(x, dt, kind, gamma, u_fD, u_wD, u_fj, u_wj, active, Pinv, c_acc,
                               imu_S, imu_S1, sig_fj, sig_wj, params, null_proj, xn, F, Q, Gm, sig, acc_ws)
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
            if np.isfinite(v0) and np.isfinite(v1) and np.isfinite(v2):
                held_fD[0] = v0
                held_fD[1] = v1
                held_wD[0] = v2
            held_t[0] = t
            pending = True
            # Peripheral sensors that stopped delivering leave the least-squares solution.
            changed = False
            for jj in range(nu):
                if active[jj] and (t - last_seen[jj]) > stale_after:
                    active[jj] = False
                    changed = True
            if changed:
                Pinv, null_proj = _least_squares_map(S_map, active, gamma)
                if kind == KIND_ACC:
                    c_acc = Pinv @ imu_eta
        elif k == EVENT_IMU_PERIPHERAL:
            v0 = values_ev[e, 0] - bias_j[j, 0]
            v1 = values_ev[e, 1] - bias_j[j, 1]
            v2 = values_ev[e, 2] - bias_j[j, 2]
            if np.isfinite(v0) and np.isfinite(v1) and np.isfinite(v2):
                if not active[j]:
                    degraded_time[j] += t - last_seen[j]
                    active[j] = True
                    Pinv, null_proj = _least_squares_map(S_map, active, gamma)
                    if kind == KIND_ACC:
                        c_acc = Pinv @ imu_eta
                held_fj[j, 0] = v0
                held_fj[j, 1] = v1
                held_wj[j] = v2
                last_seen[j] = t
        elif k == EVENT_TOF:
            z = values_ev[e, 0] - tof_offset[j]
            if not np.isfinite(z):
                counts_rejected[j] += 1
                continue
            rho = tof_measurement_into(x, tof_eta[j], tof_S[j], tof_S1[j], params[P_DREF], H)
            _aid(x, P, z - rho, H, tof_var[j], params[P_GATE], ubuf, j, counts_accepted, counts_rejected, nis_sum, last_innovation)
        elif k == EVENT_STRAIN:
            ch = n_tof + j
            z = values_ev[e, 0] - strain_offset[j]
            if not np.isfinite(z):
                counts_rejected[ch] += 1
                continue
            H[:] = 0.0
            pred = 0.0
            for m in range(gamma):
                if aided[m] > 0:
                    H[5 + m] = strain_K[j, m]
                # Eq. (22): the strain of unaided unit deformations is subtracted at its estimate.
                pred += strain_K[j, m] * x[5 + m]
            _aid(x, P, z - pred, H, strain_var[j], params[P_GATE], ubuf, ch, counts_accepted, counts_rejected, nis_sum,
                 last_innovation)
        elif k == EVENT_BEARING:
            z = values_ev[e, 0]
            if not np.isfinite(z):
                counts_rejected[i_bear] += 1
                continue
            H[:] = 0.0
            H[0] = 1.0
            _aid(x, P, z - x[0], H, params[P_RBEAR], params[P_GATE], ubuf, i_bear, counts_accepted, counts_rejected,
                 nis_sum, last_innovation)
            # The bearing runs on a rail: h = 0 and ḣ = 0 as pseudo-measurements.
            H[:] = 0.0
            H[1] = 1.0
            S, d2, ok = update_scalar_into(x, P, -x[1], H, params[P_RH], 1e300, ubuf)
            counts_accepted[i_bear + 1] += 1
            H[:] = 0.0
            H[3] = 1.0
            S, d2, ok = update_scalar_into(x, P, -x[3], H, params[P_RHD], 1e300, ubuf)
            counts_accepted[i_bear + 2] += 1
    return x, P, t_now, n_out, pending
