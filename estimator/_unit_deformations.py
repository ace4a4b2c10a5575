"""Unit deformations: the eigenmodes of the beam seen from the body frame.

The body frame is the tangent of the beam at D, so every unit deformation satisfies
s(0) = 0 and s'(0) = 0.

Pinned support (the paper's plain bearing): an eigenmode w_k becomes
s̃_k(η) = w_k(η) − w_k'(0)·η, scaled so that max |s̃_k| = 1 over the beam. After this
transformation modes 1 and 2 look alike (both are dominated by the first bending shape, MAC
≈ 0.99); they share one unit deformation, the combimode, so six modes give five unit
deformations: unit deformation 1 = modes 1 + 2, unit deformation χ ≥ 2 = mode χ + 1 (paper,
Table 1). The combimode's shape is s̃_2. Mode 1 is the pendulum's swing: per unit of its motion
it deforms the beam in the body frame about twelve times less than mode 2 does (max |s̃_k| over
max |w_k|: 0.25 and 3.1 for the 4 m sheet), so the body-frame deformation b_1 stands for is
mode 2's. Each sensor reads a shape exactly only if the model's shape is that shape: a mixture
(the pair's first singular vector) misreads mode 2 in every path at once, by +0.14 % (gyros'
slopes), +2.1 % (gauges' curvatures) and +0.85 % (accelerometers, whose tilt term g·α_j, taken
on the estimated b, feeds the misread slope back), while s̃_1's small share is misread instead.

Clamped support (the fixed bearing of Section 3.5, a mast's root): the body frame is the
clamp's, the eigenmodes already satisfy w(0) = w'(0) = 0, nothing looks alike and there is no
combimode: unit deformation χ = mode χ, scaled to max |s| = 1.

Because s̃ is η times a constant away from a Hermite field, the unit deformations stay exact
Hermite fields and s, s', s'' are interpolated exactly at any η.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._beam import BeamModel, NaturalModes, NodalShapes, natural_modes

__all__ = ["UnitDeformations", "unit_deformations", "MAX_UNIT_DEFORMATIONS"]

MAX_UNIT_DEFORMATIONS = 5
_SAMPLES = 4001  # evaluation grid for the max-norm


@dataclass(frozen=True)
class UnitDeformations:
    """Γ unit deformations s_χ(η) in body coordinates.

    Attributes
    ----------
    shapes : NodalShapes with Γ columns (max |s_χ| = 1, s_χ(L) > 0 where it is not ~0).
    modes : tuple of tuples, the 1-based eigenmode numbers behind each unit deformation.
    frequencies_hz : tuple of tuples, the eigenfrequencies of those modes (Hz).
    """

    shapes: NodalShapes
    modes: tuple[tuple[int, ...], ...]
    frequencies_hz: tuple[tuple[float, ...], ...]

    @property
    def count(self) -> int:
        return self.shapes.count

    @property
    def length(self) -> float:
        return float(self.shapes.nodes[-1])

    def shape(self, eta: np.ndarray | float) -> np.ndarray:
        """s_χ(η): shape (len(η), Γ) (m per unit b)."""
        return self.shapes.evaluate(eta, 0)

    def slope(self, eta: np.ndarray | float) -> np.ndarray:
        """s'_χ(η): shape (len(η), Γ) (rad per unit b)."""
        return self.shapes.evaluate(eta, 1)

    def curvature(self, eta: np.ndarray | float) -> np.ndarray:
        """s''_χ(η): shape (len(η), Γ) (1/m per unit b)."""
        return self.shapes.evaluate(eta, 2)

    def subset(self, count: int) -> "UnitDeformations":
        """The first ``count`` unit deformations."""
        if not 1 <= count <= self.count:
            raise ValueError(f"{count=} must be in [1, {self.count}]")
        return UnitDeformations(
            NodalShapes(self.shapes.nodes, self.shapes.dofs[:, :count]),
            self.modes[:count],
            self.frequencies_hz[:count],
        )


def _normalise(field: NodalShapes) -> np.ndarray:
    grid = np.linspace(0.0, field.nodes[-1], _SAMPLES)
    grid = np.union1d(grid, field.nodes)
    values = field.evaluate(grid)
    peak = np.max(np.abs(values), axis=0)
    if np.any(peak <= 0):
        raise ValueError("a unit deformation vanishes over the whole beam")
    dofs = field.dofs / peak
    tip = values[-1] / peak
    # Sign: tip positive, or the largest excursion positive where the tip is nearly still.
    largest = values[np.argmax(np.abs(values), axis=0), np.arange(values.shape[1])] / peak
    reference = np.where(np.abs(tip) > 1e-3, tip, largest)
    return dofs * np.where(reference < 0, -1.0, 1.0)


def unit_deformations(
    model_or_modes: BeamModel | NaturalModes, count: int = 4, *, combimode: bool | None = None
) -> UnitDeformations:
    """The first ``count`` (Γ, 1..5) unit deformations of a beam model (or of its modes).

    Parameters
    ----------
    model_or_modes : the beam model, or its natural modes (enough of them: Γ + 1 with the combimode).
    count : Γ, an integer in 1..5.
    combimode : merge modes 1 and 2 into one unit deformation. ``None`` (default) follows the
        support: the combimode for a pinned beam (paper, Figure 5), none for a clamped one
        (Section 3.5: each eigenmode is its own unit deformation).

    Returns
    -------
    UnitDeformations with Γ shapes in the body frame.

    Raises
    ------
    ValueError
        ``count`` out of range, or too few eigenmodes given.

    Examples
    --------
    The clamped strip of ``natural_modes``' example: its first two unit deformations are its first
    two bending modes (no combimode on a clamp), scaled to a tip deflection of 1.

    >>> import numpy as np
    >>> from contract import parse_rig
    >>> from estimator import assemble_beam, unit_deformations
    >>> rig = parse_rig({"beam": {"length": 1.0, "width": 0.05, "thickness": 0.005,
    ...                           "youngs_modulus": 210e9, "density": 7850.0},
    ...                  "gravity": 0.0, "reflector_distance": 0.5, "support": "clamped",
    ...                  "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]})
    >>> units = unit_deformations(assemble_beam(rig), 2)
    >>> units.modes
    ((1,), (2,))
    >>> np.round(units.shape(np.array([0.0, 0.5, 1.0])), 3)   # rows: η = 0, 0.5, 1 m
    array([[ 0.   ,  0.   ],
           [ 0.34 , -0.714],
           [ 1.   ,  1.   ]])
    """
    if not isinstance(count, (int, np.integer)) or not 1 <= count <= MAX_UNIT_DEFORMATIONS:
        raise ValueError(f"{count=} must be an integer in [1, {MAX_UNIT_DEFORMATIONS}]")
    return _unit_deformations(model_or_modes, int(count), combimode)


def with_residual_modes(model: BeamModel, count: int, residual: int) -> UnitDeformations:
    """The ``count`` unit deformations followed by ``residual`` more (the next eigenmodes in the
    same body frame), for an estimator that carries residual modes: its first ``count`` columns
    are the shapes of ``unit_deformations(model, count)``.

    Raises
    ------
    ValueError
        ``count`` out of 1..5 or ``residual`` not a non-negative integer.
    """
    if not isinstance(count, (int, np.integer)) or not 1 <= count <= MAX_UNIT_DEFORMATIONS:
        raise ValueError(f"{count=} must be an integer in [1, {MAX_UNIT_DEFORMATIONS}]")
    if isinstance(residual, bool) or not isinstance(residual, (int, np.integer)) or residual < 0:
        raise ValueError(f"{residual=} must be a non-negative integer")
    return _unit_deformations(model, int(count) + int(residual), None)


def _unit_deformations(model_or_modes: BeamModel | NaturalModes, count: int, combimode: bool | None) -> UnitDeformations:
    support = model_or_modes.support
    if support not in ("pinned", "clamped"):
        raise ValueError(f"{support=} must be 'pinned' or 'clamped'")
    if combimode is None:
        combimode = support == "pinned"
    elif not isinstance(combimode, (bool, np.bool_)):
        raise ValueError(f"{combimode=} must be True, False or None (from the support)")
    needed = count + 1 if combimode else count
    modes = model_or_modes if isinstance(model_or_modes, NaturalModes) else natural_modes(model_or_modes, needed)
    if modes.shapes.count < needed:
        raise ValueError(f"{count} unit deformations need {needed} eigenmodes, got {modes.shapes.count}")
    nodes = modes.shapes.nodes
    dofs = modes.shapes.dofs[:, :needed].copy()
    if support == "pinned":
        # The body frame turns with the tangent at D: take out each mode's rotation about D.
        rigid = np.zeros(2 * len(nodes))
        rigid[0::2] = nodes
        rigid[1::2] = 1.0
        body = dofs - np.outer(rigid, dofs[1])
    else:
        body = dofs  # the clamp's frame: w(0) = w'(0) = 0 already
    body = _normalise(NodalShapes(nodes, body))
    freqs = [float(f) for f in modes.frequencies_hz[:needed]]
    if combimode:
        body = body[:, 1:]  # the combimode is s̃_2 (module docstring), already normalised
        mode_numbers = ((1, 2),) + tuple((k,) for k in range(3, needed + 1))
        frequencies = ((freqs[0], freqs[1]),) + tuple((f,) for f in freqs[2:])
    else:
        mode_numbers = tuple((k,) for k in range(1, needed + 1))
        frequencies = tuple((f,) for f in freqs)
    return UnitDeformations(NodalShapes(nodes, body), mode_numbers, frequencies)
