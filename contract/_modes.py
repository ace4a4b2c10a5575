"""Which eigenmodes each unit deformation carries, and the labels every view uses for them.

The analytics number the eigenmodes 1.. in the order of the unit deformations' modes
(``UnitDeformations.modes``): for the pinned beam unit deformation 1 (the combimode) carries
modes 1 and 2 and unit deformation χ ≥ 2 carries mode χ + 1; a clamped beam without a
combimode has one mode per unit deformation. Trends (one per mode) and spectra (one per unit
deformation) take their labels from here, so both name the same mode the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["ModeMap"]


@dataclass(frozen=True)
class ModeMap:
    """Eigenmode numbers per unit deformation.

    Parameters
    ----------
    unit_modes : per unit deformation (in order b1, b2, ...) the 1-based eigenmode numbers it
        carries, e.g. ``((1, 2), (3,), (4,), (5,))``. All modes together must be 1..M in order.

    Raises
    ------
    ValueError
        For an empty map, an empty group or mode numbers that are not 1..M in order.
    """

    unit_modes: tuple[tuple[int, ...], ...]

    def __post_init__(self) -> None:
        try:
            groups = tuple(tuple(int(m) for m in group) for group in self.unit_modes)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"unit_modes={self.unit_modes!r} must be a sequence of sequences of mode numbers") from exc
        if not groups or any(not g for g in groups):
            raise ValueError(f"unit_modes={self.unit_modes!r} needs at least one unit deformation, each with a mode")
        flat = [m for g in groups for m in g]
        if flat != list(range(1, len(flat) + 1)):
            raise ValueError(f"unit_modes={self.unit_modes!r}: the modes must be numbered 1..{len(flat)} in order")
        object.__setattr__(self, "unit_modes", groups)

    @classmethod
    def of(cls, unit_modes: Sequence[Sequence[int]]) -> "ModeMap":
        return cls(tuple(tuple(g) for g in unit_modes))

    @property
    def gamma(self) -> int:
        """Number of unit deformations Γ."""
        return len(self.unit_modes)

    @property
    def modes(self) -> tuple[int, ...]:
        """All eigenmode numbers, 1..M."""
        return tuple(m for g in self.unit_modes for m in g)

    def unit_of(self, mode: int) -> int:
        """The 1-based unit deformation that carries ``mode``."""
        for unit, group in enumerate(self.unit_modes, start=1):
            if mode in group:
                return unit
        raise KeyError(f"mode {mode!r} is not one of the modes {self.modes}")

    def modes_of(self, unit: int) -> tuple[int, ...]:
        """The eigenmodes of 1-based unit deformation ``unit``."""
        if not 1 <= unit <= self.gamma:
            raise KeyError(f"unit deformation {unit!r} is not in 1..{self.gamma}")
        return self.unit_modes[unit - 1]

    def unit_label(self, unit: int) -> str:
        """``b1 · mode 1+2``: a unit deformation and the modes it carries."""
        return f"b{unit} · mode {'+'.join(str(m) for m in self.modes_of(unit))}"

    def mode_label(self, mode: int) -> str:
        """``mode 2 (b1)``: an eigenmode and the unit deformation that carries it."""
        return f"mode {mode} (b{self.unit_of(mode)})"
