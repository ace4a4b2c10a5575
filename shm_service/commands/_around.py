"""``shm loads`` around the section: stations at an angle (``--stations 5.0@45``), hot spots at an
angle or all around (``"angle_deg": "all"``), the strain there from both planes' curvature
(ε = −(ζp·κζ + ξp·κξ), ``analytics.section_strain``) and the root bending moment per plane with
its resultant. A planar beam's stations sit at 0 (or 180): its figures are those of the +ζ face.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Literal

__all__ = ["XI_MISSING", "parse_station_points", "root_planes", "station_points", "station_signals", "virtual_at_gauge", "xi_of"]

#: Said when a biaxial beam's estimate carries no ξ plane: its figures leave the ξ curvature out.
XI_MISSING = ("the beam bends in two planes (beam.bending = 'biaxial') but the estimate carries no ξ plane (no b_xi): "
              "strain, stress and moments leave the ξ curvature out, so points off the ζ faces and the root moment's "
              "resultant are understated")


def parse_station_points(text: str, length: float, error: type[ValueError] = ValueError) -> tuple[tuple[float, float], ...]:
    """'5.0@45,12.5@225,3' → ((5.0, 45.0), (12.5, 225.0), (3.0, 0.0)): η (m, on [0, length]) @ angle
    (degrees from +ζ towards +ξ; a plain η is at 0, the +ζ face)."""
    values = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        eta_text, _, angle_text = part.partition("@")
        try:
            eta = float(eta_text)
            angle = float(angle_text) if angle_text.strip() else 0.0
        except ValueError:
            raise error(f"--stations: {part!r} is not η (m) or η@angle (m@degrees), e.g. 5.0@45") from None
        if "@" in part and not angle_text.strip():
            raise error(f"--stations: {part!r} gives no angle after '@' (η@degrees, e.g. 5.0@45)")
        if not (math.isfinite(eta) and 0.0 <= eta <= length):
            raise error(f"--stations: {eta_text.strip()} is outside the beam [0, {length}]")
        if not math.isfinite(angle):
            raise error(f"--stations: {part!r}: the angle must be finite degrees")
        values.append((eta, angle))
    if not values:
        raise error(f"--stations {text!r} names no station")
    return tuple(values)


def station_points(rig: Any, stations: Any) -> tuple[list[tuple[float, float | str]], dict]:
    """The stations as (η, angle) sorted by η then angle (the rig's hot spots with theirs, "all" last at
    its η), and the hot spot at each. ``stations``: None (a grid of 15 at L/16 steps, angle 0), or
    positions (m) or (η, angle) pairs."""
    import numpy as np

    spots = {(round(h.position, 9), h.angle_deg if h.angle_deg == "all" else float(h.angle_deg)): h for h in rig.hot_spots}
    grid = stations if stations is not None else tuple(np.linspace(0.0, rig.beam.length, 17)[1:-1])
    points = {(round(float(p), 9), 0.0) if np.ndim(p) == 0 else (round(float(p[0]), 9), float(p[1])) for p in grid}
    ordered = sorted(points | set(spots), key=lambda k: (k[0], math.inf if k[1] == "all" else k[1]))
    return ordered, spots


def xi_of(record: Any, keep: Any = None) -> tuple[Any, Any] | None:
    """(b_ξ on the kept samples, the ξ unit deformations) of a record that has the ξ plane, else None."""
    b_xi = getattr(record, "b_xi", None)
    if b_xi is None or getattr(record, "units_xi", None) is None:
        return None
    return (b_xi if keep is None else b_xi[keep]), record.units_xi


def station_signals(beam: Any, b: Any, units: Any, xi: tuple[Any, Any] | None, points: list, spots: dict, factor: Any, *,
                    detail_of: Callable[[Any], Any], exponents: tuple[float, ...], n_eq: float,
                    half_cycles: Literal["half", "full", "ignore"]) -> tuple[Any, Any, list[dict[str, Any]]]:
    """(strain (N, S), bending moment in ζ (N, S), per station its angle and, off the ζ plane, its ξ
    figures) at the ``points`` from b (N, Γ) and, when given, ``xi`` = (b_ξ, ξ unit deformations).

    A station of angle "all" is its worst point around the section (``analytics.worst_around`` over
    ``analytics.around_angles``: every 5 degrees and a rectangle's corners), by its hot spot's detail."""
    import numpy as np

    from analytics import around_angles, bending_moment, outline_corners, section_strain, worst_around

    eta = np.array([p for p, _ in points], dtype=float)
    kappa = b @ units.curvature(eta).T
    kappa_xi = None if xi is None else xi[0] @ xi[1].curvature(eta).T
    strain = np.empty_like(kappa)
    extras: list[dict[str, Any]] = []
    for j, (pos, angle) in enumerate(points):
        if angle != "all":
            zeta_p, xi_p = beam.section_point(pos, angle)
            strain[:, j] = section_strain(kappa[:, j:j + 1], [zeta_p], None if kappa_xi is None else kappa_xi[:, j:j + 1],
                                          None if kappa_xi is None else [xi_p])[:, 0]
            extras.append({"angle_deg": float(angle)})
            continue
        angles = around_angles(outline_corners(beam, pos))
        zeta_p, xi_p = beam.section_point(np.full(angles.size, pos), angles)
        ring = section_strain(np.repeat(kappa[:, j:j + 1], angles.size, axis=1), zeta_p,
                              None if kappa_xi is None else np.repeat(kappa_xi[:, j:j + 1], angles.size, axis=1),
                              None if kappa_xi is None else xi_p)
        detail = detail_of(spots.get((pos, angle))) if beam.youngs_modulus is not None else None
        worst, _loads, judged = worst_around(ring, angles, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, detail=detail,
                                             to_stress=beam.youngs_modulus or 1.0)
        strain[:, j] = ring[:, worst]
        extras.append({"angle_deg": float(angles[worst]), "angle_spec": "all", "angles_evaluated": int(angles.size),
                       "worst_by": f"{judged} over {angles.size} points around the section (every 5 degrees and the outline's corners)"})
    moment = bending_moment(kappa, beam.bending_stiffness(eta)) * factor[:, None]
    if kappa_xi is not None:
        moment_xi = bending_moment(kappa_xi, beam.bending_stiffness_xi(eta)) * factor[:, None]
        for j, extra in enumerate(extras):
            extra.update(bending_moment_xi_rms_nm=float(np.sqrt(np.mean(moment_xi[:, j] ** 2))),
                         bending_moment_resultant_max_nm=float(np.max(np.hypot(moment[:, j], moment_xi[:, j]))))
    return strain, moment, extras


def virtual_at_gauge(beam: Any, sensor: Any, b: Any, units: Any, xi: tuple[Any, Any] | None) -> Any:
    """The virtual strain (n,) at a gauge's point of the section (its position and ``angle_deg``)."""
    import numpy as np

    from analytics import section_strain, virtual_strain

    at = np.array([sensor.position], dtype=float)
    if xi is None and sensor.angle_deg == 0.0:  # the +ζ face: the planar contract's −c·κ
        return virtual_strain(b, units.curvature(at), beam.fibre_distance(at))[:, 0]
    zeta_p, xi_p = beam.section_point(sensor.position, sensor.angle_deg)
    kappa = b @ units.curvature(at).T
    kappa_xi = None if xi is None else xi[0] @ xi[1].curvature(at).T
    return section_strain(kappa, [zeta_p], kappa_xi, None if xi is None else [xi_p])[:, 0]


def root_planes(root: dict[str, Any], b: Any, units: Any, xi: tuple[Any, Any], beam: Any, factor: Any, exponents: Any,
                n_eq: float, half_cycles: Literal["half", "full", "ignore"]) -> dict[str, Any]:
    """The root bending moment of a biaxial beam: (Mζ, Mξ) = EI·κ per plane at η = 0 and the resultant
    √(Mζ² + Mξ²); ``root`` is the ζ plane's entry (kept at the top level as for a planar beam)."""
    import numpy as np

    from analytics import bending_moment, resultant_moment, signal_loads

    zero = np.array([0.0])
    m_zeta = bending_moment(b @ units.curvature(zero).T, beam.bending_stiffness([0.0]))[:, 0] * factor
    m_xi = bending_moment(xi[0] @ xi[1].curvature(zero).T, beam.bending_stiffness_xi([0.0]))[:, 0] * factor
    xl = signal_loads(m_xi, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name="root bending moment in ξ")
    resultant = resultant_moment(m_zeta, m_xi)
    at = int(np.argmax(resultant))
    zeta = {k: root[k] for k in ("rms_nm", "range_max_nm", "del")}
    return {**root, "zeta": zeta,
            "xi": {"rms_nm": xl.rms, "range_max_nm": xl.range_max, "del": [{"m": m, "n_eq": n, "moment_range_nm": v} for m, n, v in xl.dels]},
            "resultant": {"rms_nm": float(np.sqrt(np.mean(resultant**2))), "max_nm": float(resultant[at]),
                          "moment_zeta_at_max_nm": float(m_zeta[at]), "moment_xi_at_max_nm": float(m_xi[at])}}
