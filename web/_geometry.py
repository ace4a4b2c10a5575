"""Geometry of the live beam: pure numpy, no viser (unit-testable).

Frames (recording contract): the inertial frame has η along the beam at rest (down along
gravity for a hanging beam, up for a standing mast) and ζ horizontal towards the reflector,
origin at the bearing's rest position. The body frame sits at the bearing
D = (h, d) (h along η, d along ζ) and is turned by φ (positive φ turns η towards ζ). A point at arc
length η with elastic deflection Δ(η) = Σ b_χ s_χ(η) (body frame, across the beam) sits at

    r = D + R(φ) [η, Δ]    i.e.    η_I = h + cos φ·η − sin φ·Δ,   ζ_I = d + sin φ·η + cos φ·Δ.

World (viewer) coordinates: x = ζ, y = across the sheet's width, z up: z = −η for a hanging
beam, z = +η for a standing one (``standing=True``), so a mast is drawn upright. Overscaling
multiplies the elastic part Δ (and the slope Δ′) by ``elastic_scale`` and the rigid motion
(h, d, φ) by ``rigid_scale``, like the paper's Figure 15.

A beam that bends in two planes also deflects by Δξ(η) = Σ bξ sξ(η) along ξ = η × ζ, which is
world +y for a standing beam and −y for a hanging one (``lateral``); a clamp holds it (φ ≡ 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from contract import StateLayout

__all__ = [
    "BeamState",
    "clamp_boxes",
    "lateral",
    "UnitShapes",
    "centreline",
    "parse_state",
    "ribbon",
    "ribbon_faces",
    "segments",
    "tangent_angle",
    "tof_rays",
    "to_world",
    "up_sign",
]

#: Rays are drawn at most this long (m) when a ToF's axis is nearly parallel to the reflector.
MAX_RAY_LENGTH = 5.0


class UnitShapes(Protocol):
    """What the geometry needs of ``estimator.UnitDeformations``."""

    @property
    def count(self) -> int: ...

    def shape(self, eta: np.ndarray | float) -> np.ndarray: ...

    def slope(self, eta: np.ndarray | float) -> np.ndarray: ...


@dataclass(frozen=True)
class BeamState:
    """The part of the estimator state the picture needs: d, h (m), φ (rad), b (Γ,), and bξ (Γξ,)
    of a beam that bends in two planes (empty for a planar one)."""

    d: float
    h: float
    phi: float
    b: np.ndarray
    b_xi: np.ndarray = field(default_factory=lambda: np.zeros(0))


def parse_state(x: object, layout: StateLayout) -> BeamState:
    """Validate an estimator state vector and pick the beam part through its ``layout``.

    Raises ValueError (naming the problem) for a non-1-D, wrong-length or non-finite vector.
    """
    if not isinstance(layout, StateLayout):
        raise ValueError(f"layout must be a contract.StateLayout, got {type(layout).__name__}")
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"state vector x must be numeric: {exc}") from None
    if arr.ndim != 1:
        raise ValueError(f"state vector x must be 1-D, got shape {arr.shape}")
    arr = layout.check(arr)
    d, h, phi, b = arr[layout.d], arr[layout.h], float(layout.phi_of(arr)), layout.b_of(arr)
    b_xi = layout.b_xi_of(arr)
    if not (np.isfinite(d) and np.isfinite(h) and np.isfinite(phi) and np.all(np.isfinite(b)) and np.all(np.isfinite(b_xi))):
        raise ValueError("state vector x has NaN or infinite values in d, h, phi, b or b_xi")
    return BeamState(d=float(d), h=float(h), phi=phi, b=b.copy(), b_xi=b_xi.copy())


def _place(state: BeamState, eta: np.ndarray, delta: np.ndarray, rigid_scale: float) -> np.ndarray:
    phi = rigid_scale * state.phi
    cp, sp = np.cos(phi), np.sin(phi)
    out = np.empty((eta.size, 2))
    out[:, 0] = rigid_scale * state.h + cp * eta - sp * delta
    out[:, 1] = rigid_scale * state.d + sp * eta + cp * delta
    return out


def _check_scales(elastic_scale: float, rigid_scale: float) -> None:
    for name, value in (("elastic_scale", elastic_scale), ("rigid_scale", rigid_scale)):
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"{name}={value!r} must be finite and >= 0")


def centreline(
    state: BeamState,
    units: UnitShapes,
    eta: np.ndarray,
    *,
    elastic_scale: float = 1.0,
    rigid_scale: float = 1.0,
    deflection: np.ndarray | None = None,
) -> np.ndarray:
    """Inertial (η_I, ζ_I) of the beam's centre line at arc lengths ``eta``: shape (len(eta), 2).

    ``deflection`` (len(eta),) replaces Σ b s(η) (used for the truth shape, which comes as Δ at
    stations); the rigid motion is the state's either way.
    """
    _check_scales(elastic_scale, rigid_scale)
    eta = np.atleast_1d(np.asarray(eta, dtype=float))
    if eta.ndim != 1:
        raise ValueError(f"eta must be 1-D, got shape {eta.shape}")
    if deflection is None:
        delta = units.shape(eta) @ state.b
    else:
        delta = np.asarray(deflection, dtype=float)
        if delta.shape != eta.shape:
            raise ValueError(f"deflection has shape {delta.shape}, expected {eta.shape} (one value per station)")
    return _place(state, eta, elastic_scale * delta, rigid_scale)


def lateral(state: BeamState, units_xi: UnitShapes | None, eta: np.ndarray, *, elastic_scale: float = 1.0,
            standing: bool = False) -> np.ndarray:
    """World y (len(eta),) of the centre line: the ξ deflection Σ bξ sξ(η) overscaled, signed as ξ
    lies in the world (+y standing, −y hanging); zeros for a planar beam (``units_xi`` None)."""
    _check_scales(elastic_scale, 1.0)
    eta = np.atleast_1d(np.asarray(eta, dtype=float))
    if units_xi is None or state.b_xi.size == 0:
        return np.zeros(eta.shape)
    return up_sign(standing) * elastic_scale * (units_xi.shape(eta) @ state.b_xi)


def tangent_angle(
    state: BeamState, units: UnitShapes, eta: np.ndarray, *, elastic_scale: float = 1.0, rigid_scale: float = 1.0
) -> np.ndarray:
    """Angle of the beam's tangent from the inertial η axis (rad, positive towards ζ) at ``eta``."""
    _check_scales(elastic_scale, rigid_scale)
    eta = np.atleast_1d(np.asarray(eta, dtype=float))
    return rigid_scale * state.phi + elastic_scale * (units.slope(eta) @ state.b)


def up_sign(standing: bool) -> float:
    """World z per unit inertial η: −1 hanging (η points down), +1 standing (η points up the mast)."""
    if standing is True:
        return 1.0
    if standing is False:
        return -1.0
    raise ValueError(f"standing={standing!r} must be True or False")


def to_world(plane: np.ndarray, y: float | np.ndarray = 0.0, *, standing: bool = False) -> np.ndarray:
    """(N, 2) inertial (η, ζ) → (N, 3) world (x = ζ, y, z = ∓η: −η hanging, +η standing), float32."""
    sign = up_sign(standing)
    plane = np.asarray(plane, dtype=float)
    if plane.ndim != 2 or plane.shape[1] != 2:
        raise ValueError(f"plane points must have shape (N, 2), got {plane.shape}")
    out = np.empty((plane.shape[0], 3), dtype=np.float32)
    out[:, 0] = plane[:, 1]
    out[:, 1] = y
    out[:, 2] = sign * plane[:, 0]
    return out


def ribbon_faces(n: int) -> np.ndarray:
    """Triangles of a ribbon over ``n`` centre-line points (vertex 2i: y = −w/2, 2i+1: y = +w/2)."""
    if n < 2:
        raise ValueError(f"a ribbon needs at least 2 centre-line points, got {n}")
    i = np.arange(n - 1, dtype=np.uint32)
    a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
    return np.concatenate([np.stack([a, c, b], axis=1), np.stack([b, c, d], axis=1)]).astype(np.uint32)


def ribbon(plane: np.ndarray, width: float | np.ndarray, *, standing: bool = False,
           offset: np.ndarray | None = None) -> np.ndarray:
    """Vertices (2N, 3) of the sheet: each centre-line point at y = −w/2 and y = +w/2 (world).

    ``width`` (m) is one figure, or one per centre-line point (a taper: a tube's diameter, a
    blade's depth along it). ``offset`` (N,): the centre line's world y (``lateral``: a beam that
    bends in ξ too), 0 when None.
    """
    w = np.asarray(width, dtype=float)
    n = np.shape(plane)[0]
    if w.ndim > 1 or (w.ndim == 1 and w.size != n) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"width={width!r} must be finite and > 0, one figure or one per point ({n})")
    width = w if w.ndim == 0 else w.astype(np.float32)
    centre = to_world(plane, standing=standing)
    verts = np.repeat(centre, 2, axis=0)
    verts[0::2, 1] = -0.5 * width
    verts[1::2, 1] = 0.5 * width
    if offset is not None:
        y = np.asarray(offset, dtype=np.float32)
        if y.shape != (n,):
            raise ValueError(f"offset has shape {y.shape}, expected ({n},) (one per centre-line point)")
        verts[0::2, 1] += y
        verts[1::2, 1] += y
    return verts


def segments(points: np.ndarray) -> np.ndarray:
    """A polyline (N, 3) as line segments (N−1, 2, 3) for ``add_line_segments``."""
    points = np.asarray(points, dtype=np.float32)
    return np.stack([points[:-1], points[1:]], axis=1)


def tof_rays(
    state: BeamState,
    units: UnitShapes,
    eta: np.ndarray,
    reflector_distance: float,
    *,
    elastic_scale: float = 1.0,
    rigid_scale: float = 1.0,
    standing: bool = False,
) -> np.ndarray:
    """World segments (n, 2, 3) from each ToF at ``eta`` along its +y axis to the reflector plane.

    The sensor's y axis is the beam normal (−sin α, cos α) in (η, ζ), α the tangent angle; the
    ray ends where it meets ζ = reflector_distance (length (ζ_ref − ζ)/cos α, Eq. (18)), capped at
    ``MAX_RAY_LENGTH`` and never negative.
    """
    eta = np.atleast_1d(np.asarray(eta, dtype=float))
    if eta.size == 0:
        return np.zeros((0, 2, 3), dtype=np.float32)
    start = centreline(state, units, eta, elastic_scale=elastic_scale, rigid_scale=rigid_scale)
    alpha = tangent_angle(state, units, eta, elastic_scale=elastic_scale, rigid_scale=rigid_scale)
    ca, sa = np.cos(alpha), np.sin(alpha)
    gap = reflector_distance - start[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        length = np.where(ca > 1e-6, gap / np.where(ca > 1e-6, ca, 1.0), MAX_RAY_LENGTH)
    length = np.clip(length, 0.0, MAX_RAY_LENGTH)
    end = start + length[:, None] * np.stack([-sa, ca], axis=1)
    return np.stack([to_world(start, standing=standing), to_world(end, standing=standing)], axis=1)


#: The clamp's jaws (m): how far they grip along the beam, their thickness across it (ζ) and how
#: far they reach past the sheet's edges; the carriage block they sit on, on the rail's side of D.
CLAMP_GRIP, CLAMP_JAW, CLAMP_OVERHANG, CLAMP_BASE = 0.10, 0.035, 0.03, 0.06


def clamp_boxes(state: BeamState, width: float, *, rigid_scale: float = 1.0, standing: bool = False,
                ) -> tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]:
    """(centre, dimensions) in world coordinates of a clamped support's three boxes: the two jaws
    gripping the root of the sheet on either face (ζ) over ``CLAMP_GRIP`` of its length, and the
    carriage block below them (on the rail's side of D). They move with the support (d, h); a
    clamp does not turn (φ ≡ 0)."""
    if not np.isfinite(width) or width <= 0:
        raise ValueError(f"width={width!r} must be finite and > 0")
    _check_scales(1.0, rigid_scale)
    up = up_sign(standing)
    x = rigid_scale * state.d
    z = up * rigid_scale * state.h
    span_y = width + 2 * CLAMP_OVERHANG
    jaw_z = z + up * 0.5 * CLAMP_GRIP
    jaws = tuple(
        ((x + side * 0.5 * CLAMP_JAW + side * 0.002, 0.0, jaw_z), (CLAMP_JAW, span_y, CLAMP_GRIP)) for side in (-1.0, 1.0)
    )
    base = ((x, 0.0, z - up * 0.5 * CLAMP_BASE), (2 * CLAMP_JAW + 0.004 + 0.03, span_y + 0.02, CLAMP_BASE))
    return (*jaws, base)
