"""Model updating: fit physical parameters of a rig description to measured eigenfrequencies.

The update is a bounded, regularised least-squares fit of relative frequency errors. The
regularisation pulls each parameter towards its nominal value (scaled by its bounds), so
parameters that the frequencies cannot tell apart stay where physics puts them instead of
drifting to a bound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import scipy.optimize

from ._beam import assemble_beam, natural_modes
from contract import RigDescription

__all__ = ["CalibrationParameter", "CalibrationResult", "TABLE1_HZ", "calibrate", "modal_frequencies"]

#: Eigenfrequencies of the paper's FE model of the rig (Kohl & Wagner, Table 1), modes 1–6 (Hz).
TABLE1_HZ = (0.302, 0.860, 1.909, 3.492, 5.262, 8.318)


@dataclass(frozen=True)
class CalibrationParameter:
    name: str
    nominal: float
    lower: float
    upper: float

    def __post_init__(self) -> None:
        if not self.lower <= self.nominal <= self.upper:
            raise ValueError(f"{self.name}: nominal={self.nominal} must lie in [{self.lower}, {self.upper}]")


@dataclass(frozen=True)
class CalibrationResult:
    values: dict[str, float]
    rig: RigDescription
    frequencies_hz: np.ndarray
    targets_hz: np.ndarray
    relative_error: np.ndarray


def modal_frequencies(rig: RigDescription, count: int = 6) -> np.ndarray:
    """The first ``count`` eigenfrequencies (Hz) of the rig's beam model at its reference temperature."""
    return natural_modes(assemble_beam(rig), count).frequencies_hz


def calibrate(
    build: Callable[[dict[str, float]], RigDescription],
    parameters: Sequence[CalibrationParameter],
    targets_hz: Sequence[float] = TABLE1_HZ,
    *,
    weights: Sequence[float] | None = None,
    regularisation: float = 0.02,
) -> CalibrationResult:
    """Fit ``parameters`` so that the rig ``build(values)`` has the eigenfrequencies ``targets_hz``.

    ``weights`` (one per target) expresses trust in each target frequency; the residual of
    mode k is ``weights[k] * (f_k / target_k - 1)``.
    """
    targets = np.asarray(targets_hz, dtype=float)
    if targets.ndim != 1 or targets.size == 0 or np.any(targets <= 0):
        raise ValueError(f"{targets_hz=} must be a non-empty list of positive frequencies")
    w = np.ones_like(targets) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != targets.shape or np.any(w < 0):
        raise ValueError(f"{weights=} must give one non-negative weight per target")
    if not parameters:
        raise ValueError("at least one calibration parameter is needed")
    names = [p.name for p in parameters]
    nominal = np.array([p.nominal for p in parameters])
    lower = np.array([p.lower for p in parameters])
    upper = np.array([p.upper for p in parameters])
    scale = upper - lower

    def unpack(z: np.ndarray) -> dict[str, float]:
        return dict(zip(names, (nominal + z * scale).tolist()))

    def residual(z: np.ndarray) -> np.ndarray:
        freqs = modal_frequencies(build(unpack(z)), targets.size)
        return np.concatenate([w * (freqs / targets - 1.0), regularisation * z])

    z0 = np.zeros(len(parameters))
    bounds = ((lower - nominal) / scale, (upper - nominal) / scale)
    solution = scipy.optimize.least_squares(residual, z0, bounds=bounds, x_scale=1.0, diff_step=1e-4)
    values = unpack(solution.x)
    rig = build(values)
    freqs = modal_frequencies(rig, targets.size)
    return CalibrationResult(values, rig, freqs, targets, freqs / targets - 1.0)
