"""Sensor selection by Effective Independence (Kammer 1991), as the paper picks its sensors.

EfI keeps the candidate set whose sensitivity rows span the unit deformations best: it
repeatedly drops the candidate with the smallest effective independence value, the diagonal of
the projector A (AᵀA)⁻¹ Aᵀ (the candidate's share of the Fisher information). Below as many
sensors as columns the Fisher information is singular; there the candidate with the least
sensitivity (columns scaled to equal weight) is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from contract import RigDescription
from ._unit_deformations import UnitDeformations

__all__ = ["SensorSelection", "default_aided", "effective_independence", "select_sensors"]

Peripheral = Literal["gyro", "acc"]

# The paper's restricted aiding for Γ = 4 (Section 5.3): ν_ε → aided unit deformations.
_PAPER_AIDED = {1: (2, 3, 4), 2: (3, 4), 3: (2, 3, 4)}


def effective_independence(sensitivity: np.ndarray, count: int) -> np.ndarray:
    """Indices (ascending) of the ``count`` rows of ``sensitivity`` (candidates × columns) kept by EfI."""
    A = np.asarray(sensitivity, dtype=float)
    if A.ndim != 2 or A.shape[0] == 0 or A.shape[1] == 0:
        raise ValueError(f"sensitivity must be a non-empty 2-D array, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("sensitivity contains non-finite values")
    n = A.shape[0]
    if not isinstance(count, (int, np.integer)) or not 0 <= count <= n:
        raise ValueError(f"{count=} must be an integer in [0, {n}]")
    scale = np.sqrt(np.mean(A**2, axis=0))
    A = A / np.where(scale > 0, scale, 1.0)
    keep = list(range(n))
    while len(keep) > count:
        rows = A[keep]
        if len(keep) > A.shape[1]:
            fisher = rows.T @ rows
            leverage = np.einsum("ij,jk,ik->i", rows, np.linalg.pinv(fisher), rows)
        else:
            leverage = np.sum(rows**2, axis=1)
        keep.pop(int(np.argmin(leverage)))
    return np.array(sorted(keep), dtype=int)


def default_aided(gamma: int, gauges: int) -> tuple[int, ...]:
    """The unit deformations (1-based) that ``gauges`` strain gauges aid by default."""
    if gauges <= 0:
        return ()
    if gauges >= gamma:
        return tuple(range(1, gamma + 1))
    if gamma == 4:
        return _PAPER_AIDED[gauges]
    # ToFs resolve the large low unit deformations; gauges take the small high ones.
    return tuple(range(gamma - gauges + 1, gamma + 1)) if gauges > 1 else tuple(range(2, gamma + 1))


@dataclass(frozen=True)
class SensorSelection:
    peripheral: Peripheral
    imus: tuple[str, ...]  # peripheral IMUs (D is always used)
    tofs: tuple[str, ...]
    gauges: tuple[str, ...]
    aided: tuple[int, ...]  # 1-based unit deformations aided by the gauges
    aided_xi: tuple[int, ...] = ()  # a biaxial model's ξ unit deformations aided by the gauges (1-based)

    def as_dict(self) -> dict:
        out = {"peripheral": self.peripheral, "imus": list(self.imus), "tofs": list(self.tofs),
               "gauges": list(self.gauges), "aided": list(self.aided)}
        if self.aided_xi:
            out["aided_xi"] = list(self.aided_xi)
        return out


def _choose(kind: str, candidates: Sequence, wanted, sensitivity) -> tuple[str, ...]:
    names = [s.name for s in candidates]
    if wanted is None:
        return tuple(names)
    if isinstance(wanted, (int, np.integer)):
        if not 0 <= wanted <= len(names):
            raise ValueError(f"{kind}: {wanted} requested but the rig has {len(names)}")
        if wanted == len(names):
            return tuple(names)
        rows = sensitivity(np.array([s.position for s in candidates]))
        return tuple(names[i] for i in effective_independence(rows, int(wanted)))
    wanted = tuple(wanted)
    unknown = [w for w in wanted if w not in names]
    if unknown:
        raise ValueError(f"{kind}: unknown sensor names {unknown}; the rig has {names}")
    if len(set(wanted)) != len(wanted):
        raise ValueError(f"{kind}: duplicate names in {list(wanted)}")
    return wanted


def select_sensors(
    rig: RigDescription,
    units: UnitDeformations,
    *,
    peripheral: Peripheral = "gyro",
    imus: int | Sequence[str] | None = 4,
    tofs: int | Sequence[str] | None = 4,
    gauges: int | Sequence[str] | None = 4,
    aided: Sequence[int] | None = None,
    units_xi: UnitDeformations | None = None,
) -> SensorSelection:
    """Choose the sensors of one configuration: counts are filled by EfI, names are taken as given.

    A count larger than what the rig has is capped to the rig (``None`` = all of that kind).
    ``units_xi``: a biaxial beam's ξ unit deformations; EfI then weighs both planes (the IMUs' ξ
    slopes or deflections beside the ζ ones, a gauge's strain ε = −(ζp κζ + ξp κξ) at its place
    around the section) and the gauges aid every ξ unit deformation (``aided_xi``).
    """
    if peripheral not in ("gyro", "acc"):
        raise ValueError(f"{peripheral=} must be 'gyro' or 'acc'")
    gamma = units.count
    peripheral_imus = [s for s in rig.sensors_of("imu") if s.name != "D" and s.position > 0]
    tof_sensors = list(rig.sensors_of("tof"))
    gauge_sensors = list(rig.sensors_of("strain"))

    def cap(value, available):
        return min(value, len(available)) if isinstance(value, (int, np.integer)) else value

    imu_sensitivity = units.slope if peripheral == "gyro" else units.shape
    if units_xi is not None:
        zeta_rows, xi_rows = imu_sensitivity, (units_xi.slope if peripheral == "gyro" else units_xi.shape)
        imu_sensitivity = lambda eta: np.hstack([zeta_rows(eta), xi_rows(eta)])  # noqa: E731
    chosen_imus = _choose("imus", peripheral_imus, cap(imus, peripheral_imus), imu_sensitivity)
    if rig.support == "pinned":
        tof_sensitivity = lambda eta: np.column_stack([eta, units.shape(eta)])  # noqa: E731 (φ moves ζ by η)
    elif rig.support == "clamped":
        tof_sensitivity = units.shape  # φ ≡ 0
    else:
        raise ValueError(f"support={rig.support!r} must be 'pinned' or 'clamped'")
    chosen_tofs = _choose("tofs", tof_sensors, cap(tofs, tof_sensors), tof_sensitivity)
    n_gauges = len(gauge_sensors) if gauges is None else (
        min(gauges, len(gauge_sensors)) if isinstance(gauges, (int, np.integer)) else len(tuple(gauges)))
    aided_units = tuple(aided) if aided is not None else default_aided(gamma, n_gauges)
    bad = [a for a in aided_units if not 1 <= a <= gamma]
    if bad:
        raise ValueError(f"aided unit deformations {bad} are outside 1..{gamma}")
    if n_gauges and not aided_units:
        raise ValueError("strain gauges are selected but no unit deformation is aided")
    columns = [a - 1 for a in aided_units] or list(range(gamma))
    gauge_sensitivity = lambda eta: units.curvature(eta)[:, columns]  # noqa: E731
    aided_xi: tuple[int, ...] = ()
    if units_xi is not None:
        aided_xi = tuple(range(1, units_xi.count + 1)) if n_gauges else ()
        angles = np.array([s.angle_deg for s in gauge_sensors], dtype=float)

        def gauge_sensitivity(eta: np.ndarray) -> np.ndarray:
            zeta_p, xi_p = (np.asarray(v, dtype=float).reshape(-1) for v in rig.beam.section_point(eta, angles))
            return np.hstack([-zeta_p[:, None] * units.curvature(eta)[:, columns], -xi_p[:, None] * units_xi.curvature(eta)])
    chosen_gauges = _choose("gauges", gauge_sensors, cap(gauges, gauge_sensors), gauge_sensitivity)
    gamma = max(gamma, units_xi.count if units_xi is not None else 0)  # the peripheral IMUs serve both planes
    if len(chosen_imus) < gamma:
        raise ValueError(
            f"Γ={gamma} unit deformations need at least {gamma} peripheral IMUs ({peripheral}), "
            f"got {len(chosen_imus)} (the rig has {len(peripheral_imus)}): add {gamma - len(chosen_imus)} peripheral "
            f"IMU(s) or lower the unit deformations (--modes) to {len(chosen_imus)}"
        )
    return SensorSelection(peripheral, chosen_imus, chosen_tofs, chosen_gauges, tuple(sorted(aided_units)), aided_xi)
