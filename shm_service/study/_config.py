"""Settings of a sensor-configuration study and the configurations it runs (paper, Section 4)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from estimator import default_aided

Peripheral = Literal["gyro", "acc"]

GAMMA = 4  # the paper studies Γ = 4 (a rig file may ask for another Γ: StudySettings.modes)
BENCHMARK_COUNTS = (4, 4, 4)  # ν_s = ν_ρ = ν_ε = 4 (gyro: the benchmark "bm")


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Configuration(_Closed):
    """One sensor configuration: the peripheral input sensor, the counts ν_s, ν_ρ, ν_ε (picked by
    Effective Independence) and the unit deformations the gauges aid (Eq. 22)."""

    peripheral: Peripheral
    imus: int = Field(ge=1, description="ν_s, peripheral IMUs (at least Γ)")
    tofs: int = Field(ge=0, description="ν_ρ, ToFs")
    gauges: int = Field(ge=0, description="ν_ε, strain gauges")
    aided: tuple[int, ...] = Field(default=(), description="unit deformations (1-based) aided by the gauges")
    modes: int = Field(GAMMA, ge=1, le=5, description="Γ, unit deformations estimated")

    @model_validator(mode="before")
    @classmethod
    def _default_aiding(cls, data: object) -> object:
        if isinstance(data, dict) and isinstance(data.get("gauges"), int) and data["gauges"] > 0 and not data.get("aided"):
            gamma = int(data.get("modes", GAMMA))
            return {**data, "aided": default_aided(gamma, min(data["gauges"], gamma))}
        return data

    @model_validator(mode="after")
    def _aiding(self) -> "Configuration":
        if self.gauges == 0 and self.aided:
            raise ValueError(f"aided={list(self.aided)} needs strain gauges, but gauges=0")
        if self.imus < self.modes:
            raise ValueError(f"imus={self.imus} must be at least Γ={self.modes}")
        bad = [a for a in self.aided if not 1 <= a <= self.modes]
        if bad:
            raise ValueError(f"aided unit deformations {bad} are outside 1..{self.modes}")
        return self

    @property
    def is_benchmark(self) -> bool:
        return self.peripheral == "gyro" and (self.imus, self.tofs, self.gauges) == BENCHMARK_COUNTS

    @property
    def label(self) -> str:
        aided = f" (b{','.join(map(str, self.aided))})" if self.gauges and self.gauges < self.modes else ""
        return f"{self.peripheral} ν_s={self.imus} ν_ρ={self.tofs} ν_ε={self.gauges}{aided}"

    @property
    def slug(self) -> str:
        return f"{self.peripheral}_s{self.imus}_t{self.tofs}_g{self.gauges}"


def benchmark() -> Configuration:
    return Configuration(peripheral="gyro", imus=4, tofs=4, gauges=4)


class StudySettings(_Closed):
    """What the study simulates and which configurations it runs.

    The defaults are the paper's study: dense layout (18 IMU/ToF boards, 12 gauges), paper
    excitation, realistic plant, gyro and acc, benchmark, ν_ε = 0 with ν_ρ = 4…13 and ν_s = 4, 5,
    and ν_ε = 1, 2, 3 (restricted aiding) with ν_ρ = 4…13, on three seeds.
    """

    seeds: tuple[int, ...] = Field((1, 2, 3), min_length=1, description="one simulated recording per seed")
    duration: float = Field(300.0, gt=0, le=3600, description="recording length, s")
    rest: float = Field(60.0, ge=5, description="initial rest phase (bias calibration), s")
    layout: Literal["benchmark", "dense"] = "dense"
    excitation: Literal["paper", "ambient", "decay"] = "paper"
    ideal: bool = Field(False, description="idealised plant: no mismatch, friction, scale/misalignment errors")
    friction_torque: float = Field(0.03, ge=0, description="Coulomb friction of the bearing on the realistic plant, N·m [0.03]: "
                                   "one of the error sources behind the drift without gauges")
    peripherals: tuple[Peripheral, ...] = ("gyro", "acc")
    tofs: tuple[int, ...] = Field(tuple(range(4, 14)), min_length=1, description="ν_ρ swept without and with reduced gauges")
    imus: tuple[int, ...] = Field((4, 5), min_length=1, description="ν_s swept without gauges")
    reduced_gauges: tuple[int, ...] = Field((1, 2, 3), description="ν_ε < Γ with restricted aiding")
    workers: int | None = Field(None, ge=1, le=64, description="worker processes (default: the cores)")
    rig: str | None = Field(None, description="a rig description (.json/.toml) to study instead of the layout: its beam, "
                            "support and sensors; the sweeps keep the counts it has (no ToFs: ν_ρ = 0)")
    modes: int = Field(GAMMA, ge=1, le=5, description="Γ, unit deformations (the paper: 4)")

    @field_validator("seeds", "tofs", "imus", "reduced_gauges", "peripherals")
    @classmethod
    def _unique(cls, value: tuple, info) -> tuple:
        if len(set(value)) != len(value):
            raise ValueError(f"{info.field_name}={list(value)} has duplicates")
        return value

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        bad = [s for s in value if s < 0]
        if bad:
            raise ValueError(f"seeds {bad} must be non-negative")
        return value

    @field_validator("reduced_gauges")
    @classmethod
    def _reduced(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        bad = [g for g in value if not 1 <= g < GAMMA]
        if bad:
            raise ValueError(f"reduced_gauges {bad} must lie in 1..{GAMMA - 1} (ν_ε = {GAMMA} is the benchmark)")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> "StudySettings":
        if "gyro" not in self.peripherals:
            raise ValueError(f"peripherals={list(self.peripherals)} must include 'gyro': the benchmark is the gyro configuration")
        if self.rest >= self.duration:
            raise ValueError(f"rest={self.rest} s must be shorter than duration={self.duration} s")
        have = self.sensor_counts()
        if self.rig is not None:
            if have["imus"] < self.modes:
                raise ValueError(f"the rig {self.rig} has {have['imus']} peripheral IMUs: Γ={self.modes} needs at least {self.modes}")
            return self
        if self.modes != GAMMA:
            raise ValueError(f"modes={self.modes}: the paper's layouts are studied with Γ={GAMMA}; give a rig file for another Γ")
        wanted = {"imus": max(self.imus + (4,)), "tofs": max(self.tofs + (4,)), "gauges": GAMMA}
        for kind, count in wanted.items():
            if count > have[kind]:
                raise ValueError(f"{kind}: {count} requested but the {self.layout} layout has {have[kind]}")
        bad = [t for t in self.tofs if t < 1]
        if bad:
            raise ValueError(f"tofs {bad} must be at least 1")
        bad = [i for i in self.imus if i < GAMMA]
        if bad:
            raise ValueError(f"imus {bad} must be at least Γ={GAMMA}")
        return self

    def sensor_counts(self) -> dict[str, int]:
        """Peripheral IMUs (not D), ToFs and strain gauges of the studied rig."""
        rig = self.rig_description()
        return {
            "imus": len([s for s in rig.sensors_of("imu") if s.name != "D" and (s.position or 0) > 0]),
            "tofs": len(rig.sensors_of("tof")),
            "gauges": len(rig.sensors_of("strain")),
        }

    def rig_description(self):
        """The studied rig: the rig file, or the layout's."""
        if self.rig is not None:
            from estimator import load_rig

            return load_rig(self.rig)
        from ..rig_layouts import default_rig

        return default_rig(self.layout)

    def benchmark(self) -> Configuration:
        """The reference every configuration is scored against (Eq. 21): the paper's gyro 4/4/4, or
        on a rig file gyro with up to 4 IMUs and ToFs it has and Γ gauges (as many as it has)."""
        if self.rig is None:
            return benchmark()
        have = self.sensor_counts()
        return Configuration(peripheral="gyro", imus=max(self.modes, min(4, have["imus"])), tofs=min(4, have["tofs"]),
                             gauges=min(self.modes, have["gauges"]), modes=self.modes)

    @classmethod
    def quick(cls, **overrides) -> "StudySettings":
        """A small study (two seeds of 240 s with 30 s rest, ν_ρ = 4, 5, one reduced-gauge case) for
        tests and a first look: about a minute on two cores. Shorter or single-seed runs are too
        noisy for the one-extra-ToF ordering (a few per cent for acc)."""
        values = dict(seeds=(1, 2), duration=240.0, rest=30.0, tofs=(4, 5), imus=(4,), reduced_gauges=(2,))
        values.update(overrides)
        return cls(**values)

    def configurations(self) -> tuple[Configuration, ...]:
        """The paper's configurations for these settings, benchmark first, without duplicates (on
        a rig file: the sweeps' counts the rig has, ν_ρ = 0 without ToFs)."""
        if self.rig is not None:
            return self._rig_configurations()
        out: list[Configuration] = []
        for peripheral in self.peripherals:
            out.append(Configuration(peripheral=peripheral, imus=4, tofs=4, gauges=4))
            for imus in self.imus:
                for tofs in self.tofs:
                    out.append(Configuration(peripheral=peripheral, imus=imus, tofs=tofs, gauges=0))
            for gauges in self.reduced_gauges:
                for tofs in self.tofs:
                    out.append(Configuration(peripheral=peripheral, imus=4, tofs=tofs, gauges=gauges))
        unique = list(dict.fromkeys(out))
        unique.sort(key=lambda c: not c.is_benchmark)
        return tuple(unique)

    def _rig_configurations(self) -> tuple[Configuration, ...]:
        have = self.sensor_counts()
        gamma = self.modes
        bm = self.benchmark()
        imus = sorted({i for i in self.imus + (bm.imus,) if gamma <= i <= have["imus"]})
        tofs = sorted({t for t in self.tofs if t <= have["tofs"]} | {bm.tofs}) if have["tofs"] else [0]
        # fewer gauges than Γ leave unit deformations that only ToFs observe (the estimator refuses them)
        reduced = {g for g in self.reduced_gauges if g <= have["gauges"]} if have["tofs"] else set()
        gauges = sorted(reduced | {bm.gauges}, reverse=True)
        out = [bm]
        for peripheral in self.peripherals:
            for i in imus:
                for t in tofs:
                    for g in gauges:
                        out.append(Configuration(peripheral=peripheral, imus=i, tofs=t, gauges=g, modes=gamma))
        return tuple(dict.fromkeys(out))
