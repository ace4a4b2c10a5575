"""The virtual rig: plant, excitation and sensors, producing samples in blocks.

Blocks keep memory bounded for long runs and let a live source pace them; ``simulate`` gathers
them into one recording.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from collections.abc import Iterable
from typing import Iterator, cast

import numpy as np
import scipy.signal

from contract import Sensor
from estimator import BucklingError, NodalShapes, RigDescription, assemble_beam, natural_modes, parse_rig

from ..rig_layouts import build_rig
from ._biaxial import bending_of, biaxial_points_motion, gauge_angle, gauge_point, wind_angle, xi_twin
from ._excitation import DistributedLoad, Excitation, OperationalExcitation, make_excitation
from ._kinematics import points_motion
from ._plant import Plant, build_plant, clamped_basis, integrate
from ._settings import SimulationSettings, WindDirection
from ._wind import scaled_wind_load

__all__ = ["SampleBlock", "VirtualRig", "SAMPLE_RATE_HZ", "SLOW_DIVIDER"]

SAMPLE_RATE_HZ = 200.0
SLOW_DIVIDER = 6  # ToF and bearing run at 200 / 6 = 33.33 Hz
TEMPERATURE_DIVIDER = 200  # 1 Hz
_MAX_OMEGA_H = 0.6  # ω·h of the basis's highest mode per Runge–Kutta step


@dataclass
class SampleBlock:
    """Samples of one block. Times are seconds from the start of the run.

    ``measurements`` maps topic → (times (n,), values (n, k)); ``truth`` holds the
    ``/truth/state`` fields at the 200 Hz times.
    """

    times: np.ndarray
    measurements: dict[str, tuple[np.ndarray, np.ndarray]]
    truth: dict[str, np.ndarray]
    delays: dict[str, np.ndarray] = field(default_factory=dict)


class _GaussMarkov:
    """First-order Gauss–Markov processes (one per column), continued across blocks."""

    def __init__(self, rng: np.random.Generator, sigma: np.ndarray, tau: float, dt: float):
        self.rng = rng
        self.sigma = np.asarray(sigma, dtype=float)
        self.a = np.exp(-dt / tau)
        self.state = self.sigma * rng.standard_normal(self.sigma.shape)

    def next(self, n: int) -> np.ndarray:
        drive = self.sigma * np.sqrt(1 - self.a**2) * self.rng.standard_normal((n,) + self.sigma.shape)
        out, _ = scipy.signal.lfilter([1.0], [1.0, -self.a], drive, axis=0, zi=(self.a * self.state)[None, ...])
        self.state = out[-1]
        return out


def _perturbed_rig(nominal: RigDescription, settings: SimulationSettings, rng: np.random.Generator) -> RigDescription:
    """The beam as built: stiffness and board masses a few per cent off the nominal description."""
    data = nominal.model_dump(mode="json")
    plant = settings.plant
    if not settings.ideal:
        stiffness = 1 + plant.stiffness_mismatch * rng.standard_normal()
        if data["beam"].get("youngs_modulus") is not None:
            data["beam"]["youngs_modulus"] *= stiffness
        for station in data["beam"].get("sections") or ():
            if station["shape"] == "table":  # a table's EI is not E times a geometry: scale it alike
                station["bending_stiffness"] *= stiffness
                if bending_of(nominal) == "biaxial" and station.get("bending_stiffness_xi") is not None:
                    station["bending_stiffness_xi"] *= stiffness
        for mass in data["point_masses"]:
            factor = 1 + plant.mass_mismatch * rng.standard_normal()
            mass["mass"] *= factor
            mass["rotary_inertia"] *= factor
    return parse_rig(data)


def default_truth_stations(length_m: float) -> list[float]:
    """Eight stations at L/8, 2L/8, …, L (m): where a rig without ``truth_stations`` gets its truth."""
    return [round(length_m * k / 8, 9) for k in range(1, 9)]


def _described_rig(rig: RigDescription, settings: SimulationSettings) -> RigDescription:
    """A rig file as the recording describes it: its own keys, the simulator's settings under
    ``simulator`` (what was simulated), and truth stations scaled to the beam where it names none
    (the truth's deflection and curvature need stations; readers refuse empty ones)."""
    data = rig.model_dump(mode="json")
    if not data.get("truth_stations"):
        data["truth_stations"] = default_truth_stations(rig.beam.length)
    data["simulator"] = settings.model_dump(mode="json", exclude={"support", "orientation", "length", "layout"})
    return parse_rig(data)


def _with_damage(rig: RigDescription, settings: SimulationSettings) -> RigDescription:
    data = rig.model_dump(mode="json")
    for damage in settings.damage:
        if damage.kind == "mass":
            data["point_masses"].append(damage.as_point_mass().model_dump(mode="json"))
        else:
            data["beam"]["stiffness_segments"] = list(data["beam"].get("stiffness_segments", [])) + [
                damage.as_segment().model_dump(mode="json")
            ]
    return parse_rig(data)


def _plant_model(rig: RigDescription, extra_nodes: list[float], what: str):
    try:
        return assemble_beam(rig, extra_nodes=extra_nodes)
    except BucklingError as exc:
        raise BucklingError(f"{what}: {exc}", critical_load_factor=exc.critical_load_factor,
                            bare_critical_length=exc.bare_critical_length) from None


class VirtualRig:
    """Simulates the rig of ``settings``; ``nominal_rig`` is what the recording's rig.json says."""

    def __init__(self, settings: SimulationSettings, nominal_rig: RigDescription | None = None):
        self.settings = settings
        self.dt = 1.0 / SAMPLE_RATE_HZ
        self.n_samples = int(round(settings.duration * SAMPLE_RATE_HZ))
        seeds = np.random.SeedSequence(settings.seed).spawn(4)
        # The structure as built (E and masses off the nominal) may come from another seed than the
        # run: recordings of one structure on different days share ``plant_seed``.
        plant_seeds = seeds if settings.plant_seed is None else np.random.SeedSequence(settings.plant_seed).spawn(4)
        self._rng_plant = np.random.default_rng(plant_seeds[0])
        self._rng_excitation = np.random.default_rng(seeds[1])
        self._rng_sensors = np.random.default_rng(seeds[2])
        self._rng_ambient = np.random.default_rng(seeds[3])
        #: A rig given as a description (``shm simulate --rig``) rather than the built-in sheet's layout:
        #: its wind load and truth stations are scaled to the beam.
        self.custom_rig = nominal_rig is not None
        self.nominal_rig = _described_rig(nominal_rig, settings) if nominal_rig is not None else build_rig(
            settings.layout, length=settings.length, support=settings.support, orientation=settings.orientation,
            simulator=settings.model_dump(mode="json"),
        )
        #: No bearing sensor: the support is fixed to the ground (d ≡ 0, the contract's fixed foundation).
        self.fixed_support = self.nominal_rig.support_fixed_to_ground
        #: "planar" (ζ only, as the contract's default) or "biaxial" (ζ and ξ, each its own plant)
        self.bending = bending_of(self.nominal_rig)
        self.biaxial = self.bending == "biaxial"
        if self.biaxial:
            self.wind_direction: WindDirection | None = settings.wind_direction or WindDirection()
        elif settings.wind_direction is not None:
            raise ValueError(f"wind_direction={settings.wind_direction.model_dump()} acts on a biaxial beam "
                             "(beam.bending = 'biaxial'); this beam bends in ζ only")
        else:
            self.wind_direction = None
        for damage in settings.damage:
            for x in damage.nodes:
                if not 0 <= x <= self.nominal_rig.beam.length:
                    raise ValueError(f"damage position {x} m is outside the beam [0, {self.nominal_rig.beam.length}]")
        # The described rig first: a standing beam that buckles is refused with the FE's figures.
        nominal_model = assemble_beam(self.nominal_rig)
        self._build_plants()
        nominal_freqs = natural_modes(nominal_model, 6).frequencies_hz
        op = settings.operational
        self.wind_correlation_m, self.wind_load_rms = self._wind_load()
        self.excitation: Excitation = make_excitation(
            settings.excitation, settings.duration, self._rng_excitation,
            eigenfrequencies_hz=nominal_freqs, rest_s=settings.rest, ambient_force_std=settings.plant.ambient_force,
            # A fixed support does not move: the operational excitation is then the wind load alone.
            # the bands are (low, high) pairs (OperationalSettings)
            operational=OperationalExcitation(0.0 if self.fixed_support else op.support_rms,
                                              cast(tuple[float, float], tuple(op.support_band)), self.wind_load_rms,
                                              self.wind_correlation_m, cast(tuple[float, float], tuple(op.load_band)), op.ramp),
        )
        self._ambient_loads()
        self._sensor_setup()
        self._state = (np.zeros(self.plants[0].size), np.zeros(self.plants[0].size))
        self._state_xi = None if not self.biaxial else (np.zeros(self.plants_xi[0].size), np.zeros(self.plants_xi[0].size))
        self._next_sample = 0

    def _build_plants(self) -> None:
        """The structure as built (and damaged): its plants in one modal basis, the RK4 substeps."""
        settings = self.settings
        self.plant_rig = _perturbed_rig(self.nominal_rig, settings, self._rng_plant)
        damage_nodes = [x for d in settings.damage for x in d.nodes]
        healthy_model = _plant_model(self.plant_rig, damage_nodes, "the simulated plant (E and board masses drawn off the nominal)")
        models = [healthy_model]
        if settings.damage:
            self.damaged_rig: RigDescription | None = _with_damage(self.plant_rig, settings)
            models.append(_plant_model(self.damaged_rig, damage_nodes, "the damaged plant"))
        else:
            self.damaged_rig = None
        _refuse_buckling_over_the_temperature_range(settings, self.plant_rig, models)
        basis = clamped_basis(models, settings.plant.modes)
        self.plants_xi: list[Plant] = []
        self.basis_xi: NodalShapes | None = None
        if self.biaxial:
            self._build_xi_plants(damage_nodes, healthy_model)
        friction = 0.0 if settings.ideal else settings.plant.friction_torque
        self._critical_load_factor = float(healthy_model.critical_load_factor)
        self.plants: list[Plant] = [
            build_plant(m, basis, damping_ratios=np.array(settings.plant.damping_ratios), friction_torque=friction)
            for m in models
        ]
        self.basis = basis
        # RK4 keeps the highest mode accurate (frequency error (ωh)⁴/120 ≈ 0.1 %) and stable at ω·h ≤ 0.6.
        omega_max = 2 * np.pi * max(float(p.linear_frequencies_hz.max()) for p in (*self.plants, *self.plants_xi))
        self.substeps = max(settings.plant.substeps, int(np.ceil(omega_max * self.dt / _MAX_OMEGA_H)))
        self.damage_sample = (
            None if not settings.damage else int(round((settings.damage_at or 0.0) * SAMPLE_RATE_HZ))
        )

    def _build_xi_plants(self, damage_nodes: list[float], healthy_zeta) -> None:
        """The ξ plane's own plants: the FE beam of the ξ twin (``_biaxial.xi_twin``) of the plant as
        built (and damaged), on the ζ plane's mesh, clamped modes of its own."""
        settings = self.settings
        twin = xi_twin(self.plant_rig)
        models = [_plant_model(twin, damage_nodes, "the ξ plane of the simulated plant")]
        if self.damaged_rig is not None:
            models.append(_plant_model(xi_twin(self.damaged_rig), damage_nodes, "the ξ plane of the damaged plant"))
        if not np.array_equal(models[0].nodes, healthy_zeta.nodes):
            raise AssertionError("the ξ plane's FE mesh must be the ζ plane's (the kinematics add both planes' fields)")
        _refuse_buckling_over_the_temperature_range(settings, twin, models)
        self.xi_rig = xi_twin(self.nominal_rig)
        self.basis_xi = basis_xi = clamped_basis(models, settings.plant.modes)
        self.plants_xi = [build_plant(m, basis_xi, damping_ratios=np.array(settings.plant.damping_ratios))
                          for m in models]

    def _ambient_loads(self) -> None:
        settings, basis, op = self.settings, self.basis, self.settings.operational
        # Ambient loads act on the lateral DOF of every node beyond D (below it hanging, above it standing).
        n_nodes = len(basis.nodes)
        rigid = np.zeros((2 * n_nodes,))
        rigid[0::2] = basis.nodes
        rigid[1::2] = 1.0
        T = np.column_stack([rigid, basis.dofs])
        self._load_map = T[2::2].T  # (n, nodes-1): generalized force per nodal load
        if self.basis_xi is not None:
            T_xi = np.column_stack([rigid, self.basis_xi.dofs])  # θ's column stays zero: the clamp holds it
            self._load_map_xi: np.ndarray = T_xi[2::2].T
        self._distributed_load = None
        # The wind load: the operational excitation's, and the ambient one's for a rig file (the
        # built-in sheet's ambient excitation keeps its random nodal forces).
        wind = self.excitation.operational is not None or (self.custom_rig and settings.excitation == "ambient")
        if wind:
            self._distributed_load = DistributedLoad(
                self._rng_ambient, np.asarray(basis.nodes[1:], dtype=float), rms_n_per_m=self.wind_load_rms,
                correlation_m=self.wind_correlation_m, band_hz=cast(tuple[float, float], tuple(op.load_band)), sample_rate_hz=SAMPLE_RATE_HZ,
                start_s=self.excitation.rest_s, ramp_s=op.ramp,
                storm=None if settings.wind_storm is None else (settings.wind_storm.start_s, settings.wind_storm.end_s,
                                                                settings.wind_storm.peak))

    def _wind_load(self) -> tuple[float, float]:
        """(correlation length m, RMS N/m) of the wind load: as set, the operational settings' for the
        built-in sheet, scaled to the structure for a rig file (``_wind.scaled_wind_load``)."""
        s, op = self.settings, self.settings.operational
        if s.wind_correlation is not None:
            correlation = s.wind_correlation
        elif self.custom_rig:
            correlation = max(1.0, 0.25 * self.nominal_rig.beam.length)
        else:
            correlation = op.load_correlation
        if s.wind_load_rms is not None:
            return correlation, s.wind_load_rms
        if self.custom_rig:
            return correlation, scaled_wind_load(self.nominal_rig, correlation, s.wind_base_strain)
        return correlation, op.load_rms

    def support_motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """d, ḋ, d̈ of the support at ``t`` (s): the excitation's bearing motion, or zero for a support
        fixed to the ground."""
        if self.fixed_support:
            t = np.asarray(t, dtype=float)
            return np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
        return self.excitation.bearing(t)

    # -- sensors -------------------------------------------------------------------------
    def _sensor_setup(self) -> None:
        e = self.settings.errors
        ideal = self.settings.ideal
        rng = self._rng_sensors
        rig = self.nominal_rig
        self.imus = rig.sensors_of("imu")
        self.tofs = rig.sensors_of("tof")
        self.gauges = rig.sensors_of("strain")
        n_imu = len(self.imus)
        tau = e.bias_correlation_time
        self._accel_bias = e.accel_bias * rng.standard_normal((n_imu, 3))
        self._gyro_bias = e.gyro_bias * rng.standard_normal((n_imu, 3))
        self._accel_wander = _GaussMarkov(rng, np.full((n_imu, 3), e.accel_bias_instability), tau, self.dt)
        self._gyro_wander = _GaussMarkov(rng, np.full((n_imu, 3), e.gyro_bias_instability), tau, self.dt)
        scale = 0.0 if ideal else 1.0
        self._accel_scale = 1 + scale * e.accel_scale_factor * rng.standard_normal((n_imu, 3))
        self._gyro_scale = 1 + scale * e.gyro_scale_factor * rng.standard_normal((n_imu, 3))
        self._misalignment = scale * e.misalignment * rng.standard_normal(n_imu)
        self._tof_offset = scale * e.tof_offset * rng.standard_normal(len(self.tofs))
        self._strain_offset = scale * e.strain_offset * rng.standard_normal(len(self.gauges))
        # c(η) of each gauge: half the sheet's thickness, half a tube's outer diameter, a table's value
        self._fibre_distance = np.array([rig.beam.fibre_distance(g.position) for g in self.gauges], dtype=float)
        # where each gauge sits around the section (angle_deg, from +ζ towards +ξ): (ζp, ξp) on the outline
        index = {id(s): i for i, s in enumerate(rig.sensors)}
        angles = [gauge_angle(g, index[id(g)], self.biaxial) for g in self.gauges]
        twin = xi_twin(rig) if self.biaxial else None
        self._gauge_points = np.array([gauge_point(rig, twin, x, a) for x, a in zip(_positions(self.gauges), angles)],
                                      dtype=float).reshape(-1, 2)
        if not self.biaxial:
            self._fibre_distance = self._gauge_points[:, 0]  # +c on the +ζ face (as before), −c at 180°

    def truth_metadata(self) -> dict[str, str]:
        """The ``truth`` metadata record: the plant's exact modal figures and what was simulated."""
        return _truth_metadata(self)

    def temperature(self, t: np.ndarray) -> np.ndarray:
        s = self.settings
        return s.temperature_mean + 0.5 * s.temperature_swing * np.sin(2 * np.pi * t / s.duration)

    # -- simulation ----------------------------------------------------------------------
    def _integrate_range(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """States y, ẏ, ÿ of the ζ plant over samples [k0, k1); a biaxial rig's ξ plant integrates
        alongside (its states in ``self._xi_range``)."""
        substeps = self.substeps
        n = k1 - k0
        fine_t = (k0 + np.arange(2 * substeps * n + 1) / (2 * substeps)) * self.dt
        _, _, fine_acc = self.support_motion(fine_t)
        t = (k0 + np.arange(n)) * self.dt
        temperature = self.temperature(t)
        plant = self.plants[1] if (self.damage_sample is not None and k0 >= self.damage_sample) else self.plants[0]
        force_xi = None
        if self._distributed_load is not None and self.biaxial:
            # one along-wind load, split by the wind's veering direction between the planes
            loads = self._distributed_load.nodal_loads(t)
            direction = self.wind_direction
            assert direction is not None, "a biaxial rig has its wind direction (__init__)"
            psi = wind_angle(t, direction.mean_deg, direction.veer_deg, direction.period_s)[:, None]
            force = (loads * np.cos(psi)) @ self._load_map.T
            force_xi = (loads * np.sin(psi)) @ self._load_map_xi.T
        elif self._distributed_load is not None:
            force = self._distributed_load.nodal_loads(t) @ self._load_map.T
        elif self.excitation.ambient_force_std > 0:
            loads = self.excitation.ambient_force_std * self._rng_ambient.standard_normal((n, self._load_map.shape[1]))
            loads[t < self.excitation.rest_s] = 0.0
            force = loads @ self._load_map.T
        else:
            force = np.zeros((n, plant.size))
        if self.fixed_support and self.settings.excitation in ("paper", "decay"):
            # A fixed support cannot move: the paper's moves and sine bursts and the decay's plucks act
            # as the load they would put on the beam, −μ d̈ along it (its modal participation is the
            # moving support's), while D stays put.
            _, _, schedule = self.excitation.bearing(t)
            force = force - np.outer(schedule, np.concatenate([[plant.first_moment], plant.modal_first_moment]))
        y, yd, ydd, y_end, yd_end = integrate(
            plant, self._state[0], self._state[1], fine_acc, temperature, force,
            sample_period=self.dt, substeps=substeps,
        )
        self._state = (y_end, yd_end)
        if self.biaxial:
            plant_xi = self.plants_xi[1] if len(self.plants) > 1 and plant is self.plants[1] else self.plants_xi[0]
            if force_xi is None:
                force_xi = np.zeros((n, plant_xi.size))
            # the support moves D along ζ only: no bearing acceleration acts on the ξ plane
            state_xi = self._state_xi
            assert state_xi is not None, "a biaxial rig has its ξ state (__init__)"
            r, rd, rdd, r_end, rd_end = integrate(
                plant_xi, state_xi[0], state_xi[1], np.zeros_like(fine_acc), temperature, force_xi,
                sample_period=self.dt, substeps=substeps)
            self._state_xi = (r_end, rd_end)
            self._xi_range = (r, rd, rdd)
        return y, yd, ydd

    def blocks(self, block_seconds: float = 60.0) -> Iterator[SampleBlock]:
        """Yield consecutive blocks until the run's duration is reached."""
        if block_seconds <= 0:
            raise ValueError(f"{block_seconds=} must be positive")
        step = max(SLOW_DIVIDER, int(round(block_seconds * SAMPLE_RATE_HZ)) // SLOW_DIVIDER * SLOW_DIVIDER)
        while self._next_sample < self.n_samples:
            k0 = self._next_sample
            k1 = min(self.n_samples, k0 + step)
            if self.damage_sample is not None and k0 < self.damage_sample < k1:
                k1 = self.damage_sample
            yield self._block(k0, k1)
            self._next_sample = k1

    def _block(self, k0: int, k1: int) -> SampleBlock:
        y, yd, ydd = self._integrate_range(k0, k1)
        n = k1 - k0
        index = k0 + np.arange(n)
        t = index * self.dt
        d, _, d_acc = self.support_motion(t)
        meas: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        delays: dict[str, np.ndarray] = {}

        if self.biaxial:
            r, rd, rdd = self._xi_range
            _biaxial_fast_sensors(self, t, (y, yd, ydd), (r, rd, rdd), d, d_acc, meas, delays)
            _slow_sensors(self, index, t, y, yd, ydd, d, d_acc, meas, delays, xi=(r, rd, rdd))
            truth = self._truth(y, d)
            truth.update(self._truth_xi(r))
            return SampleBlock(times=t, measurements=meas, truth=truth, delays=delays)
        _fast_sensors(self, t, y, yd, ydd, d, d_acc, meas, delays)
        _slow_sensors(self, index, t, y, yd, ydd, d, d_acc, meas, delays)
        return SampleBlock(times=t, measurements=meas, truth=self._truth(y, d), delays=delays)

    def _truth_xi(self, r) -> dict[str, np.ndarray]:
        """The ξ plane's truth: ``e_xi``, ``deflection_xi``, ``curvature_xi`` (body frame, at the truth stations)."""
        return _truth_xi_fields(self, r)

    def _truth(self, y, d) -> dict[str, np.ndarray]:
        rig = self.nominal_rig
        n = len(d)
        stations = np.asarray(rig.truth_stations, dtype=float)
        deflection = self.basis.evaluate(stations, 0)
        curvature = self.basis.evaluate(stations, 2)
        q = y[:, 1:]
        return {
            "d": d,
            "h": np.zeros(n),
            "phi": y[:, 0],
            "e": q @ self.basis.evaluate(rig.beam.length, 0),
            "deflection": q @ deflection.T,
            "curvature": q @ curvature.T,
        }


def _positions(sensors: Iterable[Sensor]) -> list[float]:
    """The arc lengths of sensors on the beam (IMUs, gauges, ToFs: the rig description places each)."""
    out = []
    for s in sensors:
        assert s.position is not None, f"{s.name} sits on the beam"
        out.append(s.position)
    return out


def _fast_sensors(self: VirtualRig, t, y, yd, ydd, d, d_acc, meas: dict, delays: dict) -> None:
    """The IMUs and strain gauges at the sample rate."""
    n = len(t)
    e = self.settings.errors
    rng = self._rng_sensors
    accel_wander = self._accel_wander.next(n)
    gyro_wander = self._gyro_wander.next(n)
    # every sensor's kinematics in one pass (fields (n, sensors)), its own column taken below
    fast = points_motion(self.basis, _positions((*self.imus, *self.gauges)), y, yd, ydd, d, d_acc,
                         self.plants[0].gravity)
    for i, imu in enumerate(self.imus):
        fx, fy = fast.specific_force_x[:, i], fast.specific_force_y[:, i]
        mis = self._misalignment[i]
        cm, sm = np.cos(mis), np.sin(mis)
        accel = np.column_stack([cm * fx + sm * fy, -sm * fx + cm * fy, np.zeros(n)])
        gyro = np.column_stack([np.zeros(n), np.zeros(n), fast.rate[:, i]])
        accel = accel * self._accel_scale[i] + self._accel_bias[i] + accel_wander[:, i] + e.accel_noise * rng.standard_normal((n, 3))
        gyro = gyro * self._gyro_scale[i] + self._gyro_bias[i] + gyro_wander[:, i] + e.gyro_noise * rng.standard_normal((n, 3))
        meas[imu.topic] = (t, np.hstack([accel, gyro]))
        delays[imu.topic] = e.imu_delay + e.delay_jitter * rng.random(n)

    for i, gauge in enumerate(self.gauges):
        curvature = fast.curvature[:, len(self.imus) + i]
        strain = -self._fibre_distance[i] * curvature + self._strain_offset[i] + e.strain_noise * rng.standard_normal(n)
        meas[gauge.topic] = (t, strain[:, None])
        delays[gauge.topic] = e.strain_delay + e.delay_jitter * rng.random(n)


def _biaxial_fast_sensors(self: VirtualRig, t, zeta, xi, d, d_acc, meas: dict, delays: dict) -> None:
    """The IMUs and gauges of a biaxial beam: accel z and gyro y carry the ξ motion, a gauge at
    (ζp, ξp) reads −(ζp κζ + ξp κξ); the same error draws, in the same order, as the planar rig."""
    n = len(t)
    e = self.settings.errors
    rng = self._rng_sensors
    accel_wander = self._accel_wander.next(n)
    gyro_wander = self._gyro_wander.next(n)
    assert self.basis_xi is not None, "a biaxial rig has its ξ basis (_build_xi_plants)"
    fast = biaxial_points_motion(self.basis, self.basis_xi, _positions((*self.imus, *self.gauges)),
                                 tuple(a[:, 1:] for a in zeta), tuple(a[:, 1:] for a in xi),
                                 d, d_acc, self.plants[0].gravity)
    for i, imu in enumerate(self.imus):
        fx, fy, fz = (fast.specific_force[k][:, i] for k in range(3))
        mis = self._misalignment[i]
        cm, sm = np.cos(mis), np.sin(mis)
        accel = np.column_stack([cm * fx + sm * fy, -sm * fx + cm * fy, fz])
        gyro = np.column_stack([np.zeros(n), fast.rate[1][:, i], fast.rate[2][:, i]])  # x: twist, noise only
        accel = accel * self._accel_scale[i] + self._accel_bias[i] + accel_wander[:, i] + e.accel_noise * rng.standard_normal((n, 3))
        gyro = gyro * self._gyro_scale[i] + self._gyro_bias[i] + gyro_wander[:, i] + e.gyro_noise * rng.standard_normal((n, 3))
        meas[imu.topic] = (t, np.hstack([accel, gyro]))
        delays[imu.topic] = e.imu_delay + e.delay_jitter * rng.random(n)
    for i, gauge in enumerate(self.gauges):
        j = len(self.imus) + i
        zeta_p, xi_p = self._gauge_points[i]
        strain = -(zeta_p * fast.curvature[:, j] + xi_p * fast.curvature_xi[:, j])
        strain = strain + self._strain_offset[i] + e.strain_noise * rng.standard_normal(n)
        meas[gauge.topic] = (t, strain[:, None])
        delays[gauge.topic] = e.strain_delay + e.delay_jitter * rng.random(n)

def _slow_sensors(self: VirtualRig, index, t, y, yd, ydd, d, d_acc, meas: dict, delays: dict, xi=None) -> None:
    """The ToFs, the bearing sensor (every ``SLOW_DIVIDER``-th sample) and the temperature."""
    n = len(t)
    rig = self.nominal_rig
    e = self.settings.errors
    rng = self._rng_sensors
    plant_g = self.plants[0].gravity
    slow = index % SLOW_DIVIDER == 0
    t_slow = t[slow]
    y_slow, yd_slow, ydd_slow = y[slow], yd[slow], ydd[slow]
    d_slow, d_acc_slow = d[slow], d_acc[slow]
    if e.tof_time_offset > 0:
        # Off-grid samples: states by cubic Hermite interpolation to the next sample (O(dt⁴)).
        k = np.nonzero(slow)[0]
        k1 = np.minimum(k + 1, n - 1)
        s = np.where(k1 > k, e.tof_time_offset / self.dt, 0.0)[:, None]
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        y_slow = h00 * y[k] + h10 * self.dt * yd[k] + h01 * y[k1] + h11 * self.dt * yd[k1]
        t_slow = t_slow + s[:, 0] * self.dt
        d_slow, _, d_acc_slow = self.support_motion(t_slow)
    theta_slow = y_slow[:, 0]
    slow_motion = points_motion(self.basis, _positions(self.tofs), y_slow, yd_slow, ydd_slow, d_slow,
                                d_acc_slow, plant_g) if self.tofs and xi is None else None
    biaxial_motion = None
    if self.tofs and xi is not None:
        if e.tof_time_offset > 0:
            raise ValueError("errors.tof_time_offset is not simulated on a biaxial beam (its ToFs sample on the grid)")
        assert self.basis_xi is not None, "a biaxial rig has its ξ basis (_build_xi_plants)"
        biaxial_motion = biaxial_points_motion(
            self.basis, self.basis_xi, _positions(self.tofs), (y_slow[:, 1:], yd_slow[:, 1:], ydd_slow[:, 1:]),
            tuple(a[slow][:, 1:] for a in xi), d_slow, d_acc_slow, plant_g)
    for i, tof in enumerate(self.tofs):
        if biaxial_motion is not None:
            # along the sensor's +y axis (turned by both planes' slopes) to the plane ζ = reflector
            zeta = biaxial_motion.inertial[1][:, i]
            distance = (rig.reflector_distance - zeta) / biaxial_motion.y_axis[1][:, i]
        else:
            assert slow_motion is not None, "a planar rig's ToFs have their motion (above)"
            zeta, slope_angle = slow_motion.inertial_zeta[:, i], slow_motion.slope_angle[:, i]
            distance = (rig.reflector_distance - zeta) / np.cos(theta_slow + slope_angle)
        distance = distance + self._tof_offset[i] + e.tof_noise * rng.standard_normal(distance.size)
        if e.tof_resolution > 0:
            distance = np.round(distance / e.tof_resolution) * e.tof_resolution
        meas[tof.topic] = (t_slow, distance[:, None])
        delays[tof.topic] = e.tof_delay + e.delay_jitter * rng.random(t_slow.size)
    if rig.sensors_of("bearing"):
        bearing = d_slow + e.bearing_noise * rng.standard_normal(t_slow.size)
        meas["/bearing/displacement"] = (t_slow, bearing[:, None])
        delays["/bearing/displacement"] = e.tof_delay + e.delay_jitter * rng.random(t_slow.size)
    if rig.sensors_of("temperature"):
        every = index % TEMPERATURE_DIVIDER == 0
        temp = self.temperature(t[every]) + e.temperature_noise * rng.standard_normal(int(every.sum()))
        meas["/env/temperature"] = (t[every], temp[:, None])
        delays["/env/temperature"] = np.full(int(every.sum()), 0.01)


def _truth_xi_fields(self: VirtualRig, r: np.ndarray) -> dict[str, np.ndarray]:
    rig = self.nominal_rig
    stations = np.asarray(rig.truth_stations, dtype=float)
    q = r[:, 1:]
    basis_xi = self.basis_xi
    assert basis_xi is not None, "asked of a biaxial rig, which has its ξ basis (_build_xi_plants)"
    return {
        "e_xi": q @ basis_xi.evaluate(rig.beam.length, 0),
        "deflection_xi": q @ basis_xi.evaluate(stations, 0).T,
        "curvature_xi": q @ basis_xi.evaluate(stations, 2).T,
    }


def _truth_metadata(self: VirtualRig) -> dict[str, str]:
    """The ``truth`` metadata record: the plant's exact modal figures and what was simulated."""
    healthy = self.plants[0]
    meta = {
        "eigenfrequencies_hz": json.dumps(healthy.linear_frequencies_hz[:8].round(6).tolist()),
        "modal_damping_ratios": json.dumps(healthy.modal_damping[:8].round(6).tolist()),
        "reference_temperature_c": json.dumps(self.plant_rig.beam.reference_temperature),
        "excitation": self.settings.excitation,
        "rest_s": json.dumps(self.excitation.rest_s),
        "still_phases_s": json.dumps([[round(a, 3), round(b, 3)] for a, b in self.excitation.still_phases]),
        "ideal": json.dumps(self.settings.ideal),
        "friction_torque_nm": json.dumps(healthy.friction_torque),
        "support": self.plant_rig.support,
        "orientation": self.plant_rig.orientation,
        "critical_load_factor": json.dumps(
            None if not np.isfinite(self._critical_load_factor) else round(self._critical_load_factor, 6)),
        "plant_rig": self.plant_rig.model_dump_json(),
    }
    if self.settings.excitation == "operational":
        meta["operational"] = self.settings.operational.model_dump_json()
    meta["fixed_support"] = json.dumps(self.fixed_support)
    if self._distributed_load is not None:
        meta["wind_load"] = json.dumps({"rms_n_per_m": round(self.wind_load_rms, 9),
                                        "correlation_m": round(self.wind_correlation_m, 6)})
        if self.settings.wind_storm is not None:
            meta["wind_storm"] = self.settings.wind_storm.model_dump_json()
    if self.damaged_rig is not None:
        meta["eigenfrequencies_after_damage_hz"] = json.dumps(self.plants[1].linear_frequencies_hz[:8].round(6).tolist())
        meta["damage_time_s"] = json.dumps((self.damage_sample or 0) / SAMPLE_RATE_HZ)
        meta["damage"] = json.dumps([d.model_dump(mode="json", exclude_none=True) for d in self.settings.damage])
    if self.biaxial:
        meta["bending"] = "biaxial"
        meta["eigenfrequencies_xi_hz"] = json.dumps(self.plants_xi[0].linear_frequencies_hz[:8].round(6).tolist())
        meta["modal_damping_ratios_xi"] = json.dumps(self.plants_xi[0].modal_damping[:8].round(6).tolist())
        if self.damaged_rig is not None:
            meta["eigenfrequencies_after_damage_xi_hz"] = json.dumps(
                self.plants_xi[1].linear_frequencies_hz[:8].round(6).tolist())
        if self._distributed_load is not None:
            assert self.wind_direction is not None, "a biaxial rig has its wind direction (__init__)"
            meta["wind_direction"] = self.wind_direction.model_dump_json()
    return meta


def _refuse_buckling_over_the_temperature_range(s: SimulationSettings, plant_rig: RigDescription, models: list) -> None:
    """The critical load scales with E: a mast that stands at the reference temperature may
    buckle when the swing softens it (the linear plant would then diverge)."""
    beam = plant_rig.beam
    coldest, warmest = s.temperature_mean - 0.5 * s.temperature_swing, s.temperature_mean + 0.5 * s.temperature_swing
    softest = min(1 + beam.youngs_modulus_temperature_coefficient * (t - beam.reference_temperature) for t in (coldest, warmest))
    for model in models:
        factor = model.critical_load_factor * softest
        if factor <= 1.0:
            raise BucklingError(
                f"the standing beam buckles when the temperature swing softens it: its critical load factor "
                f"falls to λ_cr = {factor:.4g} between {coldest:g} and {warmest:g} °C",
                critical_load_factor=factor, bare_critical_length=float("nan"))
