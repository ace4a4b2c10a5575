"""Model updating: fit physical parameters of a rig description to measured eigenfrequencies.

The update is a bounded, regularised least-squares fit of relative frequency errors. The
regularisation pulls each parameter towards its nominal value (scaled by its bounds), so
parameters that the frequencies cannot tell apart stay where physics puts them instead of
drifting to a bound.

Read as a Bayesian update (a Gaussian prior on each parameter around its nominal value, Gaussian
errors of the target frequencies), the fit's weighted Jacobian at the optimum gives what the data
determine: the posterior covariance of the parameters, each parameter's *resolution* (the share of
its prior variance the frequencies remove: 1 = fixed by the data, 0 = only by the prior) and the
singular values of the weighted relative sensitivities, whose right singular vectors are the
parameter combinations the frequencies do and do not see. A parameter of low resolution is not
identified: its fitted value moves along a flat valley of the cost (with the BLAS kernel, the
start point, the optimiser's tolerances) while the fitted frequencies do not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import scipy.optimize

from ._beam import assemble_beam, natural_modes
from contract import RigDescription

__all__ = [
    "CalibrationParameter",
    "CalibrationResult",
    "Identifiability",
    "TABLE1_HZ",
    "calibrate",
    "calibration_identifiability",
    "modal_frequencies",
]

#: Eigenfrequencies of the paper's FE model of the rig (Kohl & Wagner, Table 1), modes 1–6 (Hz).
TABLE1_HZ = (0.302, 0.860, 1.909, 3.492, 5.262, 8.318)

#: Resolution below which a parameter is reported as not determined by the frequencies: the
#: prior then carries more of its value than the data do.
DETERMINED_RESOLUTION = 0.5


@dataclass(frozen=True)
class CalibrationParameter:
    name: str
    nominal: float
    lower: float
    upper: float

    def __post_init__(self) -> None:
        if not self.lower <= self.nominal <= self.upper:
            raise ValueError(f"{self.name}: nominal={self.nominal} must lie in [{self.lower}, {self.upper}]")
        if not self.upper > self.lower:
            raise ValueError(f"{self.name}: upper={self.upper} must exceed lower={self.lower}")


@dataclass(frozen=True)
class Identifiability:
    """What the target frequencies determine of the parameters, at one point of the update.

    Attributes
    ----------
    names : tuple of str
        Parameter names, the order of every array below.
    values : ndarray, shape (p,)
        Parameter values the figures are evaluated at (physical units).
    std : ndarray, shape (p,)
        Posterior standard deviation of each parameter (physical units): prior and data together,
        with the target error scale ``frequency_std``.
    prior_std : ndarray, shape (p,)
        Standard deviation of the regularisation's prior (physical units).
    covariance : ndarray, shape (p, p)
        Posterior covariance (physical units).
    resolution : ndarray, shape (p,)
        Diagonal of the resolution matrix, 1 − posterior variance / prior variance, in [0, 1]:
        the share of a parameter's value that the frequencies fix (independent of
        ``frequency_std``).
    sensitivity : ndarray, shape (m, p)
        Relative sensitivities ∂ ln f_k / ∂ ln p_j (unweighted).
    singular_values : ndarray, shape (p,)
        Singular values of the weighted relative sensitivities diag(w) S, largest first: a 1 %
        change of the parameters along combination i changes the weighted frequencies by
        ``singular_values[i]`` %.
    combinations : ndarray, shape (p, p)
        Right singular vectors as rows (unit vectors over ln p_j), in the order of
        ``singular_values``.
    frequency_std : float
        Relative standard uncertainty of a target of weight 1 used for ``std`` (estimated from the
        fit's residuals unless given).
    effective_parameters : float
        Trace of the resolution matrix: how many parameters the data determine in effect.
    cost : float
        ½‖r‖² of the weighted, regularised residual at ``values`` (what the update minimises).
    frequencies_hz : ndarray, shape (m,)
        The model's frequencies at ``values``.
    at_bound : tuple of str
        Parameters at (within 1e-6 of the range of) a bound: their linearised figures are
        one-sided.
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    prior_std: np.ndarray
    covariance: np.ndarray
    resolution: np.ndarray
    sensitivity: np.ndarray
    singular_values: np.ndarray
    combinations: np.ndarray
    frequency_std: float
    effective_parameters: float
    cost: float
    frequencies_hz: np.ndarray
    at_bound: tuple[str, ...]

    @property
    def undetermined(self) -> tuple[str, ...]:
        """Parameters whose resolution is below ``DETERMINED_RESOLUTION``."""
        return tuple(n for n, r in zip(self.names, self.resolution) if r < DETERMINED_RESOLUTION)

    def combination_text(self, index: int, *, threshold: float = 0.1) -> str:
        """Combination ``index`` as text, e.g. ``+0.98 ln board_rotary_inertia -0.17 ln youngs_modulus``."""
        vector = self.combinations[index]
        vector = vector * np.sign(vector[np.argmax(np.abs(vector))])
        order = np.argsort(-np.abs(vector))
        return " ".join(f"{vector[j]:+.2f} ln {self.names[j]}" for j in order if abs(vector[j]) >= threshold)

    def as_dict(self) -> dict[str, Any]:
        return {
            "frequency_std": float(self.frequency_std),
            "effective_parameters": round(float(self.effective_parameters), 4),
            "cost": float(self.cost),
            "parameters": {
                n: {"value": float(v), "std": float(s), "prior_std": float(ps), "resolution": round(float(r), 4)}
                for n, v, s, ps, r in zip(self.names, self.values, self.std, self.prior_std, self.resolution)
            },
            "singular_values": [round(float(s), 6) for s in self.singular_values],
            "combinations": [self.combination_text(i) for i in range(len(self.names))],
            "undetermined": list(self.undetermined),
            "at_bound": list(self.at_bound),
        }


@dataclass(frozen=True)
class CalibrationResult:
    values: dict[str, float]
    rig: RigDescription
    frequencies_hz: np.ndarray
    targets_hz: np.ndarray
    relative_error: np.ndarray
    #: ½‖r‖² of the weighted, regularised residual at the optimum (scipy's ``cost``).
    cost: float
    identifiability: Identifiability


def modal_frequencies(rig: RigDescription, count: int = 6) -> np.ndarray:
    """The first ``count`` eigenfrequencies (Hz) of the rig's beam model at its reference temperature."""
    return natural_modes(assemble_beam(rig), count).frequencies_hz


class _Problem:
    """The scaled update problem: z = (p − nominal) / (upper − lower)."""

    def __init__(self, build: Callable[[dict[str, float]], RigDescription], parameters: Sequence[CalibrationParameter],
                 targets_hz: Sequence[float], weights: Sequence[float] | None, regularisation: float) -> None:
        targets = np.asarray(targets_hz, dtype=float)
        if targets.ndim != 1 or targets.size == 0 or not np.all(np.isfinite(targets)) or np.any(targets <= 0):
            raise ValueError(f"{targets_hz=} must be a non-empty list of positive frequencies")
        w = np.ones_like(targets) if weights is None else np.asarray(weights, dtype=float)
        if w.shape != targets.shape or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"{weights=} must give one non-negative weight per target")
        if not parameters:
            raise ValueError("at least one calibration parameter is needed")
        if not (np.isfinite(regularisation) and regularisation > 0):
            raise ValueError(f"{regularisation=} must be positive: the prior keeps undetermined parameters physical")
        self.build = build
        self.targets = targets
        self.weights = w
        self.regularisation = float(regularisation)
        self.names = tuple(p.name for p in parameters)
        self.nominal = np.array([p.nominal for p in parameters], dtype=float)
        self.lower = np.array([p.lower for p in parameters], dtype=float)
        self.upper = np.array([p.upper for p in parameters], dtype=float)
        self.scale = self.upper - self.lower
        self.bounds = ((self.lower - self.nominal) / self.scale, (self.upper - self.nominal) / self.scale)

    def unpack(self, z: np.ndarray) -> dict[str, float]:
        return dict(zip(self.names, (self.nominal + z * self.scale).tolist()))

    def pack(self, values: dict[str, float]) -> np.ndarray:
        missing = set(self.names) - values.keys()
        if missing:
            raise ValueError(f"values lack {sorted(missing)}")
        return (np.array([values[n] for n in self.names], dtype=float) - self.nominal) / self.scale

    def frequencies(self, z: np.ndarray) -> np.ndarray:
        return modal_frequencies(self.build(self.unpack(z)), self.targets.size)

    def residual(self, z: np.ndarray) -> np.ndarray:
        return np.concatenate([self.weights * (self.frequencies(z) / self.targets - 1.0), self.regularisation * z])


def _frequency_jacobian(problem: _Problem, z: np.ndarray, f0: np.ndarray, step: float = 1e-3) -> np.ndarray:
    """∂f/∂z by central differences (one-sided at a bound), shape (m, p)."""
    lo, hi = problem.bounds
    jac = np.empty((f0.size, z.size))
    for j in range(z.size):
        up, down = z.copy(), z.copy()
        up[j] = min(z[j] + step, hi[j])
        down[j] = max(z[j] - step, lo[j])
        f_up = f0 if up[j] == z[j] else problem.frequencies(up)
        f_down = f0 if down[j] == z[j] else problem.frequencies(down)
        jac[:, j] = (f_up - f_down) / (up[j] - down[j])
    return jac


def _identifiability(problem: _Problem, z: np.ndarray, frequency_std: float | None) -> Identifiability:
    f = problem.frequencies(z)
    dfdz = _frequency_jacobian(problem, z, f)
    w, lam = problem.weights, problem.regularisation
    data_jac = (w / problem.targets)[:, None] * dfdz  # ∂(weighted data residual)/∂z
    info_data = data_jac.T @ data_jac
    info = info_data + lam**2 * np.eye(z.size)
    info_inv = np.linalg.inv(info)
    resolution_matrix = info_inv @ info_data
    resolution = np.clip(np.diag(resolution_matrix), 0.0, 1.0)
    dof = problem.targets.size - float(np.trace(resolution_matrix))
    data_residual = w * (f / problem.targets - 1.0)
    if frequency_std is None:
        # σ of a weight-1 target from the residuals over the residual degrees of freedom.
        frequency_std = float(np.sqrt(data_residual @ data_residual / max(dof, 1.0)))
    elif not (np.isfinite(frequency_std) and frequency_std > 0):
        raise ValueError(f"{frequency_std=} must be a positive relative standard uncertainty")
    scale = problem.scale
    covariance = frequency_std**2 * info_inv * np.outer(scale, scale)
    values = problem.nominal + z * scale
    if np.any(values <= 0):
        # ln p needs p > 0: a parameter at 0 has no relative sensitivity; use the range instead.
        ref = np.where(values > 0, values, scale)
    else:
        ref = values
    sensitivity = dfdz / f[:, None] * (ref / scale)[None, :]  # ∂ ln f / ∂ ln p
    _, singular_values, vt = np.linalg.svd(w[:, None] * sensitivity, full_matrices=False)
    if singular_values.size < z.size:  # fewer targets than parameters: the rest are not seen at all
        singular_values = np.concatenate([singular_values, np.zeros(z.size - singular_values.size)])
        vt = np.linalg.svd(w[:, None] * sensitivity, full_matrices=True)[2]
    lo, hi = problem.bounds
    at_bound = tuple(n for n, zj, l, h in zip(problem.names, z, lo, hi) if zj - l < 1e-6 or h - zj < 1e-6)
    return Identifiability(
        names=problem.names, values=values, std=np.sqrt(np.diag(covariance)),
        prior_std=frequency_std / lam * scale, covariance=covariance, resolution=resolution,
        sensitivity=sensitivity, singular_values=singular_values, combinations=vt,
        frequency_std=frequency_std, effective_parameters=float(np.trace(resolution_matrix)),
        cost=0.5 * float(data_residual @ data_residual + lam**2 * z @ z), frequencies_hz=f, at_bound=at_bound,
    )


def calibration_identifiability(
    build: Callable[[dict[str, float]], RigDescription],
    parameters: Sequence[CalibrationParameter],
    values: dict[str, float],
    targets_hz: Sequence[float] = TABLE1_HZ,
    *,
    weights: Sequence[float] | None = None,
    regularisation: float = 0.02,
    frequency_std: float | None = None,
) -> Identifiability:
    """Identifiability of ``parameters`` at ``values`` for the update ``calibrate`` runs.

    Parameters
    ----------
    build, parameters, targets_hz, weights, regularisation
        As for :func:`calibrate`.
    values : dict
        Parameter values (physical units) to evaluate at, e.g. a frozen calibration.
    frequency_std : float, optional
        Relative standard uncertainty of a target of weight 1; the regularisation then is a prior
        of standard deviation ``frequency_std / regularisation`` (of each parameter's range).
        Default: estimated from the residuals at ``values``.

    Returns
    -------
    Identifiability

    Raises
    ------
    ValueError
        Bad targets, weights, regularisation or ``frequency_std``, or ``values`` lacking a parameter.
    """
    problem = _Problem(build, parameters, targets_hz, weights, regularisation)
    return _identifiability(problem, problem.pack(values), frequency_std)


def calibrate(
    build: Callable[[dict[str, float]], RigDescription],
    parameters: Sequence[CalibrationParameter],
    targets_hz: Sequence[float] = TABLE1_HZ,
    *,
    weights: Sequence[float] | None = None,
    regularisation: float = 0.02,
    frequency_std: float | None = None,
) -> CalibrationResult:
    """Fit ``parameters`` so that the rig ``build(values)`` has the eigenfrequencies ``targets_hz``.

    Parameters
    ----------
    build : callable
        ``values -> RigDescription``.
    parameters : sequence of CalibrationParameter
        What is fitted, with nominal value and bounds.
    targets_hz : sequence of float
        Target eigenfrequencies, Hz.
    weights : sequence of float, optional
        One per target: the trust in it; the residual of mode k is ``weights[k] * (f_k / target_k - 1)``.
    regularisation : float
        Weight of the pull of each scaled parameter ``(p - nominal) / (upper - lower)`` to 0.
    frequency_std : float, optional
        See :func:`calibration_identifiability`.

    Returns
    -------
    CalibrationResult
        The fitted values, the rig, its frequencies, the cost and the identifiability at the optimum.

    Raises
    ------
    ValueError
        Bad targets, weights, regularisation or no parameters.
    """
    problem = _Problem(build, parameters, targets_hz, weights, regularisation)
    z0 = np.zeros(len(problem.names))
    solution = scipy.optimize.least_squares(problem.residual, z0, bounds=problem.bounds, x_scale=1.0, diff_step=1e-4)
    values = problem.unpack(solution.x)
    found = _identifiability(problem, solution.x, frequency_std)
    freqs = found.frequencies_hz
    return CalibrationResult(values, build(values), freqs, problem.targets, freqs / problem.targets - 1.0, found.cost, found)
