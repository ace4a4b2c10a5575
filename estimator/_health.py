"""Health of the running filter: is it still tracking the structure, or has it diverged?

Pure functions over what the filter already exposes (its state and its per-channel aiding
counters), so the policy (restart, report) stays with the caller. Three signs, each over one
assessment window:

- the state leaves what the rig can physically do: |d| beyond a few beam lengths (no rail is
  longer than the structure it carries by much), |φ| beyond a quarter turn, a tip deflection
  |e| beyond the beam length, or any non-finite value;
- the normalised innovations of the accepted aiding updates grow: their mean NIS over the window
  exceeds ``nis_limit`` (a consistent filter has a mean near 1; ours, tuned conservatively,
  stays below 0.5 on simulated and real data);
- the gate refuses the aiding: at least half of the aiding channels (and at least two) that got
  updates in the window refused ``reject_fraction`` of them. One sensor refused for good is a
  broken sensor, not a diverged filter, and does not count.

``restart_state`` gives the state a restarted filter begins from: the current measurements
(the bearing's displacement for d, the attitude of D's specific force for φ, the strain gauges'
least-squares b), the rest calibration kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ._filter import ImmsModel, Measurements, RestCalibration

__all__ = ["AidingWindow", "HealthConfig", "HealthVerdict", "StateBounds", "assess_health", "aiding_window",
           "gauge_disagreement", "gauges_beyond_basis", "physical_bounds", "restart_state"]


class HealthConfig(BaseModel):
    """When the filter counts as diverged, and how a restart is followed."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    nis_limit: float = Field(9.0, gt=0, description="largest mean NIS of the accepted aiding updates over a window")
    min_updates: int = Field(20, ge=1, description="aiding updates a window needs before its NIS or its refusals are judged")
    reject_fraction: float = Field(0.9, gt=0, le=1, description="share of a channel's updates refused that counts as refusing")
    d_max_beam_lengths: float = Field(3.0, gt=0, description="|d| beyond this many beam lengths is not physical")
    phi_max_rad: float = Field(math.pi / 2, gt=0, le=math.pi, description="|φ| beyond this is not physical, rad")
    tip_max_beam_lengths: float = Field(1.0, gt=0, description="|e| beyond this many beam lengths is not physical")
    confirm_s: float = Field(5.0, ge=0, description="a restarted filter is healthy again after this long without a sign, s")
    settle_s: float = Field(10.0, ge=0, description="windows starting before a restart plus this are not analysed, s")
    gauge_error_growth: float = Field(
        3.0, gt=1, description="after a divergence the strain gauges drove (their own NIS or refusals), the gauges' model "
        "error grows by this factor for the filters that follow: they see strain outside the unit deformations")
    gauge_error_max: float = Field(1e-3, gt=0, description="the largest gauge model error it grows to, m/m")


@dataclass(frozen=True)
class StateBounds:
    """What the rig can physically do: |d| ≤ d_max_m, |φ| ≤ phi_max_rad, |e| ≤ tip_max_m."""

    d_max_m: float
    phi_max_rad: float
    tip_max_m: float


def physical_bounds(beam_length_m: float, config: HealthConfig = HealthConfig()) -> StateBounds:
    """The bounds of a rig with a beam of ``beam_length_m``.

    Raises
    ------
    ValueError
        When the length is not a positive finite number of metres.
    """
    if not (math.isfinite(beam_length_m) and beam_length_m > 0):
        raise ValueError(f"{beam_length_m=} must be a positive beam length in m")
    return StateBounds(config.d_max_beam_lengths * beam_length_m, config.phi_max_rad,
                       config.tip_max_beam_lengths * beam_length_m)


@dataclass(frozen=True)
class AidingWindow:
    """The aiding updates of one window, per channel: accepted (k,), rejected (k,), and the sum
    of the accepted updates' NIS (k,)."""

    channels: tuple[str, ...]
    accepted: np.ndarray
    rejected: np.ndarray
    nis_sum: np.ndarray

    @property
    def updates(self) -> int:
        return int(self.accepted.sum() + self.rejected.sum())

    @property
    def mean_nis(self) -> float | None:
        n = int(self.accepted.sum())
        return float(self.nis_sum.sum() / n) if n else None


def aiding_window(channels: list[str] | tuple[str, ...], before: tuple[np.ndarray, np.ndarray, np.ndarray],
                  after: tuple[np.ndarray, np.ndarray, np.ndarray]) -> AidingWindow:
    """The window between two readings (accepted, rejected, nis_sum) of the filter's cumulative
    counters. Pseudo-measurements (``pseudo:*``) are left out: they are never refused.

    Raises
    ------
    ValueError
        When the readings do not match the channels, or the counters went backwards (a new filter).
    """
    k = len(channels)
    arrays = [np.asarray(a, dtype=float) for a in (*before, *after)]
    if any(a.shape != (k,) for a in arrays):
        raise ValueError(f"counters must have shape ({k},) (one per channel of {list(channels)})")
    delta = [arrays[i + 3] - arrays[i] for i in range(3)]
    if np.any(delta[0] < 0) or np.any(delta[1] < 0):
        raise ValueError("the counters went backwards: the readings are of two different filters")
    keep = np.array([not c.startswith("pseudo") for c in channels], dtype=bool)
    return AidingWindow(tuple(c for c, kept in zip(channels, keep) if kept), delta[0][keep], delta[1][keep], delta[2][keep])


@dataclass(frozen=True)
class HealthVerdict:
    """``diverged`` with the ``kind`` of sign (nonfinite, bounds, nis, rejections) and a sentence."""

    diverged: bool
    kind: str | None = None
    reason: str | None = None


def assess_health(window: AidingWindow | None, d: np.ndarray, phi: np.ndarray, e: np.ndarray, bounds: StateBounds,
                  config: HealthConfig = HealthConfig()) -> HealthVerdict:
    """Whether the filter diverged over a window.

    Parameters
    ----------
    window : the aiding updates of the window (None: not judged).
    d, phi, e : (n,) the states of the window: support position (m), attitude (rad; zeros for a
        fixed support), tip deflection (m).
    bounds : ``physical_bounds`` of the rig.
    config : HealthConfig

    Returns
    -------
    HealthVerdict
    """
    d, phi, e = (np.asarray(a, dtype=float) for a in (d, phi, e))
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(phi)) and np.all(np.isfinite(e))):
        return HealthVerdict(True, "nonfinite", "the state is not finite")
    for name, values, limit, unit in (("d", d, bounds.d_max_m, "m"), ("φ", phi, bounds.phi_max_rad, "rad"),
                                      ("e", e, bounds.tip_max_m, "m")):
        if values.size and float(np.max(np.abs(values))) > limit:
            worst = float(values[np.argmax(np.abs(values))])
            return HealthVerdict(True, "bounds", f"{name} = {worst:.3g} {unit} is beyond what the rig can do (|{name}| ≤ {limit:.3g} {unit})")
    if window is None or window.updates < config.min_updates:
        return HealthVerdict(False)
    mean = window.mean_nis
    if mean is not None and window.accepted.sum() >= config.min_updates and mean > config.nis_limit:
        return HealthVerdict(True, "nis", f"mean NIS {mean:.3g} of the accepted aiding updates exceeds {config.nis_limit:g}")
    total = window.accepted + window.rejected
    active = total > 0
    refusing = active & (window.rejected >= config.reject_fraction * np.maximum(total, 1))
    n_active, n_refusing = int(active.sum()), int(refusing.sum())
    if n_refusing >= 2 and 2 * n_refusing >= n_active:
        names = [c for c, r in zip(window.channels, refusing) if r]
        return HealthVerdict(True, "rejections", f"the gate refused {int(window.rejected[refusing].sum())} of "
                                                 f"{int(total[refusing].sum())} updates of {', '.join(names)}")
    return HealthVerdict(False)


def gauges_beyond_basis(window: AidingWindow | None, config: HealthConfig = HealthConfig()) -> tuple[str, ...]:
    """The strain-gauge channels of ``window`` that disagree with the filter on their own: a mean
    NIS of their accepted updates above ``config.nis_limit``, or the gate refusing at least
    ``config.reject_fraction`` of them (each with at least ``config.min_updates`` updates).

    A gauge reads the whole curvature; the filter predicts only that of its unit deformations. When
    modes above them carry much of the strain, the gauges alone disagree, and a new filter from the
    same measurements would disagree the same way: their model error, not the state, is what is wrong.

    Parameters
    ----------
    window : the aiding updates of a window (None: nothing to judge).
    config : HealthConfig

    Returns
    -------
    tuple of str
        The channels (``/strain/<name>``), in the window's order; empty when none disagrees.

    Examples
    --------
    >>> import numpy as np
    >>> w = AidingWindow(("/tof/t1", "/strain/g1", "/strain/g2"), np.array([50, 50, 0]), np.array([0, 0, 40]),
    ...                  np.array([50.0, 900.0, 0.0]))
    >>> gauges_beyond_basis(w)
    ('/strain/g1', '/strain/g2')
    """
    if window is None:
        return ()
    out = []
    for k, channel in enumerate(window.channels):
        if not channel.startswith("/strain/"):
            continue
        accepted, rejected = int(window.accepted[k]), int(window.rejected[k])
        if accepted + rejected < config.min_updates:
            continue
        high_nis = accepted >= config.min_updates and window.nis_sum[k] / accepted > config.nis_limit
        if high_nis or rejected >= config.reject_fraction * (accepted + rejected):
            out.append(channel)
    return tuple(out)


def gauge_disagreement(window: AidingWindow, channels: tuple[str, ...], gate: float) -> float:
    """How many times its expected variance the worst of ``channels`` saw: its accepted updates'
    mean NIS, or ``gate`` for a channel the gate refused at least a tenth of the time (the refused
    updates' NIS is above the gate; the accepted ones' mean understates it).

    Examples
    --------
    >>> import numpy as np
    >>> w = AidingWindow(("/strain/g1", "/strain/g2"), np.array([100, 50]), np.array([0, 50]), np.array([1200.0, 400.0]))
    >>> gauge_disagreement(w, ("/strain/g1",), 30.0), gauge_disagreement(w, ("/strain/g1", "/strain/g2"), 30.0)
    (12.0, 30.0)
    """
    worst = 1.0
    for k, channel in enumerate(window.channels):
        if channel not in channels:
            continue
        accepted, rejected = float(window.accepted[k]), float(window.rejected[k])
        if rejected >= 0.1 * (accepted + rejected):
            worst = max(worst, gate)
        elif accepted > 0:
            worst = max(worst, float(window.nis_sum[k]) / accepted)
    return worst


def restart_state(meas: Measurements, model: ImmsModel, calibration: RestCalibration) -> np.ndarray:
    """The state a restarted filter begins from, from the current measurements (means over
    ``meas``): d from the bearing's displacement, φ from the direction of D's specific force
    (its rest bias removed), b from the strain gauges by least squares over the aided unit
    deformations; every other state 0. States the measurements do not give stay 0.

    Returns
    -------
    (n,) array in the model's StateLayout.
    """
    layout = model.state_layout
    ix = layout.index
    x = np.zeros(layout.size)
    if meas.bearing is not None and meas.bearing.times.size:
        d = float(np.median(meas.bearing.values[:, 0]))
        if math.isfinite(d):
            x[ix.d] = d
    D = meas.imu.get("D")
    if layout.attitude and D is not None and D.times.size:
        f = np.mean(D.values[:, :2], axis=0) - calibration.bias_D[:2]
        if np.all(np.isfinite(f)) and np.hypot(*f) > 0.5 * model.rig.gravity:
            # hanging at rest: f ≈ g·(−cos φ, sin φ) in D's sensor frame (x along the beam, y across)
            if model.rig.orientation == "hanging":
                x[ix.phi] = math.atan2(f[1], -f[0])
    gauges = model.selection.gauges
    if gauges and all(g in meas.strain and meas.strain[g].times.size for g in gauges):
        eps = np.array([np.median(meas.strain[g].values[:, 0]) for g in gauges]) - calibration.strain_offset
        aided = [a - 1 for a in model.selection.aided] or list(range(model.gamma))
        K = model.strain_matrix()[:, aided]
        if np.all(np.isfinite(eps)) and K.size:
            b, *_ = np.linalg.lstsq(K, eps, rcond=None)
            if np.all(np.isfinite(b)):
                x[ix.b + np.array(aided)] = b
    return x
