"""The virtual rig's second bending plane: the ξ twin of a rig, its sections around the outline,
and the exact kinematics of a material point that bends in both planes.

Frames and signs follow the contract (recording-format.md, "Bending in two planes"): ξ = η × ζ,
the sensor z axis points along +ξ at rest; a biaxial beam is clamped, so the body frame does not
turn (θ ≡ 0) and the support moves D along ζ only.

The ξ plane is its own plant: the FE beam of the *ξ twin* of the description (the same beam with
its ξ section properties in place of the ζ ones: a rectangle's width and thickness swapped, a
table's ``bending_stiffness_xi`` and ``fibre_distance_xi``, a tube unchanged), clamped modes of its
own, its own integration. Nothing of the estimator's two-plane model is used.

Kinematics (no small-angle shortcuts). A point at arc length x sits at p = (x + u, d + w, v) with
w = Φ_ζ q, v = Φ_ξ r and the inextensible foreshortening u = −½ (qᵀ G_ζ q + rᵀ G_ξ r). The
section's frame is the rotation without twist that turns e_η onto the tangent: its rotation
vector is ρ = k(σ) (0, −v', w') with σ = √(w'² + v'²), k = arcsin σ / σ (for ζ alone the planar
rig's α = arcsin w'). Its angular rate (sensor frame) is J_r(ρ) ρ̇ and its bending curvature
J_r(ρ) ρ' (J_r the right Jacobian of SO(3)), so κζ is the z component, κξ minus the y component,
and the gyro's y axis reads minus the rate of the ξ tangent. The twist component of this frame
(second order in the slopes) is not a reading of the contract: gyro x carries only noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from contract import RigDescription, Sensor, parse_rig
from estimator import NodalShapes

from ._kinematics import _stacked_shapes

__all__ = ["BiaxialMotion", "bending_of", "biaxial_points_motion", "gauge_angle", "gauge_point", "wind_angle", "xi_twin"]

BENDINGS = ("planar", "biaxial")


def bending_of(rig: RigDescription) -> str:
    """``beam.bending`` of ``rig`` ("planar" or "biaxial"; the contract's default "planar").

    Raises
    ------
    ValueError
        For another value, or a biaxial beam that is not clamped (the support must hold both planes).
    """
    bending = getattr(rig.beam, "bending", None) or "planar"
    if bending not in BENDINGS:
        raise ValueError(f"beam.bending={bending!r} must be one of {BENDINGS}")
    if bending == "biaxial" and rig.support != "clamped":
        raise ValueError(f"beam.bending='biaxial' needs support='clamped' (support={rig.support!r} holds the beam in ζ only)")
    return bending


def _table_xi(station, index: int, key: str) -> float:
    value = getattr(station, key, None)
    if value is None or not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"beam.sections[{index}].{key}={value!r}: a table station of a biaxial beam needs it (> 0)")
    return float(value)


def xi_twin(rig: RigDescription) -> RigDescription:
    """The rig whose ζ plane is ``rig``'s ξ plane: its FE beam is the ξ plant's (module docstring).

    Raises
    ------
    ValueError
        A table station without ``bending_stiffness_xi`` or ``fibre_distance_xi``.
    """
    data = rig.model_dump(mode="json")
    beam = data["beam"]
    beam.pop("bending", None)
    # The twin serves its FE beam only: its gauges' and hot spots' angles around the section (which a
    # planar description refuses) do not belong to it.
    for item in (*data["sensors"], *data.get("hot_spots", ())):
        item.pop("angle_deg", None)
    if beam.get("sections") is None:
        beam["width"], beam["thickness"] = beam["thickness"], beam["width"]
    else:
        typed_sections = rig.beam.sections
        assert typed_sections is not None, "the dump of a beam with sections is the dump of its sections"
        for index, (station, typed) in enumerate(zip(beam["sections"], typed_sections)):
            if station["shape"] == "rectangle":
                station["width"], station["thickness"] = station["thickness"], station["width"]
            elif station["shape"] == "table":
                station["bending_stiffness"] = _table_xi(typed, index, "bending_stiffness_xi")
                station["fibre_distance"] = _table_xi(typed, index, "fibre_distance_xi")
            elif station["shape"] == "tube":
                pass  # the same in both planes
            else:
                raise ValueError(f"beam.sections[{index}].shape={station['shape']!r} must be 'rectangle', 'tube' or 'table'")
    return parse_rig(data, source="the ξ plane of rig.json")


def gauge_angle(sensor: Sensor, index: int, biaxial: bool) -> float:
    """``angle_deg`` of a gauge (default 0); a planar beam accepts only 0 and 180."""
    angle = getattr(sensor, "angle_deg", None)
    angle = 0.0 if angle is None else angle
    if not (isinstance(angle, (int, float)) and math.isfinite(angle)):
        raise ValueError(f"sensors[{index}].angle_deg={angle!r} ({sensor.name!r}) must be a number of degrees")
    if not biaxial and angle % 360 not in (0.0, 180.0):
        raise ValueError(f"sensors[{index}].angle_deg={angle!r} ({sensor.name!r}): a planar beam accepts only 0 and 180")
    return float(angle)


def gauge_point(rig: RigDescription, twin: RigDescription | None, position: float, angle_deg: float) -> tuple[float, float]:
    """(ζp, ξp) in m: where the ray from the section's centre at ``angle_deg`` (from +ζ towards +ξ)
    meets its outline at ``position``: a circle for a tube, the rectangle of half-sides c_ζ, c_ξ
    otherwise (``twin``: the ξ twin, whose fibre distance is c_ξ; None for a planar beam, whose
    angles are 0 or 180)."""
    c_zeta = float(rig.beam.fibre_distance(position))
    theta = math.radians(angle_deg)
    if twin is None:
        return (c_zeta if angle_deg % 360 == 0 else -c_zeta), 0.0
    c_xi = float(twin.beam.fibre_distance(position))
    ct, st = math.cos(theta), math.sin(theta)
    stations = rig.beam.sections
    if stations is not None and _shape_at(rig, position) == "tube":
        return c_zeta * ct, c_zeta * st
    reach = min(c_zeta / abs(ct) if abs(ct) > 1e-15 else math.inf, c_xi / abs(st) if abs(st) > 1e-15 else math.inf)
    return reach * ct, reach * st


def _shape_at(rig: RigDescription, position: float) -> str:
    sections = rig.beam.sections
    assert sections is not None, "asked only of a beam described by its stations (gauge_point)"
    positions = rig.beam.station_positions
    j = int(np.clip(np.searchsorted(positions, position, side="right") - 1, 0, len(positions) - 1))
    return sections[j].shape


def wind_angle(t: np.ndarray, mean_deg: float, veer_deg: float, period_s: float) -> np.ndarray:
    """ψ(t) (rad): the direction the wind load acts in, from +ζ towards +ξ, veering about its mean,
    ψ = mean + veer · sin(2π t / period).

    Examples
    --------
    >>> np.degrees(wind_angle(np.array([0.0, 150.0, 300.0]), 25.0, 30.0, 600.0)).round(6).tolist()
    [25.0, 55.0, 25.0]
    """
    if not (math.isfinite(period_s) and period_s > 0):
        raise ValueError(f"the wind's veer period_s={period_s} must be positive")
    t = np.asarray(t, dtype=float)
    return np.radians(mean_deg + veer_deg * np.sin(2 * np.pi * t / period_s))


@dataclass(frozen=True)
class BiaxialMotion:
    """Motion of material points over N samples, fields (N, S) (module docstring)."""

    lateral: np.ndarray  # w = Δζ (m)
    lateral_xi: np.ndarray  # v = Δξ (m)
    specific_force: np.ndarray  # (3, N, S) sensor x, y, z (m/s²)
    rate: np.ndarray  # (3, N, S) angular rate about sensor x, y, z (rad/s); x is the frame's twist
    curvature: np.ndarray  # κζ (1/m), exact
    curvature_xi: np.ndarray  # κξ (1/m), exact
    inertial: np.ndarray  # (3, N, S) η, ζ, ξ of the point (m)
    y_axis: np.ndarray  # (3, N, S) the sensor's y axis in the inertial frame


def _small(gamma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """sin γ/γ, (1 − cos γ)/γ², (γ − sin γ)/γ³ without cancellation at small γ."""
    g2 = gamma * gamma
    small = gamma < 1e-3
    safe = np.where(small, 1.0, gamma)
    A = np.where(small, 1 - g2 / 6 + g2 * g2 / 120, np.sin(safe) / safe)
    B = np.where(small, 0.5 - g2 / 24 + g2 * g2 / 720, (1 - np.cos(safe)) / safe**2)
    C = np.where(small, 1 / 6 - g2 / 120 + g2 * g2 / 5040, (safe - np.sin(safe)) / safe**3)
    return A, B, C


def _arcsin_ratio(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """k = arcsin σ / σ and h = (dk/dσ)/σ, series below σ = 1e-3."""
    s2 = sigma * sigma
    small = sigma < 1e-3
    safe = np.where(small, 0.5, sigma)
    k = np.where(small, 1 + s2 / 6 + 3 * s2 * s2 / 40, np.arcsin(safe) / safe)
    h = np.where(small, 1 / 3 + 0.3 * s2 + 15 / 56 * s2 * s2,
                 (safe / np.sqrt(1 - safe**2) - np.arcsin(safe)) / safe**3)
    return k, h


def _rho_and_rate(sz, sx, dz, dx):
    """ρ = (0, a, b) of slopes (w', v') = (sz, sx) and its derivative from (dz, dx) = d/d(t or x) of them."""
    sigma = np.sqrt(sz * sz + sx * sx)
    k, h = _arcsin_ratio(np.clip(sigma, 0.0, 1.0))
    dot = h * (sz * dz + sx * dx)
    a, b = -k * sx, k * sz
    ua, ub = -(k * dx + dot * sx), k * dz + dot * sz
    return a, b, ua, ub, np.arcsin(np.clip(sigma, 0.0, 1.0))


def _jr(a, b, ua, ub, C):
    """J_r(ρ) (0, ua, ub) for ρ = (0, a, b): its y and z components (the x one is the twist)."""
    cross = b * ua - a * ub
    return ua - C * b * cross, ub + C * a * cross


def biaxial_points_motion(
    basis: NodalShapes, basis_xi: NodalShapes, xs: tuple[float, ...] | list[float],
    q: tuple[np.ndarray, np.ndarray, np.ndarray], r: tuple[np.ndarray, np.ndarray, np.ndarray],
    bearing: np.ndarray, bearing_acceleration: np.ndarray, gravity: float,
) -> BiaxialMotion:
    """Kinematics of the points at arc lengths ``xs`` of a clamped biaxial beam.

    ``q`` and ``r`` are the (coordinates, rates, accelerations) of the ζ and ξ modal bases, each
    (N, m); ``bearing``, ``bearing_acceleration`` are d and d̈ (N,) along ζ; ``gravity`` is g_η
    (+g hanging, −g standing).
    """
    xs = tuple(float(x) for x in xs)
    out = []
    for b, (c, cd, cdd) in ((basis, q), (basis_xi, r)):
        phi, dphi, ddphi, G = _stacked_shapes(b, xs)
        Gq = c @ G
        out.append((c @ phi, cd @ phi, cdd @ phi, c @ dphi, cd @ dphi, c @ ddphi,
                    -0.5 * np.einsum("sni,ni->ns", Gq, c), -np.einsum("sni,ni->ns", Gq, cd),
                    -(np.einsum("sni,ni->ns", cd @ G, cd) + np.einsum("sni,ni->ns", Gq, cdd))))
    (w, _, w_dd, sz, sz_d, sz_x, uz, uz_d, uz_dd), (v, _, v_dd, sx, sx_d, sx_x, ux, ux_d, ux_dd) = out
    del uz_d, ux_d
    x = np.asarray(xs)[None, :]
    d_acc = np.asarray(bearing_acceleration, dtype=float)[:, None]
    eta = x + uz + ux
    f = np.stack([uz_dd + ux_dd - gravity, d_acc + w_dd, v_dd + 0.0 * eta])
    a, b, ua, ub, gamma = _rho_and_rate(sz, sx, sz_d, sx_d)
    _, _, ka, kb, _ = _rho_and_rate(sz, sx, sz_x, sx_x)
    A, B, C = _small(gamma)
    # R = I + A[ρ]× + B[ρ]×² for ρ = (0, a, b); columns are the sensor axes in the inertial frame.
    R = np.empty((3, 3) + a.shape)
    R[0, 0], R[0, 1], R[0, 2] = 1 - B * gamma**2, -A * b, A * a
    R[1, 0], R[1, 1], R[1, 2] = A * b, 1 - B * b * b, B * a * b
    R[2, 0], R[2, 1], R[2, 2] = -A * a, B * a * b, 1 - B * a * a
    force = np.einsum("ji...,j...->i...", R, f)  # Rᵀ f
    wy, wz = _jr(a, b, ua, ub, C)
    ky, kz = _jr(a, b, ka, kb, C)
    rate = np.stack([np.zeros_like(wy), wy, wz])
    inertial = np.stack([eta, np.asarray(bearing, dtype=float)[:, None] + w, v + 0.0 * eta])
    return BiaxialMotion(lateral=w, lateral_xi=v, specific_force=force, rate=rate, curvature=kz, curvature_xi=-ky,
                         inertial=inertial, y_axis=R[:, 1])
