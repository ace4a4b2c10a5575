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

__all__ = ["observability_problem"]

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


def _unit_names(null: np.ndarray, units: UnitDeformations) -> str:
    """The unit deformations a null space is made of (with their modes), e.g. 'b1 (mode 1), b2 (mode 2)'."""
    weight = np.sum(null**2, axis=1)
    chosen = [k for k in range(weight.size) if weight[k] > 0.1] or [int(np.argmax(weight))]
    return ", ".join(f"b{k + 1} (mode {'+'.join(map(str, units.modes[k]))})" for k in chosen)


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
    what = "slopes" if selection.peripheral == "gyro" else "deflections"
    imu_rows = (units.slope(imu_eta) if selection.peripheral == "gyro" else units.shape(imu_eta)) if imu_eta.size else np.zeros((0, gamma))
    rank, null = _rank_and_null(imu_rows, gamma)
    if rank < gamma:
        where = ", ".join(f"{n} at {p:g} m" for n, p in zip(selection.imus, imu_eta)) or "none"
        return (f"the peripheral IMUs ({selection.peripheral}: {where}) cannot tell the Γ={gamma} unit deformations apart: "
                f"their {what} see {_unit_names(null, units)} only in combination with the others (rank {rank} of {gamma}); "
                f"add {gamma - rank} peripheral IMU(s) at other positions or lower the unit deformations (--modes) to {rank}")
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
        return (f"the sensors cannot observe {_unit_names(null, units)} of the Γ={gamma} unit deformations: no ToF and no "
                f"aided strain gauge sees them (ToFs: {tofs}; strain gauges: {gauges}{aided}), so the peripheral IMUs' "
                f"integrated rates would drift without bound; add {gamma - rank} strain gauge(s) or ToF(s) where these "
                f"unit deformations bend or deflect, aid them with the gauges (--aided), or lower the unit deformations "
                f"(--modes) to {rank}")
    return None
