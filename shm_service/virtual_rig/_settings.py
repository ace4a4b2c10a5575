"""Settings of the virtual rig: typed, closed, with every default documented."""

from __future__ import annotations

import re
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_serializer, model_validator

from estimator import PointMass, StiffnessSegment

__all__ = ["Damage", "OperationalSettings", "PlantSettings", "SensorErrors", "SimulationSettings", "WindDirection",
           "WindStorm", "parse_damage", "settings_for_rig"]


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SensorErrors(_Closed):
    """Sensor error figures (1σ unless named otherwise), typical of the paper's MEMS boards."""

    accel_noise: float = Field(0.012, ge=0, description="white noise per sample, m/s² (≈120 µg/√Hz at 200 Hz)")
    gyro_noise: float = Field(7e-4, ge=0, description="white noise per sample, rad/s (≈4 mdps/√Hz)")
    accel_bias: float = Field(0.03, ge=0, description="constant bias per axis, m/s²")
    gyro_bias: float = Field(5e-3, ge=0, description="constant bias per axis, rad/s (≈0.3 °/s)")
    accel_bias_instability: float = Field(2e-3, ge=0, description="wandering bias (Gauss–Markov), m/s²")
    gyro_bias_instability: float = Field(
        1e-4, ge=0, description="wandering bias (Gauss–Markov), rad/s (≈20 °/h, low-cost MEMS of the MPU-6050 class)"
    )
    bias_correlation_time: float = Field(300.0, gt=0, description="correlation time of the wander, s")
    accel_scale_factor: float = Field(0.01, ge=0, description="scale-factor error, relative (realistic only)")
    gyro_scale_factor: float = Field(0.01, ge=0, description="scale-factor error, relative (realistic only)")
    misalignment: float = Field(0.005, ge=0, description="in-plane axis misalignment, rad (realistic only)")
    tof_noise: float = Field(0.002, ge=0, description="ToF white noise, m")
    tof_resolution: float = Field(0.001, ge=0, description="ToF quantisation step, m")
    tof_offset: float = Field(0.002, ge=0, description="ToF constant offset, m (realistic only)")
    strain_noise: float = Field(5e-7, ge=0, description="strain white noise, m/m")
    strain_offset: float = Field(2e-6, ge=0, description="strain zero offset, m/m (realistic only)")
    bearing_noise: float = Field(5e-5, ge=0, description="bearing displacement sensor noise, m")
    temperature_noise: float = Field(0.05, ge=0, description="temperature sensor noise, K")
    imu_delay: float = Field(0.004, ge=0, description="delivery delay of IMU samples, s")
    strain_delay: float = Field(0.003, ge=0, description="delivery delay of strain samples, s")
    tof_delay: float = Field(0.030, ge=0, description="delivery delay of ToF and bearing samples, s")
    delay_jitter: float = Field(0.002, ge=0, description="random part of the delivery delay, s")
    tof_time_offset: float = Field(
        0.0, ge=0, lt=0.005, description="ToF and bearing samples taken this long after the 200 Hz grid, s (another logger's clock)"
    )


class PlantSettings(_Closed):
    """How the simulated beam differs from the nominal description (all off with ``ideal``)."""

    modes: int = Field(12, ge=4, le=30, description="clamped-frame modes in the plant's basis")
    damping_ratios: tuple[float, ...] = Field(
        (0.006, 0.005, 0.005, 0.006, 0.007, 0.008, 0.01),
        description="modal damping of modes 1, 2, ...; the last value holds for higher modes",
    )
    friction_torque: float = Field(
        0.0, ge=0,
        description="Coulomb friction torque of the bearing, N·m [0: off]. Opt-in because a Coulomb support makes the "
        "modal figures amplitude dependent (stick-slip, friction damping), so the recording's exact linear modal "
        "figures no longer describe the plant; the study turns it on (0.03)",
    )
    stiffness_mismatch: float = Field(0.03, ge=0, description="1σ relative error of the sheet's E")
    mass_mismatch: float = Field(0.05, ge=0, description="1σ relative error of each board's mass and inertia")
    substeps: int = Field(
        5, ge=1, le=50,
        description="Runge–Kutta steps per 200 Hz sample, at least; raised so that the highest mode of the basis "
        "takes ω·h ≤ 0.6 (a short, stiff beam has modes of hundreds of Hz)")
    ambient_force: float = Field(0.05, ge=0, description="random load per FE node and sample (ambient), N; small enough that the beam stays in its linear range")


class OperationalSettings(_Closed):
    """The operational excitation (``excitation = "operational"``): the support moving randomly
    and a random distributed load along the beam, as in service (a mast on a vessel, a blade on
    its hub, a wing on a fuselage)."""

    support_rms: float = Field(0.003, ge=0, le=0.05, description="RMS of the support displacement d(t) after the ramp, m [0.003]")
    support_band: tuple[float, float] = Field(
        (0.2, 30.0), description="band of the support acceleration (flat inside, Butterworth order 4 edges), Hz [0.2, 30]")
    load_rms: float = Field(0.05, ge=0, description="RMS of the distributed load at any point, N/m [0.05]")
    load_correlation: float = Field(1.0, gt=0, description="correlation length of the load along the beam (exponential kernel), m [1]")
    load_band: tuple[float, float] = Field((0.1, 30.0), description="band of the load's time history, Hz [0.1, 30]")
    ramp: float = Field(10.0, ge=0, description="raised-cosine ramp-in after the rest phase, s [10]")

    @model_validator(mode="after")
    def _bands(self) -> "OperationalSettings":
        for name in ("support_band", "load_band"):
            lo, hi = getattr(self, name)
            if not 0 < lo < hi < 100:
                raise ValueError(f"{name}=({lo}, {hi}) must satisfy 0 < low < high < 100 Hz (the rig's Nyquist frequency)")
        return self


class Damage(_Closed):
    kind: Literal["mass", "stiffness"]
    mass: float | None = None
    position: float | None = None
    factor: float | None = None
    start: float | None = None
    end: float | None = None

    def as_point_mass(self) -> PointMass:
        return PointMass(position=self.position, mass=self.mass, label="damage")

    def as_segment(self) -> StiffnessSegment:
        return StiffnessSegment(start=self.start, end=self.end, factor=self.factor)

    @property
    def nodes(self) -> tuple[float, ...]:
        # Damage comes from parse_damage (or a recording's settings), which sets the fields of its kind:
        # the callers compare and mesh at these positions.
        if self.kind == "mass":
            assert self.position is not None, "a mass damage has its position"
            return (self.position,)
        assert self.start is not None and self.end is not None, "a stiffness damage has its start and end"
        return (self.start, self.end)


_MASS = re.compile(r"^mass:(?P<kg>[^@]+)@(?P<pos>.+)$")
_STIFFNESS = re.compile(r"^stiffness:(?P<factor>[^@]+)@(?P<a>[^-]+)-(?P<b>.+)$")


def parse_damage(text: str) -> Damage:
    """Parse ``mass:KG@POS`` or ``stiffness:FACTOR@A-B`` (positions in m from D)."""
    text = text.strip()
    try:
        if m := _MASS.match(text):
            kg, pos = float(m["kg"]), float(m["pos"])
            if not kg > 0 or not pos >= 0:
                raise ValueError
            return Damage(kind="mass", mass=kg, position=pos)
        if m := _STIFFNESS.match(text):
            factor, a, b = float(m["factor"]), float(m["a"]), float(m["b"])
            if not factor > 0 or not 0 <= a < b:
                raise ValueError
            return Damage(kind="stiffness", factor=factor, start=a, end=b)
    except ValueError:
        pass
    raise ValueError(f"damage {text!r} must be 'mass:KG@POS' (KG > 0) or 'stiffness:FACTOR@A-B' (FACTOR > 0, A < B)")


class WindStorm(_Closed):
    """A storm that passes: the wind load's RMS rises smoothly from its ambient level to ``peak``
    times it halfway between ``start_s`` and ``end_s`` and falls back (``_wind.storm_factor``)."""

    start_s: float = Field(ge=0, description="when the storm begins, s")
    end_s: float = Field(gt=0, description="when it has passed, s")
    peak: float = Field(3.0, gt=0, le=100, description="the load's RMS at the peak over its ambient RMS (load ~ wind speed²)")

    @model_validator(mode="after")
    def _ordered(self) -> "WindStorm":
        if not self.start_s < self.end_s:
            raise ValueError(f"the storm's start_s={self.start_s} must come before its end_s={self.end_s}")
        return self


class WindDirection(_Closed):
    """The direction the wind load acts in on a biaxial beam, veering about its mean:
    ψ(t) = mean_deg + veer_deg · sin(2π t / period_s), from +ζ towards +ξ; the load p(η, t) acts as
    p cos ψ in ζ and p sin ψ in ξ. The defaults load ξ at about 0.6 of ζ (RMS over whole periods:
    E[sin²ψ]/E[cos²ψ] = (1 − J₀(2·veer) cos 2·mean)/(1 + J₀(2·veer) cos 2·mean) = 0.59²)."""

    mean_deg: float = Field(25.0, ge=-180, le=180, description="mean direction, degrees from +ζ towards +ξ [25]")
    veer_deg: float = Field(30.0, ge=0, le=180, description="amplitude of the veer about the mean, degrees [30]")
    period_s: float = Field(600.0, gt=0, description="period of the veer, s [600]")


class SimulationSettings(_Closed):
    duration: float = Field(300.0, gt=0, le=7 * 24 * 3600, description="recording length, s")
    seed: int = Field(1, ge=0)
    plant_seed: int | None = Field(
        None, ge=0, description="seed of the structure as built (E and board masses drawn off the nominal); None: seed. "
        "Recordings of one structure (a baseline, then monitoring) share it and differ in seed")
    excitation: Literal["paper", "ambient", "decay", "operational"] = "paper"
    layout: Literal["benchmark", "dense"] = "benchmark"
    support: Literal["pinned", "clamped"] = Field(
        "pinned", description="pinned: the plain bearing (the beam swings about D); clamped: the fixed bearing (θ ≡ 0)")
    orientation: Literal["hanging", "standing"] = Field(
        "hanging", description="hanging below D (self-weight stretches it) or standing above it (compresses it; needs clamped)")
    length: float = Field(
        4.0, gt=0, le=100, description="beam length, m; the layout's sensors and truth stations scale with it")
    ideal: bool = Field(False, description="plant = nominal rig: no mismatch, friction, scale or misalignment errors")
    damage: tuple[Damage, ...] = ()
    damage_at: float | None = Field(None, ge=0, description="time the damage appears, s (None: from the start)")
    temperature_mean: float = Field(20.0, description="°C")
    temperature_swing: float = Field(0.0, ge=0, description="peak-to-peak temperature swing over the run, K")
    rest: float = Field(60.0, ge=0, description="initial rest phase, s")
    wind_load_rms: float | None = Field(
        None, ge=0, description="RMS of the ambient (wind) load along the beam, N/m, for the ambient and operational "
        "excitations; None: operational.load_rms for the built-in sheet, scaled to the structure for a rig file "
        "(the load whose quasi-static RMS strain at the support is wind_base_strain)")
    wind_base_strain: float = Field(
        5e-5, gt=0, le=1e-2, description="quasi-static RMS bending strain at the support of the scaled wind load of a rig "
        "file, m/m [5e-5: 10.5 MPa on steel; resonance adds to it]")
    wind_correlation: float | None = Field(
        None, gt=0, description="correlation length of the wind load along the beam, m; None: operational.load_correlation "
        "for the built-in sheet, a quarter of the beam (at least 1 m) for a rig file")
    wind_storm: WindStorm | None = Field(
        None, description="a storm that passes: the wind load (ambient and operational excitations with a wind load) "
        "ramps up to peak times its RMS and back down between start_s and end_s")
    wind_direction: WindDirection | None = Field(
        None, description="the wind load's veering direction on a biaxial beam (beam.bending = 'biaxial'); None: the "
        "defaults of WindDirection there. Refused for a planar beam, which bends in ζ only")
    start_time_ns: int = Field(1_767_225_600_000_000_000, ge=0, description="log_time of the first sample (2026-01-01 UTC)")
    plant: PlantSettings = PlantSettings()
    errors: SensorErrors = SensorErrors()
    operational: OperationalSettings = OperationalSettings()

    @model_validator(mode="after")
    def _friction_needs_a_bearing_that_turns(self) -> "SimulationSettings":
        if self.support == "clamped" and self.plant.friction_torque > 0:
            raise ValueError(
                f"plant.friction_torque={self.plant.friction_torque} acts on the pinned bearing's rotation: "
                "a clamped support has none (leave it 0)")
        return self

    @model_serializer(mode="wrap")
    def _without_an_unset_wind_direction(self, handler):
        # A planar run's settings (written into its recording) stay as they were before the setting existed.
        data = handler(self)
        if self.wind_direction is None and isinstance(data, dict):
            data.pop("wind_direction", None)
        return data

    @field_validator("damage", mode="before")
    @classmethod
    def _parse_damage(cls, value: object) -> object:
        if isinstance(value, (list, tuple)):
            return tuple(parse_damage(v) if isinstance(v, str) else v for v in value)
        return value


#: Keys of a layout's settings that a rig file describes itself (its beam, support and orientation).
_RIG_OWNED = ("support", "orientation", "length", "layout")


def settings_for_rig(rig, command_line: SimulationSettings, given: set[str] | frozenset[str] = frozenset()) -> SimulationSettings:
    """The settings of simulating the rig file ``rig``: its ``simulator`` key (any field of
    :class:`SimulationSettings` but the rig's own support, orientation, length and layout), then the
    ``given`` fields of ``command_line`` (options the user set), with support and orientation the rig's.

    Raises
    ------
    ValueError
        When ``simulator`` is not an object or names an unknown setting (pydantic's
        ``ValidationError``, naming the key).
    """
    file = rig.extra("simulator") or {}
    if not isinstance(file, dict):
        raise ValueError(f"the rig's 'simulator' key must be an object of settings, got {type(file).__name__}")
    data = {k: v for k, v in file.items() if k not in _RIG_OWNED}
    cli = command_line.model_dump(mode="json")
    for name in given:
        if name == "plant":  # the command line sets only the friction of the plant's settings
            data["plant"] = {**(data.get("plant") or {}), "friction_torque": command_line.plant.friction_torque}
        elif name in cli:
            data[name] = cli[name]
        else:
            raise ValueError(f"unknown simulation setting {name!r}")
    data["support"] = rig.support
    data["orientation"] = rig.orientation
    return SimulationSettings.model_validate(data)
