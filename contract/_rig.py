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
from typing import Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

__all__ = [
    "DNV_RP_C203_CURVE_NAMES",
    "DNV_RP_C203_ENVIRONMENTS",
    "EN1993_DETAIL_CATEGORIES",
    "EN1993_SHEAR_CATEGORIES",
    "Beam",
    "FatigueSettings",
    "HotSpot",
    "PointMass",
    "RigDescription",
    "RigError",
    "Sensor",
    "StiffnessSegment",
    "check_curve_spec",
    "load_rig",
    "parse_rig",
]

SensorKind = Literal["imu", "tof", "strain", "bearing", "temperature"]
Support = Literal["pinned", "clamped"]
Orientation = Literal["hanging", "standing"]

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

    start: float = Field(ge=0.0)
    end: float
    factor: float = Field(gt=0.0)

    @model_validator(mode="after")
    def _ordered(self) -> "StiffnessSegment":
        if not self.end > self.start:
            raise ValueError(f"stiffness segment needs end > start, got start={self.start}, end={self.end}")
        return self


class Beam(_ContractModel):
    length: float = Field(gt=0.0)
    width: float = Field(gt=0.0)
    thickness: float = Field(gt=0.0)
    youngs_modulus: float = Field(gt=0.0)
    density: float = Field(gt=0.0)
    youngs_modulus_temperature_coefficient: float = STEEL_YOUNGS_MODULUS_TEMPERATURE_COEFFICIENT
    reference_temperature: float = 20.0
    stiffness_segments: tuple[StiffnessSegment, ...] = ()

    @property
    def area(self) -> float:
        return self.width * self.thickness

    @property
    def second_moment_of_area(self) -> float:
        """I of the rectangular section for bending across the thickness (m^4)."""
        return self.width * self.thickness**3 / 12.0

    @property
    def mass_per_length(self) -> float:
        return self.density * self.area

    @property
    def mass(self) -> float:
        return self.mass_per_length * self.length

    def youngs_modulus_at(self, temperature_c: float | None) -> float:
        """E (Pa) at ``temperature_c`` (°C); ``None`` means the reference temperature."""
        if temperature_c is None:
            return self.youngs_modulus
        if not math.isfinite(temperature_c):
            raise RigError(f"{temperature_c=} must be finite")
        factor = 1.0 + self.youngs_modulus_temperature_coefficient * (temperature_c - self.reference_temperature)
        if factor <= 0.0:
            raise RigError(f"{temperature_c=} gives a non-positive Young's modulus")
        return self.youngs_modulus * factor

    def _positions(self, positions: object) -> np.ndarray:
        eta = np.asarray(positions, dtype=float)
        bad = ~np.isfinite(eta) | (eta < 0.0) | (eta > self.length)
        if bad.any():
            raise RigError(f"position {eta[bad].ravel()[0]} is outside the beam [0, {self.length}]")
        return eta

    def fibre_distance(self, positions: object) -> np.ndarray:
        """c(η) (m) at arc lengths ``positions`` (m): half the thickness of the uniform rectangle."""
        return np.full(self._positions(positions).shape, 0.5 * self.thickness)

    def bending_stiffness(self, positions: object, temperature_c: float | None = None) -> np.ndarray:
        """EI(η, T) (N·m²) at ``positions`` (m), nominal (without ``stiffness_segments``), E at ``temperature_c``."""
        return np.full(self._positions(positions).shape, self.youngs_modulus_at(temperature_c) * self.second_moment_of_area)


class HotSpot(_ContractModel):
    """A named position with a fatigue detail: its S–N curve, stress concentration and partial factors."""

    name: str = Field(min_length=1)
    position: float
    curve: str | dict[str, Any]
    scf: float = Field(default=1.0, gt=0.0)
    gamma_Ff: float = Field(default=1.0, gt=0.0)
    gamma_Mf: float = Field(default=1.0, gt=0.0)

    @field_validator("curve")
    @classmethod
    def _known_curve(cls, value: Any) -> Any:
        check_curve_spec(value)
        return value


class FatigueSettings(_ContractModel):
    """Rig-level fatigue settings: the design life the remaining life is judged against."""

    design_life_years: float | None = Field(default=None, gt=0.0)


class PointMass(_ContractModel):
    position: float = Field(ge=0.0)
    mass: float = Field(ge=0.0)
    rotary_inertia: float = Field(default=0.0, ge=0.0)


class Sensor(_ContractModel):
    name: str = Field(min_length=1)
    kind: SensorKind
    position: float | None = None

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

    beam: Beam
    gravity: float = Field(ge=0.0)
    reflector_distance: float
    support: Support = "pinned"
    orientation: Orientation = "hanging"
    point_masses: tuple[PointMass, ...] = ()
    sensors: tuple[Sensor, ...]
    truth_stations: tuple[float, ...] = ()
    hot_spots: tuple[HotSpot, ...] = ()
    fatigue: FatigueSettings | None = None

    @model_validator(mode="after")
    def _consistent(self) -> "RigDescription":
        length = self.beam.length
        if self.support == "pinned" and self.orientation == "standing":
            raise ValueError(
                "support='pinned' with orientation='standing' is an inverted pendulum, unstable at any length: "
                "a standing beam needs support='clamped'"
            )
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
        for index, mass in enumerate(self.point_masses):
            if mass.position > length:
                raise ValueError(f"point_masses[{index}]: position={mass.position} is outside the beam [0, {length}]")
        for index, segment in enumerate(self.beam.stiffness_segments):
            if segment.end > length:
                raise ValueError(f"beam.stiffness_segments[{index}]: end={segment.end} is outside the beam [0, {length}]")
        for index, station in enumerate(self.truth_stations):
            if not (0.0 <= station <= length):
                raise ValueError(f"truth_stations[{index}]={station} is outside the beam [0, {length}]")
        names: set[str] = set()
        for index, spot in enumerate(self.hot_spots):
            if not (math.isfinite(spot.position) and 0.0 <= spot.position <= length):
                raise ValueError(f"hot_spots[{index}] ({spot.name!r}): position={spot.position} is outside the beam [0, {length}]")
            if spot.name in names:
                raise ValueError(f"hot_spots[{index}]: name {spot.name!r} is not unique")
            names.add(spot.name)
        return self

    def sensors_of(self, kind: SensorKind) -> tuple[Sensor, ...]:
        return tuple(s for s in self.sensors if s.kind == kind)

    def sensor_by_topic(self) -> dict[str, Sensor]:
        return {s.topic: s for s in self.sensors}

    def extra(self, key: str, default: Any = None) -> Any:
        """An extension key of the description (for example the simulator's settings)."""
        return (self.model_extra or {}).get(key, default)

    def to_json(self) -> str:
        return json.dumps(self.model_dump(mode="json", exclude_defaults=False), indent=2)


def parse_rig(data: bytes | str | dict[str, Any], *, source: str = "rig.json") -> RigDescription:
    """Validate a rig description given as JSON text/bytes or an already parsed mapping."""
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
        problems = "; ".join(
            f"{'.'.join(str(p) for p in err['loc']) or '<root>'}: {err['msg']}" for err in exc.errors()
        )
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
