"""The straightforward filterpy loop on the same model: the reference the project's filter is
checked against (tests) and timed against (benchmarks).

It walks the same events with filterpy's ``ExtendedKalmanFilter`` (predict with the model's
propagation and Jacobian, Joseph-form ``update`` with the aiding equations), one event at a time
in plain Python. It leaves out what the production loop adds for robustness (silent sensors);
on complete data both must agree to numerical precision.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from ._filter import Events, FilterConfig, FilterOutput, ImmsModel, RestCalibration, model_arrays
from ._imms import (
    EVENT_BEARING,
    EVENT_IMU_D,
    EVENT_IMU_PERIPHERAL,
    EVENT_STRAIN,
    EVENT_TOF,
    input_weights,
    least_squares_map,
    propagate,
    tof_measurement,
)

__all__ = ["run_filterpy"]


class _ModelEKF(ExtendedKalmanFilter):
    """filterpy's EKF whose state prediction is the IMMS kinematics (filterpy's own is F·x)."""

    def predict_x(self, u=0):
        self.x = self._propagated


def run_filterpy(events: Events, model: ImmsModel, calibration: RestCalibration, config: FilterConfig = FilterConfig(), *, t0: float) -> FilterOutput:
    """Run the reference loop over ``events`` (complete data) and return the states at the D samples."""
    arrays = model_arrays(model, calibration, config)
    params = arrays.params
    layout = model.state_layout
    n = layout.size
    nu = len(model.selection.imus)
    ekf = _ModelEKF(dim_x=n, dim_z=1)
    ekf.x = np.zeros(n)
    ekf.P = np.eye(n) * config.initial_std**2
    active = np.ones(nu, dtype=np.bool_)
    lsq = least_squares_map(arrays, active)
    bias_D, bias_j = arrays.bias_D, arrays.bias_j
    held_fD = np.array([-model.gravity_eta, 0.0])
    held_wD = 0.0
    held_fj = np.tile([-model.gravity_eta, 0.0], (nu, 1))
    held_wj = np.zeros(nu)
    held_t = t0
    prev_fD, prev_wD, prev_fj, prev_wj = held_fD, held_wD, held_fj, held_wj
    prev_t = np.nan
    held_real = False
    t_now = t0
    pending = False
    out_t, out_x, out_P = [], [], []
    d_times = events.t[events.kind == EVENT_IMU_D]

    def update(z_minus_h: float, H: np.ndarray, R: float, gate: float) -> None:
        S = float(H @ ekf.P @ H) + R
        if not z_minus_h * z_minus_h / S <= gate:
            return
        # filterpy computes y = z − Hx(x); pass the innovation as z with Hx ≡ 0.
        ekf.update(np.array([z_minus_h]), lambda x: H[None, :], lambda x: np.zeros(1), R=np.array([[R]]))

    for e in range(len(events)):
        t = events.t[e]
        if t > t_now:
            if pending:
                out_t.append(t_now)
                out_x.append(ekf.x.copy())
                out_P.append(np.diag(ekf.P).copy())
                pending = False
            later = np.searchsorted(d_times, t)
            have_next = later < d_times.size and d_times[later] > held_t
            if have_next:
                t_next = d_times[later]
                group = np.nonzero(events.t == t_next)[0]
                next_fD, next_wD = held_fD.copy(), held_wD
                next_fj, next_wj = held_fj.copy(), held_wj.copy()
                for q in group:
                    v = events.values[q]
                    if events.kind[q] == EVENT_IMU_D:
                        next_fD = v[:2] - bias_D[:2]
                        next_wD = v[2] - bias_D[2]
                    elif events.kind[q] == EVENT_IMU_PERIPHERAL:
                        j = events.index[q]
                        next_fj[j] = v[:2] - bias_j[j, :2]
                        next_wj[j] = v[2] - bias_j[j, 2]
            start, remaining = t_now, t - t_now
            while remaining > 1e-12:
                dt = min(remaining, params.max_step)
                if have_next:
                    wp, wh, wn = input_weights(start + 0.5 * dt, prev_t, held_t, t_next)
                    u = (wp * prev_fD + wh * held_fD + wn * next_fD, wp * prev_wD + wh * held_wD + wn * next_wD,
                         wp * prev_fj + wh * held_fj + wn * next_fj, wp * prev_wj + wh * held_wj + wn * next_wj)
                else:
                    u = (held_fD, held_wD, held_fj, held_wj)
                x_new, F, Q = propagate(arrays, ekf.x, dt, u[0], u[1], u[2], u[3], active, lsq)
                ekf._propagated = x_new
                ekf.F, ekf.Q = F, Q
                ekf.predict()
                start += dt
                remaining -= dt
            t_now = t
        k, j, v = events.kind[e], events.index[e], events.values[e]
        if k == EVENT_IMU_D:
            prev_fD, prev_wD, prev_t = held_fD, held_wD, (held_t if held_real else np.nan)
            held_fD, held_wD = v[:2] - bias_D[:2], v[2] - bias_D[2]
            held_t, held_real = t, True
            pending = True
        elif k == EVENT_IMU_PERIPHERAL:
            prev_fj, prev_wj = prev_fj.copy(), prev_wj.copy()
            prev_fj[j], prev_wj[j] = held_fj[j], held_wj[j]
            held_fj = held_fj.copy()
            held_wj = held_wj.copy()
            held_fj[j] = v[:2] - bias_j[j, :2]
            held_wj[j] = v[2] - bias_j[j, 2]
        elif k == EVENT_TOF:
            rho, H = tof_measurement(layout.index, ekf.x, arrays.tof_eta[j], arrays.tof_S[j], arrays.tof_S1[j],
                                     params.reflector_distance)
            update(v[0] - arrays.tof_offset[j] - rho, H, arrays.tof_var[j], params.gate)
        elif k == EVENT_STRAIN:
            pair = arrays.strain_pair
            if pair.shape[1] == 0:
                K = arrays.strain_K[j]
                H = np.zeros(n)
                H[layout.modal] = K * arrays.aided
                update(v[0] - arrays.strain_offset[j] - K @ ekf.x[layout.modal], H, arrays.strain_var[j], params.gate)
            elif e == 0 or events.kind[e - 1] != EVENT_STRAIN or events.t[e - 1] != t:
                # The gauges of one time stamp as one vector measurement whose model error they
                # share: R = diag(var) + U Uᵀ with U = strain_pair · b_1 (the product updates on a
                # state augmented by ψ instead).
                group = [e]
                while group[-1] + 1 < len(events) and events.kind[group[-1] + 1] == EVENT_STRAIN and events.t[group[-1] + 1] == t:
                    group.append(group[-1] + 1)
                rows = events.index[group]
                Hm = np.zeros((len(group), n))
                Hm[:, layout.modal] = arrays.strain_K[rows] * arrays.aided
                y = events.values[group, 0] - arrays.strain_offset[rows] - arrays.strain_K[rows] @ ekf.x[layout.modal]
                U = pair[rows] * ekf.x[layout.index.b]
                R = np.diag(arrays.strain_var[rows]) + U @ U.T
                ekf.update(y, lambda x: Hm, lambda x: np.zeros(len(group)), R=R)  # noqa: B023  (called at once)
        elif k == EVENT_BEARING:
            for index, z, R, gate in ((layout.d, v[0], params.bearing_var, params.gate), (layout.h, 0.0, params.pseudo_h_var, np.inf),
                                      (layout.h_rate, 0.0, params.pseudo_h_rate_var, np.inf)):
                H = np.zeros(n)
                H[index] = 1.0
                update(z - ekf.x[index], H, R, gate)
    if pending:
        out_t.append(t_now)
        out_x.append(ekf.x.copy())
        out_P.append(np.diag(ekf.P).copy())
    return FilterOutput(np.array(out_t), np.array(out_x), np.array(out_P), np.full(len(out_t), np.nan))
