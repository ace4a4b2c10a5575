"""Exact planar kinematics of material points of the plant (no small-angle shortcuts).

A material point at arc length x sits in the floating frame at p = (x + u, w), with
w = Σ Φ_i(x) q_i and the inextensible foreshortening u = −½ ∫₀ˣ w'² = −½ qᵀ G(x) q. Its
inertial acceleration in frame components is a_D + p̈ + 2Ω J ṗ + Ω̇ J p − Ω² p (J turns by +90°);
the specific force subtracts gravity, g_η e_η of the inertial frame (g_η = +g hanging, −g standing).
The local tangent is turned by α = arcsin(w') against the frame, and the curvature is
κ = w'' / cos α.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import NodalShapes

__all__ = ["PointMotion", "foreshortening_matrix", "point_motion", "points_motion"]

_GAUSS_XI, _GAUSS_W = np.polynomial.legendre.leggauss(6)
_GAUSS_XI = 0.5 * (_GAUSS_XI + 1.0)
_GAUSS_W = 0.5 * _GAUSS_W


def foreshortening_matrix(basis: NodalShapes, x: float) -> np.ndarray:
    """G(x) = ∫₀ˣ Φ'(ξ) Φ'(ξ)ᵀ dξ, shape (m, m): the exact integral of the Hermite slopes."""
    nodes = basis.nodes
    edges = np.append(nodes[nodes < x], x)
    if edges.size < 2:
        return np.zeros((basis.count, basis.count))
    a, b = edges[:-1], edges[1:]
    points = (a[:, None] + (b - a)[:, None] * _GAUSS_XI[None, :]).ravel()
    weights = ((b - a)[:, None] * _GAUSS_W[None, :]).ravel()
    slopes = basis.evaluate(points, 1)
    return np.einsum("k,ki,kj->ij", weights, slopes, slopes)


# keyed by (id of the basis, one arc length) for a point, (id, arc lengths) for points side by side
_SHAPES: dict[tuple[int, float | tuple[float, ...]], tuple] = {}
_SHAPES_MAX = 4096


def _point_shapes(basis: NodalShapes, x: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Φ(x), Φ'(x), Φ''(x) and G(x) of a material point: fixed for the point, so computed once
    per basis and arc length, not for every block (the simulation evaluates them per sensor)."""
    key = (id(basis), float(x))
    hit = _SHAPES.get(key)
    if hit is not None and hit[0] is basis:
        return hit[1]
    shapes = (basis.evaluate(x, 0), basis.evaluate(x, 1), basis.evaluate(x, 2), foreshortening_matrix(basis, x))
    for a in shapes:
        a.setflags(write=False)
    if len(_SHAPES) >= _SHAPES_MAX:
        _SHAPES.clear()
    _SHAPES[key] = (basis, shapes)  # the basis is held, so its id is not reused while cached
    return shapes


@dataclass(frozen=True)
class PointMotion:
    """Motion of one material point over N samples (arrays of shape (N,))."""

    lateral: np.ndarray  # w: body-frame ζ of the point (m) — the deflection Δ at this arc length
    slope_angle: np.ndarray  # α: tangent angle against the body frame (rad)
    curvature: np.ndarray  # κ (1/m)
    curvature_linear: np.ndarray  # w'' (1/m), ∂²Δ/∂η² of the contract
    specific_force_x: np.ndarray  # along the local tangent (m/s²)
    specific_force_y: np.ndarray  # across the beam, towards the reflector at rest (m/s²)
    rate: np.ndarray  # rotation rate of the local tangent (rad/s)
    inertial_eta: np.ndarray  # inertial η of the point (m)
    inertial_zeta: np.ndarray  # inertial ζ of the point (m)


def _stacked_shapes(basis: NodalShapes, xs: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``_point_shapes`` of several points side by side: Φ, Φ', Φ'' (m, S) and G (S, m, m)."""
    key = (id(basis), xs)
    hit = _SHAPES.get(key)
    if hit is not None and hit[0] is basis:
        return hit[1]
    each = [_point_shapes(basis, x) for x in xs]
    shapes = (np.column_stack([e[0] for e in each]), np.column_stack([e[1] for e in each]),
              np.column_stack([e[2] for e in each]), np.stack([e[3] for e in each]))
    for a in shapes:
        a.setflags(write=False)
    if len(_SHAPES) >= _SHAPES_MAX:
        _SHAPES.clear()
    _SHAPES[key] = (basis, shapes)
    return shapes


def point_motion(
    basis: NodalShapes,
    x: float,
    y: np.ndarray,
    yd: np.ndarray,
    ydd: np.ndarray,
    bearing: np.ndarray,
    bearing_acceleration: np.ndarray,
    gravity: float,
) -> PointMotion:
    """Kinematics of the point at arc length ``x`` from plant states y = [θ, q] (N, 1 + m).

    ``bearing`` and ``bearing_acceleration`` are d and d̈ (N,) in m and m/s². ``gravity`` is
    gravity's component along inertial η (m/s²): +g for a hanging beam, −g for a standing one
    (η points up along it), so a standing beam's accelerometers read +g along x at rest.
    """
    both = points_motion(basis, (x,), y, yd, ydd, bearing, bearing_acceleration, gravity)
    return PointMotion(*(getattr(both, f)[:, 0] for f in PointMotion.__dataclass_fields__))


def points_motion(
    basis: NodalShapes,
    xs: tuple[float, ...] | list[float],
    y: np.ndarray,
    yd: np.ndarray,
    ydd: np.ndarray,
    bearing: np.ndarray,
    bearing_acceleration: np.ndarray,
    gravity: float,
) -> PointMotion:
    """``point_motion`` of the points at arc lengths ``xs`` (S,) at once: every field of the
    result is (N, S), column s that of ``xs[s]`` (one pass over the states for all the sensors
    of a block instead of one per sensor)."""
    xs = tuple(float(x) for x in xs)
    phi, dphi, ddphi, G = _stacked_shapes(basis, xs)
    x = np.asarray(xs)[None, :]
    theta, omega, omega_dot = y[:, :1], yd[:, :1], ydd[:, :1]
    q, qd, qdd = y[:, 1:], yd[:, 1:], ydd[:, 1:]
    w, w_d, w_dd = q @ phi, qd @ phi, qdd @ phi
    slope, slope_d = q @ dphi, qd @ dphi
    w2 = q @ ddphi
    Gq = q @ G  # (S, N, m)
    u = (-0.5 * np.einsum("sni,ni->ns", Gq, q))
    u_d = -np.einsum("sni,ni->ns", Gq, qd)
    u_dd = -(np.einsum("sni,ni->ns", qd @ G, qd) + np.einsum("sni,ni->ns", Gq, qdd))
    eta = x + u
    ct, st = np.cos(theta), np.sin(theta)
    bearing_acceleration = np.asarray(bearing_acceleration)[:, None]
    accel_eta = bearing_acceleration * st + u_dd - 2 * omega * w_d - omega_dot * w - omega**2 * eta
    accel_zeta = bearing_acceleration * ct + w_dd + 2 * omega * u_d + omega_dot * eta - omega**2 * w
    force_eta = accel_eta - gravity * ct
    force_zeta = accel_zeta + gravity * st
    alpha = np.arcsin(np.clip(slope, -1.0, 1.0))
    ca, sa = np.cos(alpha), np.sin(alpha)
    return PointMotion(
        lateral=w,
        slope_angle=alpha,
        curvature=w2 / ca,
        curvature_linear=w2,
        specific_force_x=ca * force_eta + sa * force_zeta,
        specific_force_y=-sa * force_eta + ca * force_zeta,
        rate=omega + slope_d / ca,
        inertial_eta=ct * eta - st * w,
        inertial_zeta=np.asarray(bearing)[:, None] + st * eta + ct * w,
    )
