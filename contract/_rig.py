"""The rig description (``rig.json`` of the recording contract) as a typed model.

The contract allows extra keys (noise figures, simulator settings, damage descriptions) and
readers that do not know them ignore them, so the models keep unknown keys instead of
forbidding them; everything the contract does name is validated strictly.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

__all__ = [
    "DNV_RP_C203_CURVE_NAMES",
    "DNV_RP_C203_ENVIRONMENTS",
    "EN1993_DETAIL_CATEGORIES",
    "EN1993_SHEAR_CATEGORIES",
    "PLANES",
    "Beam",
    "Bending",
    "Plane",
    "check_curve_spec",
    "FatigueSettings",
    "HotSpot",
    "PointMass",
    "RectangleSection",
    "RigDescription",
    "RigError",
    "Sensor",
    "StiffnessSegment",
    "TableSection",
    "TubeSection",
    "load_rig",
    "parse_rig",
]

SensorKind = Literal["imu", "tof", "strain", "bearing", "temperature"]
Support = Literal["pinned", "clamped"]
Orientation = Literal["hanging", "standing"]
Bending = Literal["planar", "biaxial"]
#: The two bending planes: ζ (the planar contract's) and ξ = η × ζ (a biaxial beam's second).
Plane = Literal["zeta", "xi"]
PLANES: tuple[str, ...] = ("zeta", "xi")

# Kinds whose sensors sit on the beam and therefore need a position.
_POSITIONED_KINDS = ("imu", "tof", "strain")

#: Steel loses about 0.03 % of its Young's modulus per kelvin.
STEEL_YOUNGS_MODULUS_TEMPERATURE_COEFFICIENT = -3.0e-4


#: EN 1993-1-9 Fig. 7.1 detail categories Δσ_C (MPa), normal stress ("36*" is also accepted).
EN1993_DETAIL_CATEGORIES = (160, 140, 125, 112, 100, 90, 80, 71, 63, 56, 50, 45, 40, 36)
#: EN 1993-1-9 Fig. 7.2 detail categories Δτ_C (MPa), shear stress ("EN1993-1-9:shear:<Δτ_C>").
EN1993_SHEAR_CATEGORIES = (100, 80)
#: DNV-RP-C203 (2016) S–N curves of Tables 2-1 (air) and 2-2 (seawater with cathodic protection).
DNV_RP_C203_CURVE_NAMES = ("B1", "B2", "C", "C1", "C2", "D", "E", "F", "F1", "F3", "G", "W1", "W2", "W3")
DNV_RP_C203_ENVIRONMENTS = ("air", "seawater-cp")


def check_curve_spec(spec: object) -> None:
    """Raise ValueError naming the value unless ``spec`` names a known S–N curve (see INTERFACES/hot_spots):
    "EN1993-1-9:<Δσ_C>", "EN1993-1-9:shear:<Δτ_C>", "DNV-RP-C203:<curve>:air|seawater-cp" or
    {"points": [[N, Δσ_Pa], ...]} (N increasing, Δσ decreasing, all > 0, at least two)."""
    if isinstance(spec, dict):
        if set(spec) != {"points"}:
            raise ValueError(f"curve {spec!r}: a user curve is {{'points': [[N, stress_range_pa], ...]}}")
        try:
            p = np.asarray(spec["points"], dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"curve points {spec['points']!r} must be [[N, stress_range_pa], ...]") from None
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2:
            raise ValueError(f"curve points must be at least two [N, stress_range_pa] pairs, got shape {p.shape}")
        if not np.all(np.isfinite(p)) or np.any(p <= 0):
            raise ValueError(f"curve points must be finite and > 0, got {p.tolist()}")
        if np.any(np.diff(p[:, 0]) <= 0) or np.any(np.diff(p[:, 1]) >= 0):
            raise ValueError(f"curve points need N increasing and stress range decreasing, got {p.tolist()}")
        return
    if not isinstance(spec, str):
        raise ValueError(f"curve {spec!r} must be a name like 'EN1993-1-9:71' or {{'points': ...}}")
    parts = spec.split(":")
    if parts[0] == "EN1993-1-9":
        shear = len(parts) == 3 and parts[1] == "shear"
        if len(parts) != (3 if shear else 2):
            raise ValueError(f"curve {spec!r}: expected 'EN1993-1-9:<category>' or 'EN1993-1-9:shear:<category>'")
        text = parts[-1]
        categories = EN1993_SHEAR_CATEGORIES if shear else EN1993_DETAIL_CATEGORIES
        try:
            value = float(text[:-1] if text == "36*" and not shear else text)
        except ValueError:
            value = math.nan
        if value not in categories:
            raise ValueError(f"curve {spec!r}: unknown EN 1993-1-9 {'shear ' if shear else ''}detail category {text!r}; "
                             f"known: {', '.join(map(str, categories))}{'' if shear else ', 36*'}")
        return
    if parts[0] == "DNV-RP-C203":
        if len(parts) != 3:
            raise ValueError(f"curve {spec!r}: expected 'DNV-RP-C203:<curve>:air' or ':seawater-cp'")
        if parts[2] not in DNV_RP_C203_ENVIRONMENTS:
            raise ValueError(f"curve {spec!r}: unknown DNV-RP-C203 environment {parts[2]!r}; known: {', '.join(DNV_RP_C203_ENVIRONMENTS)}")
        if parts[1] not in DNV_RP_C203_CURVE_NAMES:
            raise ValueError(f"curve {spec!r}: unknown DNV-RP-C203 curve {parts[1]!r}; known: {', '.join(DNV_RP_C203_CURVE_NAMES)}")
        return
    raise ValueError(f"curve {spec!r}: unknown standard {parts[0]!r}; known: EN1993-1-9, DNV-RP-C203, or {{'points': ...}}")


#: The extension keys the project's own tools write or read (the contract allows extra keys and
#: readers that do not know them ignore them): the key as it stands in rig.json -> its meaning.
EXTENSION_KEYS: dict[str, str] = {
    "simulator": "an object: the virtual rig's settings a recording was simulated with (every `shm simulate` setting but the rig's "
                 "own support, orientation, length and layout); `shm simulate --rig FILE` reads it as the settings' defaults",
    "notes": "free text (a string or a list of strings): where the values came from, what was estimated; never read",
    "sensors[].axes": "the axes an IMU measures, e.g. [\"accel_y\"] for a single-axis accelerometer (`shm import` writes it when the "
                      "channel map fills fewer than six; the unfilled fields are written as 0.0 and are not used)",
}


class RigError(ValueError):
    """A rig description that breaks the contract; the message names the offending key."""


class _ContractModel(BaseModel):
    # Extra keys are part of the contract ("allowed and ignored"): keep them for those who know them.
    model_config = ConfigDict(extra="allow", frozen=True)


class StiffnessSegment(_ContractModel):
    """A segment [start, end] (m) whose bending stiffness is ``factor`` times the nominal EI.

    An extension of the contract (an extra key of ``beam``): damage (factor < 1) or a
    stiffener (factor > 1).
    """

    start: float = Field(ge=0.0, description="where the segment starts, m from D")
    end: float = Field(description="where it ends, m from D (> start, on the beam)")
    factor: float = Field(gt=0.0, description="its bending stiffness over the nominal EI (0.8: a 20 % loss; > 1: a stiffener)")

    @model_validator(mode="after")
    def _ordered(self) -> "StiffnessSegment":
        if not self.end > self.start:
            raise ValueError(f"stiffness segment needs end > start, got start={self.start}, end={self.end}")
        return self


class RectangleSection(_ContractModel):
    """A solid rectangle at ``position`` (m from D), bending across its ``thickness`` (m)."""

    position: float = Field(ge=0.0, allow_inf_nan=False, description="the station's arc length from D, m")
    shape: Literal["rectangle"] = Field(description='"rectangle": a solid rectangle')
    width: float = Field(gt=0.0, allow_inf_nan=False, description="across the bending plane, m")
    thickness: float = Field(gt=0.0, allow_inf_nan=False, description="in the bending plane (the beam bends across it), m")


class TubeSection(_ContractModel):
    """A circular hollow section at ``position`` (m from D): ``outer_diameter`` and ``wall_thickness`` (m)."""

    position: float = Field(ge=0.0, allow_inf_nan=False, description="the station's arc length from D, m")
    shape: Literal["tube"] = Field(description='"tube": a circular hollow section (a mast, a tower)')
    outer_diameter: float = Field(gt=0.0, allow_inf_nan=False, description="outer diameter, m (the fibre distance is half of it)")
    wall_thickness: float = Field(gt=0.0, allow_inf_nan=False, description="wall thickness, m (at most half the outer diameter)")

    @model_validator(mode="after")
    def _wall_fits(self) -> TubeSection:
        if self.wall_thickness > 0.5 * self.outer_diameter:
            raise ValueError(
                f"wall_thickness={self.wall_thickness} m exceeds half the outer_diameter={self.outer_diameter} m"
            )
        return self


class TableSection(_ContractModel):
    """Any other section by its properties at the reference temperature: EI (N·m²), μ (kg/m), c (m)."""

    position: float = Field(ge=0.0, allow_inf_nan=False, description="the station's arc length from D, m")
    shape: Literal["table"] = Field(description='"table": any other section (a blade) by its properties')
    bending_stiffness: float = Field(gt=0.0, allow_inf_nan=False, description="EI at the reference temperature, N·m² (follows the beam's "
                                     "temperature coefficient)")
    mass_per_length: float = Field(gt=0.0, allow_inf_nan=False, description="μ = ρA, kg/m")
    fibre_distance: float = Field(gt=0.0, allow_inf_nan=False, description="c, the distance of the outer fibre from the neutral axis, m "
                                  "(strain ε = −c·κ)")
    bending_stiffness_xi: float | None = Field(None, gt=0.0, allow_inf_nan=False, description="EI for bending in ξ at the reference "
                                               "temperature, N·m² (required for a biaxial beam, ignored for a planar one)")
    fibre_distance_xi: float | None = Field(None, gt=0.0, allow_inf_nan=False, description="c_ξ, the outline's half-side along ξ, m "
                                            "(required for a biaxial beam, ignored for a planar one)")


Section = Annotated[RectangleSection | TubeSection | TableSection, Field(discriminator="shape")]

#: The dimensions of each shape that vary linearly along a taper.
_SECTION_DIMENSIONS = {
    "rectangle": ("width", "thickness"),
    "tube": ("outer_diameter", "wall_thickness"),
    "table": ("bending_stiffness", "mass_per_length", "fibre_distance"),
}
#: The keys a table station of a biaxial beam adds (they vary linearly along a taper too).
_TABLE_XI_KEYS = ("bending_stiffness_xi", "fibre_distance_xi")
#: An angle within this many degrees of a multiple of 90 is taken as that multiple, so the faces
#: (0, 90, 180, 270) get exact cosines and sines and a planar beam's strain stays −c·κ bit for bit.
_QUADRANT_TOLERANCE_DEG = 1e-9


def _cos_sin_deg(angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of angles in degrees, exact (0, ±1) at the multiples of 90."""
    angle = np.asarray(angle_deg, dtype=float)
    quarter = np.round(angle / 90.0)
    on_face = np.abs(angle - 90.0 * quarter) <= _QUADRANT_TOLERANCE_DEG
    radians = np.radians(angle)
    cos, sin = np.cos(radians), np.sin(radians)
    k = np.mod(quarter, 4).astype(int)
    cos = np.where(on_face, np.array([1.0, 0.0, -1.0, 0.0])[k], cos)
    sin = np.where(on_face, np.array([0.0, 1.0, 0.0, -1.0])[k], sin)
    return cos, sin


def _planar_angle(angle: float) -> bool:
    """True for the angles a planar beam accepts: the +ζ face (0) and the −ζ face (180), modulo 360."""
    return math.isfinite(angle) and float(np.mod(angle, 360.0)) in (0.0, 180.0)


def _require_table_xi(stations: tuple[Any, ...], indices: Any = None, error: type[ValueError] = ValueError) -> None:
    """A biaxial beam's table stations (those at ``indices``, default all) give their ξ properties:
    ``error`` naming the station and the key."""
    for index in range(len(stations)) if indices is None else indices:
        station = stations[index]
        for key in _TABLE_XI_KEYS if station.shape == "table" else ():
            if getattr(station, key) is None:
                raise error(
                    f"beam.sections[{index}].{key} is required: a table station of a biaxial beam "
                    "(beam.bending='biaxial') gives its ξ plane's bending_stiffness_xi and fibre_distance_xi"
                )


def _as_positions(positions: Any, length: float) -> tuple[np.ndarray, bool]:
    scalar = np.ndim(positions) == 0
    try:
        eta = np.atleast_1d(np.asarray(positions, dtype=float))
    except (TypeError, ValueError) as exc:
        raise RigError(f"positions={positions!r} must be arc lengths in m (numbers): {exc}") from None
    if eta.ndim != 1:
        raise RigError(f"positions must be a scalar or a 1-D array of arc lengths, got shape {eta.shape}")
    if np.any(~np.isfinite(eta)) or np.any(eta < 0.0) or np.any(eta > length * (1 + 1e-12)):
        bad = eta[~np.isfinite(eta) | (eta < 0.0) | (eta > length * (1 + 1e-12))]
        raise RigError(f"position {bad[0]} is outside the beam [0, {length}] m (positions are arc lengths on it; "
                       f"off the beam: {bad[:5].tolist()})")
    return np.clip(eta, 0.0, length), scalar


class Beam(_ContractModel):
    """The beam: length, material and cross-section along it.

    Without ``sections`` the beam is the uniform rectangle ``width`` × ``thickness`` (m) of the
    paper's sheet; with ``sections`` (stations of ``rectangle``, ``tube`` or ``table`` shape,
    ordered by position from 0 to ``length``, linear tapers between neighbours, a step where two
    stations share a position) its properties vary along it. ``youngs_modulus`` (Pa) and
    ``density`` (kg/m³) apply to rectangles and tubes; a beam of table sections only may omit them.
    """

    length: float = Field(gt=0.0, allow_inf_nan=False, description="arc length from D to the tip, m")
    width: float | None = Field(default=None, gt=0.0, allow_inf_nan=False, description="the uniform rectangle's width, m "
                                "(not with sections)")
    thickness: float | None = Field(default=None, gt=0.0, allow_inf_nan=False, description="the uniform rectangle's thickness, m "
                                    "(the beam bends across it; not with sections)")
    youngs_modulus: float | None = Field(default=None, gt=0.0, allow_inf_nan=False, description="E at the reference temperature, Pa "
                                         "(rectangles and tubes; a beam of table sections may omit it)")
    density: float | None = Field(default=None, gt=0.0, allow_inf_nan=False, description="ρ, kg/m³ (rectangles and tubes)")
    youngs_modulus_temperature_coefficient: float = Field(STEEL_YOUNGS_MODULUS_TEMPERATURE_COEFFICIENT, description=
                                                          "relative change of E per K (steel's by default); every EI follows it")
    reference_temperature: float = Field(20.0, description="the temperature E and the tables' EI are given at, °C")
    stiffness_segments: tuple[StiffnessSegment, ...] = Field((), description="segments whose EI is a factor times the nominal "
                                                             "(damage, stiffeners)")
    sections: tuple[Section, ...] | None = Field(None, description="the cross-section along the beam: stations of shape rectangle, "
                                                 "tube or table ordered from 0 to length, linear tapers between neighbours, a step where "
                                                 "two share a position; None: the uniform rectangle width × thickness")
    bending: Bending = Field("planar", description='"planar": bending in ζ only (the other axes carry only noise); "biaxial": '
                             "bending in ζ and in ξ = η × ζ (needs support='clamped'; a rectangle's width lies along ξ)")

    @model_validator(mode="after")
    def _sections_consistent(self) -> Beam:
        if self.sections is None:
            for key in ("width", "thickness", "youngs_modulus", "density"):
                if getattr(self, key) is None:
                    raise ValueError(f"beam.{key} is required (a uniform rectangle) unless beam.sections is given")
            return self
        for key in ("width", "thickness"):
            if getattr(self, key) is not None:
                raise ValueError(
                    f"beam.{key} is not allowed together with beam.sections: the sections give the cross-section"
                )
        stations = self.sections
        if len(stations) < 2:
            raise ValueError(f"beam.sections needs at least two stations (at 0 and at length), got {len(stations)}")
        if stations[0].position != 0.0:
            raise ValueError(f"beam.sections[0].position={stations[0].position} must be 0 (the first station is at D)")
        if not math.isclose(stations[-1].position, self.length, rel_tol=1e-12, abs_tol=0.0):
            raise ValueError(
                f"beam.sections[{len(stations) - 1}].position={stations[-1].position} must equal "
                f"beam.length={self.length} (the last station is at the tip)"
            )
        for index in range(1, len(stations)):
            before, here = stations[index - 1], stations[index]
            if here.position < before.position:
                raise ValueError(
                    f"beam.sections[{index}].position={here.position} is before beam.sections[{index - 1}].position="
                    f"{before.position}: stations are ordered by position"
                )
            if index >= 2 and here.position == before.position == stations[index - 2].position:
                raise ValueError(
                    f"beam.sections[{index}].position={here.position}: three stations at one position "
                    "(a step is exactly two)"
                )
            if here.position > before.position and here.shape != before.shape:
                raise ValueError(
                    f"beam.sections[{index}].shape={here.shape!r} differs from beam.sections[{index - 1}].shape="
                    f"{before.shape!r}: both ends of a taper have the same shape (a change of shape is a step, "
                    "two stations at one position)"
                )
        shapes = {station.shape for station in stations}
        for key in ("youngs_modulus", "density"):
            if getattr(self, key) is None and shapes & {"rectangle", "tube"}:
                raise ValueError(f"beam.{key} is required: it applies to the rectangle and tube sections")
        if self.bending == "biaxial":
            _require_table_xi(stations)
        return self

    @property
    def biaxial(self) -> bool:
        """True when the beam bends in both planes (``bending == "biaxial"``)."""
        return self.bending == "biaxial"

    # -- the uniform rectangle -----------------------------------------------------------
    def _uniform(self, what: str) -> None:
        if self.sections is not None:
            raise RigError(
                f"beam.{what} is a property of the uniform rectangle; this beam varies along beam.sections: "
                f"use the properties at positions (Beam.bending_stiffness, Beam.mass_per_length_at, Beam.fibre_distance)"
            )

    @property
    def uniform(self) -> bool:
        """True for the uniform rectangle (no ``sections``)."""
        return self.sections is None

    @property
    def area(self) -> float:
        self._uniform("area")
        return self.width * self.thickness

    @property
    def second_moment_of_area(self) -> float:
        """I of the rectangular section for bending across the thickness (m^4)."""
        self._uniform("second_moment_of_area")
        return self.width * self.thickness**3 / 12.0

    @property
    def second_moment_of_area_xi(self) -> float:
        """I_ξ of the rectangular section for bending in ξ, across the width (m^4): thickness·width³/12."""
        self._uniform("second_moment_of_area_xi")
        return self.thickness * self.width**3 / 12.0

    @property
    def mass_per_length(self) -> float:
        self._uniform("mass_per_length")
        return self.density * self.area

    @property
    def mass(self) -> float:
        """The beam's own mass (kg), integrated over the sections."""
        if self.sections is None:
            return self.mass_per_length * self.length
        return float(np.sum(self._segment_integrals(0)))

    # -- temperature ----------------------------------------------------------------------
    def stiffness_factor_at(self, temperature_c: float | None) -> float:
        """E(T)/E(T_ref): the factor on every bending stiffness at ``temperature_c`` (°C; ``None``: reference)."""
        if temperature_c is None:
            return 1.0
        if isinstance(temperature_c, bool) or not isinstance(temperature_c, (int, float, np.floating, np.integer)):
            raise RigError(f"{temperature_c=} must be a number (°C) or None")
        if not math.isfinite(temperature_c):
            raise RigError(f"{temperature_c=} must be finite")
        factor = 1.0 + self.youngs_modulus_temperature_coefficient * (temperature_c - self.reference_temperature)
        if factor <= 0.0:
            raise RigError(f"{temperature_c=} gives a non-positive Young's modulus")
        return factor

    def youngs_modulus_at(self, temperature_c: float | None) -> float:
        """E (Pa) at ``temperature_c`` (°C); ``None`` means the reference temperature."""
        if self.youngs_modulus is None:
            raise RigError("beam.youngs_modulus is not given (a beam of table sections): it has no E")
        if temperature_c is None:
            return self.youngs_modulus
        return self.youngs_modulus * self.stiffness_factor_at(temperature_c)

    # -- properties along the beam ----------------------------------------------------------
    @property
    def station_positions(self) -> np.ndarray:
        """Positions (m) of the section stations (empty for the uniform rectangle)."""
        if self.sections is None:
            return np.zeros(0)
        return np.array([station.position for station in self.sections], dtype=float)

    def _properties(self, eta: np.ndarray, plane: str = "zeta") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(EI at the reference temperature, μ, c) of ``plane`` ("zeta" or "xi") at arc lengths ``eta`` already on the beam.

        In ξ a rectangle bends across its width (EI_ξ = E·thickness·width³/12, c_ξ = width/2), a tube
        as in ζ, a table by its ``bending_stiffness_xi`` and ``fibre_distance_xi``.
        """
        if plane not in PLANES:
            raise RigError(f"plane={plane!r} must be one of {PLANES}")
        xi = plane == "xi"
        if self.sections is None:
            ones = np.ones_like(eta)
            inertia, c = (self.second_moment_of_area_xi, 0.5 * self.width) if xi else (self.second_moment_of_area, 0.5 * self.thickness)
            return self.youngs_modulus * inertia * ones, self.mass_per_length * ones, c * ones
        stations = self.sections
        positions = self.station_positions
        last = len(stations) - 1
        # The last station at or before η: at a step, the one listed later (the section beyond it).
        start = np.clip(np.searchsorted(positions, eta, side="right") - 1, 0, last)
        stiffness, mass, fibre = np.empty_like(eta), np.empty_like(eta), np.empty_like(eta)
        for j in np.unique(start):
            at = start == j
            a = stations[j]
            b = stations[min(j + 1, last)]
            span = b.position - a.position
            t = np.zeros(int(at.sum())) if j == last or span <= 0 else (eta[at] - a.position) / span
            keys = _SECTION_DIMENSIONS[a.shape] + (_TABLE_XI_KEYS if xi and a.shape == "table" else ())
            if xi and a.shape == "table":
                _require_table_xi(stations, (j, min(j + 1, last)), RigError)
            dims = {key: getattr(a, key) + t * (getattr(b, key) - getattr(a, key)) for key in keys}
            if a.shape == "rectangle":
                w, h = dims["width"], dims["thickness"]
                if xi:
                    w, h = h, w  # bending in ξ: across the width
                stiffness[at] = self.youngs_modulus * w * h**3 / 12.0
                mass[at] = self.density * w * h
                fibre[at] = 0.5 * h
            elif a.shape == "tube":
                outer = dims["outer_diameter"]
                inner = outer - 2.0 * dims["wall_thickness"]
                stiffness[at] = self.youngs_modulus * np.pi / 64.0 * (outer**4 - inner**4)
                mass[at] = self.density * np.pi / 4.0 * (outer**2 - inner**2)
                fibre[at] = 0.5 * outer
            elif a.shape == "table":
                stiffness[at] = dims["bending_stiffness_xi" if xi else "bending_stiffness"]
                mass[at] = dims["mass_per_length"]
                fibre[at] = dims["fibre_distance_xi" if xi else "fibre_distance"]
            else:
                raise RigError(f"beam.sections[{j}].shape={a.shape!r} must be 'rectangle', 'tube' or 'table'")
        return stiffness, mass, fibre

    def bending_stiffness(self, positions: Any, temperature_c: float | None = None) -> np.ndarray | float:
        """EI(η, T) in N·m² at arc lengths ``positions`` (m), nominal (without ``stiffness_segments``).

        Parameters
        ----------
        positions : float or array-like (n,), arc lengths on the beam [0, length] m.
        temperature_c : °C, or ``None`` for the reference temperature; E(T) through the beam's
            temperature coefficient (tables follow it too).

        Returns
        -------
        float or ndarray (n,). At a step the section beyond it.

        Raises
        ------
        RigError
            A position off the beam or not finite; a temperature that is not finite.
        """
        eta, scalar = _as_positions(positions, self.length)
        values = self._properties(eta)[0] * self.stiffness_factor_at(temperature_c)
        return float(values[0]) if scalar else values

    def mass_per_length_at(self, positions: Any) -> np.ndarray | float:
        """μ(η) = ρA in kg/m at arc lengths ``positions`` (m); at a step the section beyond it.

        Raises
        ------
        RigError
            A position off the beam or not finite.
        """
        eta, scalar = _as_positions(positions, self.length)
        values = self._properties(eta)[1]
        return float(values[0]) if scalar else values

    def fibre_distance(self, positions: Any) -> np.ndarray | float:
        """c(η) in m at arc lengths ``positions`` (m): half the thickness of a rectangle, half the outer
        diameter of a tube, the table's ``fibre_distance``; at a step the section beyond it.

        Bending strain on the +ζ face is ε = −c(η)·∂²Δ/∂η².

        Raises
        ------
        RigError
            A position off the beam or not finite.
        """
        eta, scalar = _as_positions(positions, self.length)
        values = self._properties(eta)[2]
        return float(values[0]) if scalar else values

    def bending_stiffness_xi(self, positions: Any, temperature_c: float | None = None) -> np.ndarray | float:
        """EI_ξ(η, T) in N·m² for bending in ξ, as ``bending_stiffness`` is for ζ: a rectangle's
        E·thickness·width³/12, a tube's EI, a table's ``bending_stiffness_xi`` (RigError without it)."""
        eta, scalar = _as_positions(positions, self.length)
        values = self._properties(eta, "xi")[0] * self.stiffness_factor_at(temperature_c)
        return float(values[0]) if scalar else values

    def fibre_distance_xi(self, positions: Any) -> np.ndarray | float:
        """c_ξ(η) in m, the outline's half-side along ξ: half a rectangle's width, half a tube's outer
        diameter, a table's ``fibre_distance_xi`` (RigError without it); at a step the section beyond it."""
        eta, scalar = _as_positions(positions, self.length)
        values = self._properties(eta, "xi")[2]
        return float(values[0]) if scalar else values

    def section_point(self, positions: Any, angle_deg: Any) -> tuple[np.ndarray | float, np.ndarray | float]:
        """(ζp, ξp) in m: where the ray from the section's centre at ``angle_deg`` (degrees from +ζ
        towards +ξ) meets the outline at arc lengths ``positions`` (m); the strain there is
        ε = −(ζp·κζ + ξp·κξ). The outline of a tube is its outer circle, of a rectangle or a table
        station the rectangle of half-sides c (along ζ) and c_ξ (along ξ). Floats for scalar inputs,
        else arrays of the broadcast shape. RigError for a position off the beam, an angle not
        finite, or an angle other than 0 ((c, 0)) and 180 ((−c, 0)) on a planar beam.

        >>> from contract import parse_rig
        >>> beam = parse_rig({"beam": {"length": 2.0, "width": 0.06, "thickness": 0.02, "youngs_modulus": 2.1e11,
        ...                            "density": 7850.0, "bending": "biaxial"}, "gravity": 0.0, "support": "clamped",
        ...                   "sensors": []}).beam
        >>> beam.section_point(1.0, 0.0), beam.section_point(1.0, 90.0), beam.section_point(1.0, 180.0)
        ((0.01, 0.0), (0.0, 0.03), (-0.01, 0.0))
        """
        return _section_point(self, positions, angle_deg)

    def _segment_integrals(self, moment: int) -> np.ndarray:
        """∫ μ(η) η^moment dη over each stretch between neighbouring stations (exact: μ is a polynomial of degree ≤ 2)."""
        xi, weights = np.polynomial.legendre.leggauss(4)
        positions = self.station_positions
        out = np.zeros(max(len(positions) - 1, 0))
        for j in range(len(out)):
            a, b = positions[j], positions[j + 1]
            if b <= a:
                continue
            x = 0.5 * (a + b) + 0.5 * (b - a) * xi
            mu = self._properties(x)[1]
            out[j] = 0.5 * (b - a) * float(np.sum(weights * mu * x**moment))
        return out


def _shapes_at(beam: Beam, eta: np.ndarray) -> np.ndarray:
    """The shape of the section at each arc length (the uniform beam's is "rectangle"; at a step the one beyond it)."""
    if beam.sections is None:
        return np.full(eta.shape, "rectangle", dtype=object)
    start = np.clip(np.searchsorted(beam.station_positions, eta, side="right") - 1, 0, len(beam.sections) - 1)
    return np.array([beam.sections[j].shape for j in start], dtype=object).reshape(eta.shape)


def _section_point(beam: Beam, positions: Any, angle_deg: Any) -> tuple[np.ndarray | float, np.ndarray | float]:
    """``Beam.section_point``."""
    eta, scalar_eta = _as_positions(positions, beam.length)
    scalar = scalar_eta and np.ndim(angle_deg) == 0
    try:
        angle = np.asarray(angle_deg, dtype=float)
    except (TypeError, ValueError):
        raise RigError(f"angle_deg={angle_deg!r} must be degrees (numbers)") from None
    if not np.all(np.isfinite(angle)):
        raise RigError(f"angle_deg={angle_deg!r} must be finite degrees")
    if scalar_eta:
        eta = eta.reshape(())
    eta, angle = np.broadcast_arrays(eta, angle)
    cos, sin = _cos_sin_deg(angle)
    c_zeta = beam._properties(eta.ravel())[2].reshape(eta.shape)
    if not beam.biaxial:
        bad = [float(a) for a in np.atleast_1d(angle).ravel() if not _planar_angle(float(a))]
        if bad:
            raise RigError(f"angle_deg={bad[0]:g}: a planar beam accepts only 0 and 180 (beam.bending='planar')")
        zeta_p, xi_p = c_zeta * cos, np.zeros_like(c_zeta)
    else:
        c_xi = beam._properties(eta.ravel(), "xi")[2].reshape(eta.shape)
        round_ = _shapes_at(beam, eta.ravel()).reshape(eta.shape) == "tube"
        # The rectangle: the ray leaves through a ζ face (|ζp| = c) unless it reaches a ξ face first.
        through_zeta = np.abs(sin) * c_zeta <= np.abs(cos) * c_xi
        with np.errstate(divide="ignore", invalid="ignore"):
            zeta_rect = np.where(through_zeta, np.copysign(c_zeta, cos), c_xi * cos / np.abs(sin))
            xi_rect = np.where(through_zeta, c_zeta * sin / np.abs(cos), np.copysign(c_xi, sin))
        zeta_p = np.where(round_, c_zeta * cos, zeta_rect)
        xi_p = np.where(round_, c_zeta * sin, xi_rect)
    if scalar:
        return float(zeta_p), float(xi_p)
    return zeta_p, xi_p


class HotSpot(_ContractModel):
    """A named position with a fatigue detail: its S–N curve, stress concentration and partial factors."""

    name: str = Field(min_length=1, description="the hot spot's name (unique), as the loads and /api/fatigue report it")
    position: float = Field(description="arc length from D, m")
    curve: str | dict[str, Any] = Field(description='its S–N curve: "EN1993-1-9:CLASS" (e.g. "EN1993-1-9:71"), '
                                        '"DNV-RP-C203:CURVE" (e.g. "DNV-RP-C203:D"), or {"points": [[N, Δσ Pa], ...]}')
    scf: float = Field(default=1.0, gt=0.0, description="stress concentration factor on the nominal stress")
    gamma_Ff: float = Field(default=1.0, gt=0.0, description="partial factor on the stress ranges (loads)")
    gamma_Mf: float = Field(default=1.0, gt=0.0, description="partial factor on the fatigue strength (material)")
    angle_deg: float | Literal["all"] = Field(default=0.0, description='where around the section, degrees from +ζ towards +ξ (0: the '
                                              '+ζ face); "all": the worst point around the circumference (a girth weld; biaxial '
                                              "beams only); a planar beam accepts only 0 and 180")

    @field_validator("angle_deg")
    @classmethod
    def _finite_angle(cls, value: Any) -> Any:
        if value != "all" and not math.isfinite(value):
            raise ValueError(f"angle_deg={value!r} must be finite degrees or 'all'")
        return value

    @field_validator("curve")
    @classmethod
    def _known_curve(cls, value: Any) -> Any:
        check_curve_spec(value)
        return value


class FatigueSettings(_ContractModel):
    """Rig-level fatigue settings: the design life the remaining life is judged against."""

    design_life_years: float | None = Field(default=None, gt=0.0, description="the design life, years: the remaining life and "
                                            "the consumed share are judged against it (shm loads, /api/fatigue)")


class PointMass(_ContractModel):
    position: float = Field(ge=0.0, description="arc length from D, m")
    mass: float = Field(ge=0.0, description="kg (a sensor board, an added mass)")
    rotary_inertia: float = Field(default=0.0, ge=0.0, description="about the axis of bending, kg·m²")


class Sensor(_ContractModel):
    name: str = Field(min_length=1, description="unique within its kind; the topic's NAME (/imu/NAME); the IMU at the support is D")
    kind: SensorKind = Field(description="imu (accel + gyro), tof (distance to the reflector), strain (a gauge, on the +ζ face unless its angle_deg says otherwise), "
                             "bearing (the support's displacement d), temperature")
    position: float | None = Field(None, description="arc length from D, m (required for imu, tof and strain)")
    angle_deg: float = Field(0.0, allow_inf_nan=False, description="a strain gauge's place around the section, degrees from +ζ "
                             "towards +ξ (0: the +ζ face, 90: the +ξ face); a planar beam accepts only 0 and 180")

    @property
    def topic(self) -> str:
        if self.kind == "bearing":
            return "/bearing/displacement"
        if self.kind == "temperature":
            return "/env/temperature"
        if self.kind in _POSITIONED_KINDS:
            return f"/{self.kind}/{self.name}"
        raise RigError(f"unknown sensor kind {self.kind!r}")


class RigDescription(_ContractModel):
    """The rig: beam, support at D (``pinned``: the paper's plain bearing, φ a state; ``clamped``: the
    fixed bearing of Section 3.5, φ ≡ 0), orientation (``hanging`` below D, gravity along +η;
    ``standing`` above D, gravity along −η, self-weight compresses the beam), attached masses and sensors."""

    beam: Beam = Field(description="the beam: length, material, cross-section along it (the beam section below)")
    gravity: float = Field(ge=0.0, description="g, m/s² (0: a beam moving in a horizontal plane)")
    reflector_distance: float | None = Field(None, description="distance of the ToFs' reflector plane from D along ζ at rest, m "
                                             "(required with ToF sensors, else left out)")
    support: Support = Field("pinned", description='"pinned": the paper\'s plain bearing (φ a state); "clamped": fixed to the '
                             'carriage or the ground (φ ≡ 0)')
    orientation: Orientation = Field("hanging", description='"hanging": below D, gravity along +η; "standing": above D (a mast), '
                                     "gravity along −η (needs clamped)")
    point_masses: tuple[PointMass, ...] = Field((), description="attached masses (the point_masses[] section below)")
    sensors: tuple[Sensor, ...] = Field(description="every sensor (the sensors[] section below)")
    truth_stations: tuple[float, ...] = Field((), description="stations where a simulation writes the true deflection and curvature, m")
    hot_spots: tuple[HotSpot, ...] = Field((), description="fatigue details for shm loads and /api/fatigue (the hot_spots[] section below)")
    fatigue: FatigueSettings | None = Field(None, description="rig-level fatigue settings (the fatigue section below)")

    @model_validator(mode="after")
    def _consistent(self) -> "RigDescription":
        length = self.beam.length
        if self.beam.biaxial and self.support != "clamped":
            raise ValueError(
                f"beam.bending='biaxial' needs support='clamped', got support={self.support!r}: the support must hold the "
                "beam in both planes (a pinned bearing turns freely in ξ)"
            )
        if self.support == "pinned" and self.orientation == "standing":
            raise ValueError(
                "support='pinned' with orientation='standing' is an inverted pendulum, unstable at any length: "
                "a standing beam needs support='clamped'"
            )
        if self.reflector_distance is None and self.sensors_of("tof"):
            names = ", ".join(s.name for s in self.sensors_of("tof"))
            raise ValueError(f"reflector_distance is required: the rig has ToF sensors ({names}) that measure to the reflector plane")
        if self.reflector_distance is not None and not math.isfinite(self.reflector_distance):
            raise ValueError(f"reflector_distance={self.reflector_distance} must be finite")
        seen: set[tuple[str, str]] = set()
        for index, sensor in enumerate(self.sensors):
            key = (sensor.kind, sensor.name)
            if key in seen:
                raise ValueError(f"sensors[{index}]: name {sensor.name!r} is not unique within kind {sensor.kind!r}")
            seen.add(key)
            if sensor.kind in _POSITIONED_KINDS:
                if sensor.position is None:
                    raise ValueError(f"sensors[{index}] ({sensor.kind} {sensor.name!r}): position is required")
                if not (0.0 <= sensor.position <= length) or not math.isfinite(sensor.position):
                    raise ValueError(
                        f"sensors[{index}] ({sensor.kind} {sensor.name!r}): position={sensor.position} "
                        f"is outside the beam [0, {length}]"
                    )
        self._angles_fit_bending()
        for index, mass in enumerate(self.point_masses):
            if mass.position > length:
                raise ValueError(f"point_masses[{index}]: position={mass.position} is outside the beam [0, {length}]")
        for index, segment in enumerate(self.beam.stiffness_segments):
            if segment.end > length:
                raise ValueError(f"beam.stiffness_segments[{index}]: end={segment.end} is outside the beam [0, {length}]")
        for index, station in enumerate(self.truth_stations):
            if not (0.0 <= station <= length):
                raise ValueError(f"truth_stations[{index}]={station} is outside the beam [0, {length}]")
        spot_names: set[str] = set()
        for index, spot in enumerate(self.hot_spots):
            if not (math.isfinite(spot.position) and 0.0 <= spot.position <= length):
                raise ValueError(f"hot_spots[{index}] ({spot.name!r}): position={spot.position} is outside the beam [0, {length}]")
            if spot.name in spot_names:
                raise ValueError(f"hot_spots[{index}]: name {spot.name!r} is not unique")
            spot_names.add(spot.name)
        return self

    def _angles_fit_bending(self) -> None:
        """A planar beam knows only the ζ faces: its gauges and hot spots sit at 0 or 180 degrees."""
        if self.beam.biaxial:
            return
        for index, sensor in enumerate(self.sensors):
            if sensor.kind == "strain" and not _planar_angle(sensor.angle_deg):
                raise ValueError(
                    f"sensors[{index}] (strain {sensor.name!r}): angle_deg={sensor.angle_deg:g}, but a planar beam accepts only 0 and 180 "
                    "(beam.bending='planar'; other angles need beam.bending='biaxial')"
                )
        for index, spot in enumerate(self.hot_spots):
            if spot.angle_deg == "all" or not _planar_angle(spot.angle_deg):
                angle = repr(spot.angle_deg) if spot.angle_deg == "all" else format(spot.angle_deg, "g")
                raise ValueError(
                    f"hot_spots[{index}] ({spot.name!r}): angle_deg={angle}, but a planar beam accepts only 0 and 180 "
                    "(beam.bending='planar'; other angles and 'all' need beam.bending='biaxial')"
                )

    @property
    def support_fixed_to_ground(self) -> bool:
        """No ``bearing`` sensor: the support D is fixed to the ground (d ≡ 0), as a mast on its foundation."""
        return not self.sensors_of("bearing")

    def sensors_of(self, kind: SensorKind) -> tuple[Sensor, ...]:
        return tuple(s for s in self.sensors if s.kind == kind)

    def sensor_by_topic(self) -> dict[str, Sensor]:
        return {s.topic: s for s in self.sensors}

    def extra(self, key: str, default: Any = None) -> Any:
        """An extension key of the description (for example the simulator's settings)."""
        return (self.model_extra or {}).get(key, default)

    def to_json(self) -> str:
        data = self.model_dump(mode="json", exclude_defaults=False)
        # Optional keys the contract says are "not given" (a sectioned beam's width and thickness, a
        # table beam's material, a rig without ToFs' reflector) are left out rather than written as null.
        for key in ("width", "thickness", "youngs_modulus", "density", "sections"):
            if data["beam"].get(key, 0) is None:
                del data["beam"][key]
        # The biaxial keys at their defaults are left out too: a planar rig's description reads as before.
        if data["beam"].get("bending") == "planar":
            del data["beam"]["bending"]
        for station in data["beam"].get("sections") or ():
            for key in _TABLE_XI_KEYS:
                if key in station and station[key] is None:
                    del station[key]
        for item in (*data["sensors"], *data["hot_spots"]):
            if item.get("angle_deg") == 0.0:
                del item["angle_deg"]
        if data.get("reflector_distance", 0) is None:
            del data["reflector_distance"]
        return json.dumps(data, indent=2)


def _key(loc: tuple[Any, ...]) -> str:
    """A pydantic error location as the key in rig.json: ``beam.sections[3].outer_diameter``."""
    key = ""
    previous: Any = None
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
        elif isinstance(previous, int) and part in _SECTION_DIMENSIONS and key.startswith("beam.sections"):
            pass  # the shape tag of a section (pydantic's union branch), not a key of rig.json
        else:
            key += f".{part}" if key else str(part)
        previous = part
    return key or "<root>"


def parse_rig(data: bytes | str | dict[str, Any], *, source: str = "rig.json") -> RigDescription:
    """Validate a rig description given as JSON text/bytes or an already parsed mapping.

    Examples
    --------
    >>> from contract import parse_rig
    >>> rig = parse_rig('{"beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, '
    ...                 '"youngs_modulus": 2.0e11, "density": 7850.0}, "gravity": 9.81, '
    ...                 '"reflector_distance": 0.5, "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]}')
    >>> rig.support, rig.orientation, rig.sensors[0].topic
    ('pinned', 'hanging', '/imu/D')
    >>> parse_rig({"beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": 2.0e11,
    ...                     "density": 7850.0}, "gravity": 9.81, "reflector_distance": 0.5,
    ...            "sensors": [{"name": "s1", "kind": "imu", "position": 5.0}]})
    Traceback (most recent call last):
    ...
    contract._rig.RigError: rig.json: ... position=5.0 is outside the beam [0, 4.0]
    """
    if isinstance(data, (bytes, str)):
        try:
            data = json.loads(data)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise RigError(f"{source}: not valid JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise RigError(f"{source}: must be a JSON object, got {type(data).__name__}")
    try:
        return RigDescription.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(f"{_key(err['loc'])}: {err['msg']}" for err in exc.errors())
        raise RigError(f"{source}: {problems}") from None


def load_rig(path: str | Path) -> RigDescription:
    """Read a rig description from a ``.json`` or ``.toml`` file."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RigError(f"cannot read rig description {str(path)!r}: {exc}") from exc
    if path.suffix.lower() == ".toml":
        try:
            return parse_rig(tomllib.loads(raw.decode("utf-8")), source=str(path))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise RigError(f"{path}: not valid TOML: {exc}") from exc
    return parse_rig(raw, source=str(path))
