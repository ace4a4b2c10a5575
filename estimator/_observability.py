"""Can a rig's selected sensors observe the Γ unit deformations the estimator carries?

The IMMS integrates the peripheral IMUs' readings into b (gyros: ḃ, Eq. 9; accelerometers: b̈,
Eq. 8); what holds b's level against the integrated noise and bias wander is the aiding: ToFs
(Eq. 18, the deflection at η_j) and strain gauges (Eq. 19, the curvature at η_j, for the unit
deformations they aid). A unit deformation that no aiding row sees would drift without bound,
and the peripheral IMUs must tell the Γ unit deformations apart for the least squares that turns
their readings into ḃ or b̈. Both are rank conditions on the model's own shapes (FE unit
deformations of whatever section the beam has), checked before a filter is built so that a rig
that cannot work is refused at once, with what is missing.
"""

from __future__ import annotations

import numpy as np

from ._selection import SensorSelection
from ._unit_deformations import UnitDeformations

__all__ = ["UnobservableRig", "biaxial_observability_problem", "observability_problem"]


class UnobservableRig(ValueError):
    """The selected sensors cannot observe the unit deformations asked for; the message says
    which and what to add."""

# A row space direction weaker than this (relative to the strongest, rows and columns scaled to
# unit size) counts as not seen: sensors at a node of a unit deformation see nothing of it.
_RELATIVE_TOLERANCE = 1e-6


def _rank_and_null(rows: np.ndarray, gamma: int) -> tuple[int, np.ndarray]:
    """Numerical rank of ``rows`` (m, Γ) after scaling rows and columns, and a basis (Γ, k) of its
    null space (the combinations of unit deformations the rows do not see)."""
    if rows.shape[0] == 0:
        return 0, np.eye(gamma)
    A = np.array(rows, dtype=float)
    A /= np.maximum(np.linalg.norm(A, axis=1, keepdims=True), 1e-300)
    scale = np.linalg.norm(A, axis=0)
    A /= np.where(scale > 0, scale, 1.0)
    _, s, vt = np.linalg.svd(A, full_matrices=True)
    rank = int(np.sum(s > _RELATIVE_TOLERANCE * max(float(s[0]) if s.size else 0.0, 1e-300)))
    return rank, vt[rank:].T


def _unit_names(null: np.ndarray, units: UnitDeformations, prefix: str = "b") -> str:
    """The unit deformations a null space is made of (with their modes), e.g. 'b1 (mode 1), b2 (mode 2)'."""
    weight = np.sum(null**2, axis=1)
    chosen = [k for k in range(weight.size) if weight[k] > 0.1] or [int(np.argmax(weight))]
    return ", ".join(f"{prefix}{k + 1} (mode {'+'.join(map(str, units.modes[k]))})" for k in chosen)


def _imu_problem(units: UnitDeformations, selection: SensorSelection, imu_eta: np.ndarray, *, axes: str = "",
                 prefix: str = "b", option: str = "--modes") -> str | None:
    """Why the peripheral IMUs' least squares cannot tell the unit deformations apart, or None."""
    gamma = units.count
    what = "slopes" if selection.peripheral == "gyro" else "deflections"
    imu_rows = (units.slope(imu_eta) if selection.peripheral == "gyro" else units.shape(imu_eta)) if imu_eta.size else np.zeros((0, gamma))
    rank, null = _rank_and_null(imu_rows, gamma)
    if rank >= gamma:
        return None
    where = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.imus, imu_eta)) or "none"
    return (f"the peripheral IMUs ({selection.peripheral}{axes}: {where}) cannot tell the Γ={gamma} unit deformations apart: "
            f"their {what} see {_unit_names(null, units, prefix)} only in combination with the others (rank {rank} of {gamma}); "
            f"add {gamma - rank} peripheral IMU(s) at other positions or lower the unit deformations ({option}) to {rank}")


def observability_problem(units: UnitDeformations, selection: SensorSelection, *, imu_eta: np.ndarray,
                          tof_eta: np.ndarray, gauge_eta: np.ndarray) -> str | None:
    """What the selected sensors cannot observe of the Γ unit deformations, or None.

    Parameters
    ----------
    units : the Γ unit deformations of the rig's model.
    selection : the selected sensors (peripheral IMUs, ToFs, gauges, aided unit deformations).
    imu_eta, tof_eta, gauge_eta : (ν,), (T,), (G,) positions (m from D) of the selected sensors.

    Returns
    -------
    str or None
        A sentence naming the unit deformations that would not be seen and what to add; None when
        the peripheral IMUs resolve all Γ and the aiding (ToFs and aided gauges) sees all Γ.

    Examples
    --------
    A clamped mast with four gyros and four gauges observes Γ = 4; without the gauges and without
    ToFs, ``observability_problem`` names b1..b4 and asks for gauges or ToFs.
    """
    gamma = units.count
    imu_eta, tof_eta, gauge_eta = (np.asarray(a, dtype=float) for a in (imu_eta, tof_eta, gauge_eta))
    problem = _imu_problem(units, selection, imu_eta)
    if problem:
        return problem
    rows = [units.shape(tof_eta)] if tof_eta.size else []
    if gauge_eta.size and selection.aided:
        curvature = units.curvature(gauge_eta)
        mask = np.zeros(gamma)
        mask[[a - 1 for a in selection.aided]] = 1.0
        rows.append(curvature * mask)
    aiding = np.vstack(rows) if rows else np.zeros((0, gamma))
    rank, null = _rank_and_null(aiding, gamma)
    if rank < gamma:
        tofs = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.tofs, tof_eta)) or "none"
        gauges = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.gauges, gauge_eta)) or "none"
        aided = f" aiding b{','.join(map(str, selection.aided))}" if selection.gauges else ""
        # Aiding more unit deformations helps only where there are as many rows as unit deformations.
        reaid = ("aid them with the gauges (--aided), "
                 if len(selection.gauges) + len(selection.tofs) >= gamma and len(selection.aided) < gamma else "")
        return (f"the sensors cannot observe {_unit_names(null, units)} of the Γ={gamma} unit deformations: no ToF and no "
                f"aided strain gauge sees them (ToFs: {tofs}; strain gauges: {gauges}{aided}), so the peripheral IMUs' "
                f"integrated rates would drift without bound; add {gamma - rank} strain gauge(s) or ToF(s) where these "
                f"unit deformations bend or deflect, {reaid}or lower the unit deformations (--modes) to {rank}")
    return None


def biaxial_observability_problem(units: UnitDeformations, units_xi: UnitDeformations, selection: SensorSelection, *,
                                  imu_eta: np.ndarray, tof_eta: np.ndarray, gauge_eta: np.ndarray,
                                  gauge_points: tuple[np.ndarray, np.ndarray]) -> str | None:
    """What the selected sensors cannot observe of a biaxial beam's two planes, or None; the
    sentence starts with the plane ("the zeta plane", "the xi plane").

    Per plane the peripheral IMUs must tell its unit deformations apart (ζ: accel y or gyro z, ξ:
    accel z or gyro y), and the aiding must see every unit deformation of both planes: ToFs see ζ
    only, a gauge at (ζp, ξp) on the outline sees −(ζp κζ + ξp κξ), so only gauges off the ζ faces
    (angles other than 0 and 180) hold the ξ plane.

    Parameters
    ----------
    units, units_xi : the Γ and Γξ unit deformations of the ζ and ξ planes.
    selection : the selected sensors (``aided`` for ζ, ``aided_xi`` for ξ).
    imu_eta, tof_eta, gauge_eta : positions (m) of the selected sensors.
    gauge_points : (ζp, ξp) (G,) in m of the selected gauges (``Beam.section_point``).
    """
    imu_eta, tof_eta, gauge_eta = (np.asarray(a, dtype=float) for a in (imu_eta, tof_eta, gauge_eta))
    zeta_p, xi_p = (np.asarray(a, dtype=float) for a in gauge_points)
    g, gx = units.count, units_xi.count
    axes = " z" if selection.peripheral == "gyro" else " accel y"
    problem = _imu_problem(units, selection, imu_eta, axes=axes)
    if problem:
        return f"the zeta plane: {problem}"
    axes = " y" if selection.peripheral == "gyro" else " accel z"
    problem = _imu_problem(units_xi, selection, imu_eta, axes=axes, prefix="bxi", option="--modes-xi")
    if problem:
        return f"the xi plane: {problem}"
    off_axis = np.abs(xi_p) > 1e-9 * max(float(np.max(np.abs(np.concatenate([zeta_p, xi_p])), initial=0.0)), 1e-300)
    tofs = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.tofs, tof_eta)) or "none"
    if not selection.aided_xi or not np.any(off_axis):
        at = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.gauges, gauge_eta)) or "none"
        sensor = "gyro y" if selection.peripheral == "gyro" else "accel z"
        return (f"the xi plane is not observed: no sensor holds bxi1..bxi{gx} against the drift of the integrated "
                f"{sensor}: no strain gauge sits at an angle off 0/180 (the ζ faces; selected gauges: {at}) and ToFs "
                f"measure ζ only; add strain gauges off the ζ faces (90 and 270 are the ξ faces), or estimate the beam "
                f"as planar (beam.bending='planar')")
    rows = [np.hstack([units.shape(tof_eta), np.zeros((tof_eta.size, gx))])] if tof_eta.size else []
    if gauge_eta.size:
        mask = np.zeros(g)
        mask[[a - 1 for a in selection.aided]] = 1.0
        mask_xi = np.zeros(gx)
        mask_xi[[a - 1 for a in selection.aided_xi]] = 1.0
        rows.append(np.hstack([-zeta_p[:, None] * units.curvature(gauge_eta) * mask,
                               -xi_p[:, None] * units_xi.curvature(gauge_eta) * mask_xi]))
    aiding = np.vstack(rows) if rows else np.zeros((0, g + gx))
    rank, null = _rank_and_null(aiding, g + gx)
    if rank >= g + gx:
        return None
    weight = np.sum(null**2, axis=1)
    in_xi = weight[g:].sum() >= weight[:g].sum()
    plane, null_plane, plane_units = ("xi", null[g:], units_xi) if in_xi else ("zeta", null[:g], units)
    gauges = ", ".join(f"{n} at {p:g} m, {np.degrees(np.arctan2(x, z)) % 360:g}°"
                       for n, p, z, x in zip(selection.gauges, gauge_eta, zeta_p, xi_p)) or "none"
    return (f"the {plane} plane: the sensors cannot observe {_unit_names(null_plane, plane_units, 'bxi' if in_xi else 'b')}: "
            f"no ToF and no aided strain gauge sees them (ToFs: {tofs}, ζ only; strain gauges: {gauges}), so the "
            f"peripheral IMUs' integrated rates would drift without bound; the two planes need {g + gx} independent "
            f"aiding rows and have {rank}: add strain gauge(s) where these unit deformations bend "
            f"({'off the ζ faces' if in_xi else 'off the ξ faces'}) or lower the unit deformations "
            f"({'--modes-xi' if in_xi else '--modes'})")
