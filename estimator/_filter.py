"""The IMMS filter: model set-up from rig.json, rest-phase calibration, and the filter class.

Inputs are plain arrays (``Measurements``); readers and services convert recordings into them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from contract import BEARING_TOPIC, ModeMap, RigDescription, StateLayout

from ._beam import _axial_gravity, assemble_beam
from ._imms import (
    EVENT_BEARING,
    EVENT_IMU_D,
    EVENT_IMU_PERIPHERAL,
    EVENT_STRAIN,
    EVENT_TOF,
    KIND_ACC,
    KIND_GYRO,
    AidingCounters,
    EventArrays,
    FilterOutputs,
    FilterParams,
    FilterState,
    ModelArrays,
    run_events,
    tip_variance,
)
from ._observability import UnobservableRig, biaxial_observability_problem, observability_problem
from ._selection import SensorSelection, select_sensors
from ._unit_deformations import UnitDeformations, unit_deformations, with_residual_modes

__all__ = [
    "EstimateResult",
    "Events",
    "FilterConfig",
    "FilterOutput",
    "ImmsFilter",
    "ImmsModel",
    "Measurements",
    "RestCalibration",
    "SensorSeries",
    "build_events",
    "build_model",
    "calibrate_at_rest",
    "model_arrays",
    "support_position_problem",
]


class FilterConfig(BaseModel):
    """Tuning of the EKF. Noise levels of the sensors are learnt from the rest phase; these are
    the floors and the model-error terms that the data cannot tell."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    gate: float = Field(30.0, gt=0, description="innovation gate on the squared Mahalanobis distance (≈5.5σ)")
    stale_after_s: float = Field(0.05, gt=0, description="a peripheral IMU silent this long leaves the solution, s")
    max_step_s: float = Field(0.005, gt=0, description="longest single prediction step, s")
    rest_max_s: float = Field(60.0, gt=0, description="longest rest phase used for calibration, s")
    rest_min_s: float = Field(2.0, gt=0, description="shortest rest phase accepted for calibration, s")
    accel_noise_floor: float = Field(0.005, ge=0, description="m/s²")
    gyro_noise_floor: float = Field(3e-4, ge=0, description="rad/s")
    q_b: float = Field(1e-8, ge=0, description="model error of ḃ (truncated modes), 1/s")
    q_v: float | None = Field(
        None, ge=0,
        description="model error of b̈ (accelerometers) beyond their noise (which the input noise already "
        "carries), 1/s³; None: 1e-6 with strain gauges, 1e-3 without (nothing then corrects b̈ at 200 Hz, and "
        "with 1e-4 the NEES of φ shows the filter overconfident by ~2). With gauges 1e-4 was 20 times the "
        "accelerometers' own b̈ noise and let b follow the gauges, which misread the combimode (then the pair's "
        "singular vector)",
    )
    q_beta: float = Field(1e-11, ge=0, description="random walk of the gyro bias at D, rad²/s³")
    q_beta_peripheral: float = Field(
        5e-11, ge=0, description="random walk of the peripheral gyro biases, rad²/s³ (≈ 2σ²/τ of a 1e-4 rad/s, 300 s wander)"
    )
    q_rigid: float = Field(1e-4, ge=0, description="model error of the bearing's acceleration, m²/s³")
    q_null: float = Field(1e-2, ge=0, description="random walk of unit deformations no sensor sees, 1/s")
    q_residual: float = Field(
        1e-4, ge=0, description="model error of the residual modes' dynamics: random walk of their rates, 1/s³")
    residual_damping: float = Field(
        0.01, ge=0, lt=1, description="damping ratio assumed for the residual modes (the FE model has none), 1")
    combimode_error_scale: float = Field(
        1.0, ge=0, description="scale of the gauges' shared model error from the combimode's shape "
        "(ImmsModel.combimode_strain_errors); 0 drops it")
    tof_model_std: float = Field(0.002, ge=0, description="ToF model error (higher modes, beam surface), m")
    strain_model_std: float = Field(
        1.5e-6, ge=0, description="strain model error (higher modes, FE against plant), m/m; the combimode's share "
        "is modelled on its own (combimode_error_scale)")
    bearing_std: float = Field(1e-4, gt=0, description="floor of the bearing sensor's noise, m")
    fixed_support_std: float = Field(
        1e-4, gt=0, description="a support fixed to the ground (no bearing sensor): the d = 0 pseudo-measurement at "
        "every sample of the IMU at D, m (a foundation moves by micrometres; this bounds what the D accelerometer's "
        "bias wander would integrate to)")
    pseudo_h_std: float = Field(1e-4, gt=0, description="h = 0 pseudo-measurement, m")
    pseudo_h_rate_std: float = Field(1e-3, gt=0, description="ḣ = 0 pseudo-measurement, m/s")
    initial_std: float = Field(1e-3, gt=0, description="initial standard deviation of every state (at rest)")


@dataclass(frozen=True)
class SensorSeries:
    """Samples of one sensor: ``times`` (n,) in s (increasing), ``values`` (n, k)."""

    times: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if t.ndim != 1 or v.shape[0] != t.shape[0]:
            raise ValueError(f"times {t.shape} and values {v.shape} do not match")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", v)

    def window(self, start: float, end: float) -> "SensorSeries":
        lo, hi = np.searchsorted(self.times, [start, end])
        return SensorSeries(self.times[lo:hi], self.values[lo:hi])


@dataclass(frozen=True)
class Measurements:
    """Measurements of one recording, times in s from a common origin.

    imu values are [f_x, f_y, ω_z] (sensor frame, m/s² and rad/s), for a biaxial beam
    [f_x, f_y, ω_z, f_z, ω_y] (``contract.IMU_BIAXIAL_COLUMNS``); tof, strain and bearing values
    are the distance (m), strain (m/m) and bearing displacement (m).
    """

    imu: Mapping[str, SensorSeries]
    tof: Mapping[str, SensorSeries] = field(default_factory=dict)
    strain: Mapping[str, SensorSeries] = field(default_factory=dict)
    bearing: SensorSeries | None = None

    @property
    def start(self) -> float:
        return min(s.times[0] for s in self.imu.values() if s.times.size)

    @property
    def end(self) -> float:
        return max(s.times[-1] for s in self.imu.values() if s.times.size)


@dataclass(frozen=True)
class ImmsModel:
    """The estimator's model of one configuration, built from rig.json and a sensor selection.

    ``units`` are the Γ unit deformations it reports (b, the mode labels); ``modal_units`` the
    Γ + R modal shapes the filter carries, the unit deformations followed by R residual modes
    (None: R = 0), whose participation p of the support's lateral acceleration (r̈ + … + ω² r =
    −p a_D) is ``residual_participation``. Deflection, tip deflection and curvature are read from
    all of them.

    A biaxial beam (``beam.bending = "biaxial"``) adds its ξ plane: ``units_xi`` (Γξ unit
    deformations of the ξ FE model), ``modal_units_xi`` (with its Rξ residual modes) and
    ``residual_participation_xi``; ``gauge_angle`` are the selected gauges' places around the
    section (degrees from +ζ towards +ξ). A planar model has ``units_xi = None``.
    """

    rig: RigDescription
    units: UnitDeformations
    selection: SensorSelection
    imu_eta: np.ndarray
    tof_eta: np.ndarray
    gauge_eta: np.ndarray
    stations: np.ndarray
    modal_units: UnitDeformations | None = None
    residual_participation: tuple[float, ...] = ()
    combimode_pair: UnitDeformations | None = None
    units_xi: UnitDeformations | None = None
    modal_units_xi: UnitDeformations | None = None
    residual_participation_xi: tuple[float, ...] = ()
    gauge_angle: np.ndarray | None = None

    @property
    def biaxial(self) -> bool:
        """The model carries the ξ plane (a biaxial beam)."""
        return self.units_xi is not None

    @property
    def gamma_xi(self) -> int:
        """Γξ, the unit deformations in ξ (0 for a planar model)."""
        return 0 if self.units_xi is None else self.units_xi.count

    @property
    def modal_xi(self) -> UnitDeformations | None:
        """The Γξ + Rξ shapes of the ξ modal block (None for a planar model)."""
        return self.units_xi if self.modal_units_xi is None else self.modal_units_xi

    @property
    def residual_xi(self) -> int:
        """Rξ, the residual modes carried in ξ."""
        modal = self.modal_xi
        return 0 if modal is None else modal.count - self.gamma_xi

    def gauge_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(ζp, ξp) (G,) in m of the selected gauges: where on the outline each sits
        (``Beam.section_point``); a planar model's are (±c(η), 0) of the +ζ and −ζ faces."""
        eta = self.gauge_eta
        angle = np.zeros(eta.size) if self.gauge_angle is None else np.asarray(self.gauge_angle, dtype=float)
        if eta.size == 0:
            return np.zeros(0), np.zeros(0)
        if not self.biaxial:
            # ±c exactly (a gauge on the −ζ face reads the opposite strain): planar strain stays −c·κ bit for bit
            face = np.where(np.mod(angle, 360.0) == 180.0, -1.0, 1.0)
            return face * np.asarray(self.rig.beam.fibre_distance(eta), dtype=float), np.zeros(eta.size)
        zeta_p, xi_p = self.rig.beam.section_point(eta, angle)
        return np.asarray(zeta_p, dtype=float), np.asarray(xi_p, dtype=float)

    def combimode_strain_errors(self) -> np.ndarray:
        """The strain the combimode cannot represent of the two modes it merges, per unit b_1, at
        the selected gauges: (G, 2), signed; (G, 0) without a combimode.

        The combimode stands for s̃_1 and s̃_2, alike in deflection (MAC ≈ 0.99) but with
        curvatures 20–40 % apart at the gauges. Its shape is s̃_2 (``unit_deformations``), so
        mode 2's column is zero; for s̃_1, b is what the peripheral IMUs' least squares reads
        (slopes for gyros, deflections for accelerometers: they read its tip to 0.1–0.25 %), and
        the column is the strain that b predicts at each gauge minus the mode's own strain there,
        divided by b_1: the conflict between the inputs and the gauges that no b resolves (read by
        the four gauges alone, s̃_1's tip comes out 3.6 % small). It is one pattern over the gauges
        and grows with the amplitude of mode 1, which b_1 bounds, so the filter carries it as a
        model error Σ_k ψ_k column_k · b_1 shared by the gauges of one time (conservative: most of
        b_1 is mode 2).
        """
        pair = self.combimode_pair
        n_g = self.gauge_eta.size
        if pair is None or self.imu_eta.size == 0 or n_g == 0:
            return np.zeros((n_g, 0))
        units = self.units
        if self.kind == KIND_GYRO:
            A, Y = units.slope(self.imu_eta), pair.slope(self.imu_eta)
        else:
            A, Y = units.shape(self.imu_eta), pair.shape(self.imu_eta)
        b = np.linalg.pinv(A) @ Y  # (Γ, 2): each mode as the IMUs read it
        fibre = self.rig.beam.fibre_distance(self.gauge_eta)[:, None]  # c(η): h*/2 of the paper's sheet
        miss = -fibre * (units.curvature(self.gauge_eta) @ b - pair.curvature(self.gauge_eta))
        return miss / b[0]

    @property
    def kind(self) -> int:
        return KIND_GYRO if self.selection.peripheral == "gyro" else KIND_ACC

    @property
    def gamma(self) -> int:
        return self.units.count

    @property
    def modal(self) -> UnitDeformations:
        """The Γ + R shapes of the state's modal block (b, then the residual modes r)."""
        return self.units if self.modal_units is None else self.modal_units

    @property
    def residual(self) -> int:
        """R, the residual modes carried beyond the Γ unit deformations."""
        return self.modal.count - self.gamma

    @property
    def state_layout(self) -> StateLayout:
        """Which entry of the state vector is what (the one layout every consumer reads)."""
        return StateLayout(self.selection.peripheral, self.gamma, len(self.selection.imus), attitude=self.has_attitude,
                           imu_names=tuple(self.selection.imus), residual=self.residual, gamma_xi=self.gamma_xi,
                           residual_xi=self.residual_xi)

    @property
    def has_attitude(self) -> bool:
        """φ is a state (pinned bearing); a clamped support fixes φ ≡ 0 and has none."""
        if self.rig.support == "pinned":
            return True
        if self.rig.support == "clamped":
            return False
        raise ValueError(f"support={self.rig.support!r} must be 'pinned' or 'clamped'")

    @property
    def gravity_eta(self) -> float:
        """Gravity along inertial η (m/s²): +g hanging, −g standing (η points up the mast)."""
        return _axial_gravity(self.rig)

    @property
    def mode_map(self) -> ModeMap:
        """The eigenmodes each unit deformation carries (the labels of trends and spectra)."""
        return ModeMap.of(self.units.modes)

    @property
    def state_size(self) -> int:
        return self.state_layout.size

    @property
    def state_names(self) -> list[str]:
        return list(self.state_layout.names)

    @property
    def fixed_support(self) -> bool:
        """No bearing sensor: D is fixed to the ground (d ≡ 0), told to the filter as a pseudo-measurement."""
        return self.rig.support_fixed_to_ground

    @property
    def aiding_channels(self) -> list[str]:
        return ([f"/tof/{n}" for n in self.selection.tofs] + [f"/strain/{n}" for n in self.selection.gauges]
                + ["pseudo:d" if self.fixed_support else BEARING_TOPIC, "pseudo:h", "pseudo:h_rate"])

    def tip_row(self) -> np.ndarray:
        """s_χ(L) of the Γ unit deformations: e = b · tip_row() without residual modes."""
        return self.units.shape(self.rig.beam.length)

    def strain_matrix(self) -> np.ndarray:
        """Eq. (19) with the section's fibre distance: ε = −c(η) S'' [b, r] (c = h*/2 for the paper's
        sheet), rows for the selected gauges (Γ + R columns). A biaxial model's gauge at θ sees both
        planes, ε = −(ζp κζ + ξp κξ): Γ + R + Γξ + Rξ columns, [b, r] then [bξ, rξ]."""
        n_xi = 0 if self.modal_xi is None else self.modal_xi.count
        if self.gauge_eta.size == 0:
            return np.zeros((0, self.modal.count + n_xi))
        if not self.biaxial and (self.gauge_angle is None or not np.any(self.gauge_angle)):
            return -self.rig.beam.fibre_distance(self.gauge_eta)[:, None] * self.modal.curvature(self.gauge_eta)
        zeta_p, xi_p = self.gauge_points()
        blocks = [-zeta_p[:, None] * self.modal.curvature(self.gauge_eta)]
        if self.modal_xi is not None:
            blocks.append(-xi_p[:, None] * self.modal_xi.curvature(self.gauge_eta))
        return np.hstack(blocks)

    def tip_deflection(self, x: np.ndarray) -> np.ndarray:
        """e = Δ(L) (m) of state(s) ``x`` (…, n), residual modes included."""
        return self.state_layout.check(x)[..., self.state_layout.modal] @ self.modal.shape(self.rig.beam.length)

    def deflection(self, x: np.ndarray, eta: np.ndarray | None = None) -> np.ndarray:
        """Δ(η) (m) of state(s) ``x`` (…, n) at ``eta`` (default: the truth stations), residual modes included."""
        eta = self.stations if eta is None else np.asarray(eta, dtype=float)
        return self.state_layout.check(x)[..., self.state_layout.modal] @ self.modal.shape(eta).T

    def curvature(self, x: np.ndarray, eta: np.ndarray | None = None) -> np.ndarray:
        """∂²Δ/∂η² (1/m) of state(s) ``x`` (…, n) at ``eta`` (default: the truth stations), residual modes included."""
        eta = self.stations if eta is None else np.asarray(eta, dtype=float)
        return self.state_layout.check(x)[..., self.state_layout.modal] @ self.modal.curvature(eta).T

    def _xi_block(self, x: np.ndarray) -> tuple[np.ndarray, UnitDeformations]:
        modal = self.modal_xi
        if modal is None:
            raise ValueError("this model is planar (beam.bending='planar'): it has no ξ plane")
        return self.state_layout.check(x)[..., self.state_layout.modal_xi], modal

    def tip_deflection_xi(self, x: np.ndarray) -> np.ndarray:
        """eξ = Δξ(L) (m) of state(s) ``x`` (…, n), residual modes included; ValueError for a planar model."""
        block, modal = self._xi_block(x)
        return block @ modal.shape(self.rig.beam.length)

    def deflection_xi(self, x: np.ndarray, eta: np.ndarray | None = None) -> np.ndarray:
        """Δξ(η) (m) of state(s) ``x`` at ``eta`` (default: the truth stations); ValueError for a planar model."""
        eta = self.stations if eta is None else np.asarray(eta, dtype=float)
        block, modal = self._xi_block(x)
        return block @ modal.shape(eta).T

    def curvature_xi(self, x: np.ndarray, eta: np.ndarray | None = None) -> np.ndarray:
        """κξ = ∂²Δξ/∂η² (1/m) of state(s) ``x`` at ``eta`` (default: the truth stations); ValueError for a planar model."""
        eta = self.stations if eta is None else np.asarray(eta, dtype=float)
        block, modal = self._xi_block(x)
        return block @ modal.curvature(eta).T


def build_model(
    rig: RigDescription,
    *,
    peripheral: Literal["gyro", "acc"] = "gyro",
    modes: int = 4,
    imus=4,
    tofs=4,
    gauges=4,
    aided=None,
    temperature_c: float | None = None,
    residual_modes: int | None = None,
    check_observable: bool = True,
    modes_xi: int | None = None,
) -> ImmsModel:
    """Unit deformations (Γ = ``modes``) of the rig's FE model and the selected sensors (EfI for counts).

    A pinned support (the plain bearing) has the attitude φ as a state and the combimode; a clamped
    one (the fixed bearing, a mast's root) fixes φ ≡ 0: its state has no φ and no gyro bias at D, the
    IMU at D measures the support's acceleration, and each unit deformation is one eigenmode.
    Hanging and standing beams differ in the sign of gravity along η (``ImmsModel.gravity_eta``).

    ``residual_modes`` (R): eigenmodes after the Γ unit deformations carried as states with their
    FE dynamics (r̈ + 2ζω ṙ + ω² r = −p a_D, driven by the support's measured acceleration), not
    reported as unit deformations. None (default): 1 for a clamped support, 0 for a pinned one. The
    clamp passes the support's motion to every mode, so the paper's excitation drives mode Γ + 1
    near resonance, and the least squares of the peripheral gyros and of the gauges would read it
    as b1..bΓ many times over (for the benchmark layout −7.7 and −99 times its tip deflection). A
    pinned beam's modes beyond Γ + 1 alias about once; its body frame turns, which the residual
    model (a support that only translates) does not describe, so a pinned model carries none.

    Works with the sensors the rig has: without ToFs there is no ToF aiding (and no reflector);
    without a ``bearing`` sensor the support is fixed to the ground and the filter is told d = 0.
    ``check_observable`` (default True) refuses, with a ValueError naming what is missing, a
    selection whose peripheral IMUs cannot tell the Γ unit deformations apart or whose aiding (ToFs,
    aided gauges) does not see all of them (``observability_problem``); False builds such a model
    anyway (to inspect its layout, not to estimate with it).

    A biaxial beam (``beam.bending = "biaxial"``, clamped) bends in ξ too: Γξ = ``modes_xi`` unit
    deformations (None: the same as ``modes``) of its ξ FE model (``assemble_beam(plane="xi")``),
    with as many residual modes as ζ, in the same filter; its accel z and gyro y read the ξ plane
    and a gauge at an angle sees both. The observability check is made per plane and a refusal
    names the plane. ``modes_xi`` on a planar beam is refused.
    """
    if rig.support not in ("pinned", "clamped"):
        raise ValueError(f"support={rig.support!r} must be 'pinned' or 'clamped'")
    if not any(s.kind == "imu" and s.name == "D" for s in rig.sensors):
        others = ", ".join(s.name for s in rig.sensors_of("imu")) or "none"
        raise ValueError(f"rig.json has no IMU named 'D' at the bearing (key 'sensors': {{\"name\": \"D\", \"kind\": \"imu\", "
                         f"\"position\": 0.0}}): the IMMS needs it, on a support fixed to the ground too (the IMU on the support, "
                         f"its reference for the rigid motion); the rig's IMUs: {others}. Without it the rig serves shm import, "
                         f"inspect, oma and loads, not the estimator")
    if residual_modes is None:
        residual_modes = 1 if rig.support == "clamped" else 0
    if isinstance(residual_modes, bool) or not isinstance(residual_modes, (int, np.integer)) or not 0 <= residual_modes <= 3:
        raise ValueError(f"{residual_modes=} must be an integer in [0, 3] (or None: from the support)")
    if residual_modes and rig.support != "clamped":
        raise ValueError(f"{residual_modes=}: residual modes are modelled for a clamped support (one that only "
                         f"translates); support={rig.support!r} turns with the beam")
    biaxial = bool(getattr(rig.beam, "biaxial", False))
    if modes_xi is not None and not biaxial:
        raise ValueError(f"{modes_xi=}: unit deformations in ξ need a beam that bends in both planes "
                         "(beam.bending='biaxial'); this beam bends in ζ only")
    beam = assemble_beam(rig, temperature_c=temperature_c)
    units = unit_deformations(beam, modes)
    modal_units = with_residual_modes(beam, modes, int(residual_modes)) if residual_modes else None
    participation = _participation(beam, modal_units, modes)
    units_xi = modal_units_xi = None
    participation_xi: tuple[float, ...] = ()
    if biaxial:
        gamma_xi = modes if modes_xi is None else modes_xi
        if isinstance(gamma_xi, bool) or not isinstance(gamma_xi, (int, np.integer)) or gamma_xi < 1:
            raise ValueError(f"modes_xi={gamma_xi!r} must be an integer >= 1 (the unit deformations in ξ)")
        beam_xi = assemble_beam(rig, temperature_c=temperature_c, plane="xi")
        units_xi = unit_deformations(beam_xi, int(gamma_xi))
        modal_units_xi = with_residual_modes(beam_xi, int(gamma_xi), int(residual_modes)) if residual_modes else None
        participation_xi = _participation(beam_xi, modal_units_xi, int(gamma_xi))
    selection = select_sensors(rig, units, peripheral=peripheral, imus=imus, tofs=tofs, gauges=gauges, aided=aided,
                               units_xi=units_xi)
    # The two body-frame modes the combimode merges, each on its own (for its model error).
    pair = unit_deformations(beam, 2, combimode=False) if units.modes and units.modes[0] == (1, 2) else None
    by_name = {(s.kind, s.name): s for s in rig.sensors}
    imu_eta = np.array([by_name["imu", n].position for n in selection.imus], dtype=float)
    tof_eta = np.array([by_name["tof", n].position for n in selection.tofs], dtype=float)
    gauge_eta = np.array([by_name["strain", n].position for n in selection.gauges], dtype=float)
    gauge_angle = np.array([by_name["strain", n].angle_deg for n in selection.gauges], dtype=float) if biaxial else None
    if check_observable:
        if biaxial:
            assert units_xi is not None  # a biaxial beam's ξ basis was built above
            zeta_p, xi_p = (np.asarray(v, dtype=float).reshape(-1) for v in rig.beam.section_point(gauge_eta, gauge_angle)) \
                if gauge_eta.size else (np.zeros(0), np.zeros(0))
            problem = biaxial_observability_problem(units, units_xi, selection, imu_eta=imu_eta, tof_eta=tof_eta,
                                                    gauge_eta=gauge_eta, gauge_points=(zeta_p, xi_p))
            if problem:
                raise UnobservableRig(f"this rig cannot be estimated with Γ={units.count}, Γξ={units_xi.count}: {problem}")
        else:
            problem = observability_problem(units, selection, imu_eta=imu_eta, tof_eta=tof_eta, gauge_eta=gauge_eta)
            if problem:
                raise UnobservableRig(f"this rig cannot be estimated with Γ={units.count}: {problem}")
    return ImmsModel(
        rig=rig,
        units=units,
        selection=selection,
        imu_eta=imu_eta,
        tof_eta=tof_eta,
        gauge_eta=gauge_eta,
        stations=np.asarray(rig.truth_stations, dtype=float),
        modal_units=modal_units,
        residual_participation=participation,
        combimode_pair=pair,
        units_xi=units_xi,
        modal_units_xi=modal_units_xi,
        residual_participation_xi=participation_xi,
        gauge_angle=gauge_angle,
    )


def _participation(beam, modal_units: UnitDeformations | None, modes: int) -> tuple[float, ...]:
    """p of each residual mode of ``modal_units`` (after the ``modes`` unit deformations):
    r̈ + ω² r = −p a_D, the support's acceleration loading every mass with −m a_D (M s_r · t / M s_r · s_r)."""
    if modal_units is None:
        return ()
    t = beam.uniform_translation()
    shapes = modal_units.shapes.dofs[:, modes:]
    return tuple(float((s @ beam.mass @ t) / (s @ beam.mass @ s)) for s in shapes.T)


@dataclass(frozen=True)
class RestCalibration:
    """What the rest phase told: biases, offsets and noise levels of every selected sensor."""

    rest_end: float  # s (same origin as the measurements); equal to the start if there was no rest
    rested: bool
    bias_D: np.ndarray  # [f_x, f_y, ω_z] (a biaxial model's [f_x, f_y, ω_z, f_z, ω_y])
    bias_imu: np.ndarray  # (ν, 3) (biaxial: (ν, 5))
    noise_D: np.ndarray  # (3,) std (biaxial: (5,))
    noise_imu: np.ndarray  # (ν, 3) (biaxial: (ν, 5))
    tof_offset: np.ndarray
    tof_std: np.ndarray
    strain_offset: np.ndarray
    strain_std: np.ndarray
    bearing_std: float

    def as_dict(self) -> dict:
        return {
            "rest_end_s": float(self.rest_end),
            "rested": self.rested,
            "gyro_bias_D_rad_s": float(self.bias_D[2]),
            "accel_bias_D_m_s2": self.bias_D[:2].tolist(),
            "gyro_bias_peripheral_rad_s": self.bias_imu[:, 2].tolist(),
            "tof_offset_m": self.tof_offset.tolist(),
            "strain_offset": self.strain_offset.tolist(),
        }


def _rest_end(meas: Measurements, config: FilterConfig, model: ImmsModel | None = None) -> float:
    """End of the initial rest: the first sign of motion at D (gyro, lateral accel) or the bearing.

    A support fixed to the ground (``model.fixed_support``) does not move when the structure
    starts to: there the selected peripheral IMUs and strain gauges tell the motion too (the wind
    moves a mast's top long before its foundation)."""
    d_imu = meas.imu["D"]
    t = d_imu.times
    start = t[0]
    limit = start + config.rest_max_s
    quiet = t < start + min(2.0, config.rest_max_s)
    if quiet.sum() < 20:
        return start
    # no motion seen: the rest lasted to the end of the data at most (a calibration on its first seconds)
    end = min(limit, float(t[-1]))
    watched: list[tuple[SensorSeries, int, float]] = [(d_imu, 1, 0.05), (d_imu, 2, 0.01)]
    if model is not None and model.biaxial and d_imu.values.shape[1] >= 5:
        watched += [(d_imu, 3, 0.05), (d_imu, 4, 0.01)]
    if model is not None and model.fixed_support:
        for name in model.selection.imus:
            if name in meas.imu:
                watched += [(meas.imu[name], 1, 0.05), (meas.imu[name], 2, 0.01)]
                if model.biaxial and meas.imu[name].values.shape[1] >= 5:
                    watched += [(meas.imu[name], 3, 0.05), (meas.imu[name], 4, 0.01)]
        watched += [(meas.strain[name], 0, 2e-6) for name in model.selection.gauges if name in meas.strain]
    for series, column, floor in watched:
        ts = series.times
        x = series.values[:, column]
        ref = x[ts < start + min(2.0, config.rest_max_s)]
        ref = ref[np.isfinite(ref)]
        if ref.size < 20:
            continue
        level, spread = np.median(ref), np.std(ref)
        threshold = max(8.0 * spread, floor)
        moving = np.nonzero((np.abs(x - level) > threshold) & (ts < limit))[0]
        if moving.size:
            end = min(end, ts[moving[0]])
    if meas.bearing is not None and meas.bearing.times.size:
        b = meas.bearing
        ref = b.values[b.times < start + 2.0, 0]
        if ref.size >= 5:
            moving = np.nonzero((np.abs(b.values[:, 0] - np.median(ref)) > max(6 * np.std(ref), 2e-4)) & (b.times < limit))[0]
            if moving.size:
                end = min(end, b.times[moving[0]])
    # Motion builds up before it shows (a smooth start needs ~1.5 s to pass the thresholds): keep a margin.
    end = max(start, end - 2.0)
    return end


def calibrate_at_rest(meas: Measurements, model: ImmsModel, config: FilterConfig = FilterConfig()) -> RestCalibration:
    """Learn biases, offsets and noise levels from the initial rest phase (still, φ = 0, b = 0).

    Without a usable rest phase biases start at zero and noise levels at the floors; the
    gyro bias at D is estimated by the filter in any case.
    """
    if "D" not in meas.imu:
        raise ValueError("measurements have no IMU 'D' (the IMU at the bearing)")
    g_eta = model.gravity_eta
    start = meas.start
    end = _rest_end(meas, config, model)
    rested = end - start >= config.rest_min_s
    # Specific force along the beam at rest (−g hanging, +g standing: x points from D along the
    # beam, up a mast), nothing across, no rate; a biaxial model's IMUs add [f_z, ω_y].
    width = 5 if model.biaxial else 3
    expected = np.array([-g_eta, 0.0, 0.0, 0.0, 0.0][:width])

    def stats(series: SensorSeries | None, columns: int) -> tuple[np.ndarray, np.ndarray]:
        if series is None or not rested:
            return np.zeros(columns), np.full(columns, np.nan)
        part = series.window(start, end).values
        part = part[np.all(np.isfinite(part), axis=1)]
        if part.shape[0] < 10:
            return np.zeros(columns), np.full(columns, np.nan)
        return part.mean(axis=0)[:columns], part.std(axis=0)[:columns]

    def floor(std: np.ndarray) -> np.ndarray:
        a, w = config.accel_noise_floor, config.gyro_noise_floor
        floors = np.array([a, a, w, a, w][:width])
        return np.where(np.isfinite(std), np.maximum(std, floors), floors * 4)

    mean_D, std_D = stats(meas.imu["D"], width)
    bias_D = np.where(rested, mean_D - expected, 0.0)
    bias_imu = np.zeros((len(model.selection.imus), width))
    noise_imu = np.zeros((len(model.selection.imus), width))
    for i, name in enumerate(model.selection.imus):
        mean, std = stats(meas.imu.get(name), width)
        bias_imu[i] = mean - expected if rested and np.all(np.isfinite(std)) else 0.0
        noise_imu[i] = floor(std)
    bearing_mean, bearing_std = stats(meas.bearing, 1)
    d_ref = model.rig.reflector_distance
    tof_offset = np.zeros(len(model.selection.tofs))
    tof_std = np.zeros(len(model.selection.tofs))
    for i, name in enumerate(model.selection.tofs):
        mean, std = stats(meas.tof.get(name), 1)
        at_rest = d_ref - (bearing_mean[0] if np.isfinite(bearing_std[0]) else 0.0)
        tof_offset[i] = mean[0] - at_rest if np.isfinite(std[0]) else 0.0
        tof_std[i] = std[0] if np.isfinite(std[0]) else 0.003
    strain_offset = np.zeros(len(model.selection.gauges))
    strain_std = np.zeros(len(model.selection.gauges))
    for i, name in enumerate(model.selection.gauges):
        mean, std = stats(meas.strain.get(name), 1)
        strain_offset[i] = mean[0] if np.isfinite(std[0]) else 0.0
        strain_std[i] = std[0] if np.isfinite(std[0]) else 2e-6
    return RestCalibration(
        rest_end=end,
        rested=bool(rested),
        bias_D=bias_D,
        bias_imu=bias_imu,
        noise_D=floor(std_D),
        noise_imu=noise_imu,
        tof_offset=tof_offset,
        tof_std=tof_std,
        strain_offset=strain_offset,
        strain_std=strain_std,
        bearing_std=float(bearing_std[0]) if np.isfinite(bearing_std[0]) else float("nan"),
    )


@dataclass(frozen=True)
class Events:
    """Time-ordered measurement events: t (s), kind (event code), index (sensor), values (n, 3) (a biaxial
    model's (n, 5): its IMUs' [f_x, f_y, ω_z, f_z, ω_y])."""

    t: np.ndarray
    kind: np.ndarray
    index: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return self.t.shape[0]

    @staticmethod
    def empty(width: int = 3) -> "Events":
        return Events(np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, width)))

    def slice(self, lo: int, hi: int) -> "Events":
        return Events(self.t[lo:hi], self.kind[lo:hi], self.index[lo:hi], self.values[lo:hi])


def build_events(meas: Measurements, model: ImmsModel) -> Events:
    """Merge the selected sensors' samples into one stream ordered by time (inputs before aiding).

    Values have 3 columns, a biaxial model's 5 (its IMUs' [f_x, f_y, ω_z, f_z, ω_y]); ValueError for
    a biaxial model whose IMU samples lack f_z and ω_y."""
    parts: list[tuple[np.ndarray, int, int, np.ndarray]] = []
    width = 5 if model.biaxial else 3

    def add(series: SensorSeries | None, kind: int, index: int, columns: int) -> None:
        if series is None or series.times.size == 0:
            return
        if series.values.shape[1] < columns:
            raise ValueError(f"IMU samples have {series.values.shape[1]} columns; the biaxial model reads {columns}: "
                             "[f_x, f_y, ω_z, f_z, ω_y] (contract.IMU_BIAXIAL_COLUMNS)")
        values = np.zeros((series.times.size, width))
        values[:, :columns] = series.values[:, :columns]
        parts.append((series.times, kind, index, values))

    add(meas.imu.get("D"), EVENT_IMU_D, 0, width)
    for i, name in enumerate(model.selection.imus):
        add(meas.imu.get(name), EVENT_IMU_PERIPHERAL, i, width)
    for i, name in enumerate(model.selection.tofs):
        add(meas.tof.get(name), EVENT_TOF, i, 1)
    for i, name in enumerate(model.selection.gauges):
        add(meas.strain.get(name), EVENT_STRAIN, i, 1)
    if model.fixed_support:
        # d ≡ 0: the support is fixed to the ground. The filter keeps d, ḋ as states (one state layout
        # for every rig; the IMU at D still measures the foundation's vibration, which drives the
        # modes) and is told d = 0 with every D sample, as a bearing sensor would tell it d.
        d_series = meas.imu.get("D")
        if d_series is not None and d_series.times.size:
            add(SensorSeries(d_series.times, np.zeros((d_series.times.size, 1))), EVENT_BEARING, 0, 1)
    else:
        add(meas.bearing, EVENT_BEARING, 0, 1)
    if not parts:
        return Events.empty(width)
    t = np.concatenate([p[0] for p in parts])
    kind = np.concatenate([np.full(p[0].size, p[1], dtype=np.int64) for p in parts])
    index = np.concatenate([np.full(p[0].size, p[2], dtype=np.int64) for p in parts])
    values = np.concatenate([p[3] for p in parts])
    order = np.lexsort((kind, t))
    return Events(t[order], kind[order], index[order], values[order])


def _concat_events(a: Events, b: Events) -> Events:
    return Events(np.concatenate([a.t, b.t]), np.concatenate([a.kind, b.kind]),
                  np.concatenate([a.index, b.index]), np.concatenate([a.values, b.values]))


@dataclass(frozen=True)
class FilterOutput:
    """Filter states at the D-IMU sample times: t (N,), x (N, n), P_diag (N, n), var_e (N,)."""

    t: np.ndarray
    x: np.ndarray
    P_diag: np.ndarray
    var_e: np.ndarray

    @staticmethod
    def concatenate(parts: list["FilterOutput"], n: int) -> "FilterOutput":
        if not parts:
            return FilterOutput(np.zeros(0), np.zeros((0, n)), np.zeros((0, n)), np.zeros(0))
        return FilterOutput(np.concatenate([p.t for p in parts]), np.concatenate([p.x for p in parts]),
                            np.concatenate([p.P_diag for p in parts]), np.concatenate([p.var_e for p in parts]))


def model_arrays(model: ImmsModel, calibration: RestCalibration, config: FilterConfig = FilterConfig()) -> ModelArrays:
    """What the compiled loop reads of a model, its rest calibration and the tuning (read only).

    Every array is float64 and C-contiguous, so one compiled version of the loop serves all
    models of a configuration.
    """
    m, c, cfg = model, calibration, config
    units = m.modal  # b and the residual modes: the kernels' modal block
    noise_D = c.noise_D
    if m.fixed_support:
        bearing_std = cfg.fixed_support_std
    else:
        bearing_std = max(cfg.bearing_std, c.bearing_std if np.isfinite(c.bearing_std) else 0.0)
    reflector = m.rig.reflector_distance
    params = FilterParams(
        gravity_eta=float(m.gravity_eta), reflector_distance=float("nan") if reflector is None else float(reflector),
        gate=cfg.gate,
        stale_after=cfg.stale_after_s, sigma_f_d_x=float(noise_D[0]), sigma_f_d_y=float(noise_D[1]),
        sigma_omega_d=float(noise_D[2]), q_b=cfg.q_b,
        q_v=cfg.q_v if cfg.q_v is not None else (1e-6 if m.selection.gauges else 1e-3), q_beta=cfg.q_beta,
        q_rigid=cfg.q_rigid, bearing_var=bearing_std**2, pseudo_h_var=cfg.pseudo_h_std**2,
        pseudo_h_rate_var=cfg.pseudo_h_rate_std**2, max_step=cfg.max_step_s, q_null=cfg.q_null,
        q_beta_peripheral=cfg.q_beta_peripheral, q_residual=cfg.q_residual,
        # A pseudo-measurement states a fact of the rig: the gate never refuses it.
        bearing_gate=1e300 if m.fixed_support else cfg.gate,
        sigma_f_d_z=float(noise_D[3]) if m.biaxial else 0.0,
    )
    gamma = units.count
    empty = np.zeros((0, gamma))
    pair_errors = m.combimode_strain_errors()
    aided = np.zeros(gamma)
    aided[[a - 1 for a in m.selection.aided]] = 1.0
    if m.selection.gauges:
        aided[m.gamma:] = 1.0  # the gauges see the residual modes' strain: they must correct them
    units_xi = m.modal_xi
    nu = m.imu_eta.size
    if units_xi is None:
        imu_S_xi = imu_S1_xi = sig_xi = np.zeros((nu, 0))
        res_xi: list[float] = []
    else:
        aided_xi = np.zeros(units_xi.count)
        aided_xi[[a - 1 for a in m.selection.aided_xi]] = 1.0
        if m.selection.gauges:
            aided_xi[m.gamma_xi:] = 1.0
        aided = np.concatenate([aided, aided_xi])
        imu_S_xi = units_xi.shape(m.imu_eta) if nu else np.zeros((0, units_xi.count))
        imu_S1_xi = units_xi.slope(m.imu_eta) if nu else np.zeros((0, units_xi.count))
        sig_xi = c.noise_imu[:, 3:5]
        res_xi = [2 * np.pi * f for group in units_xi.frequencies_hz[m.gamma_xi:] for f in group]

    def arr(value: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(value, dtype=np.float64)

    return ModelArrays(
        index=m.state_layout.index,
        kind=int(m.kind),
        params=params,
        bias_D=arr(c.bias_D),
        bias_j=arr(c.bias_imu),
        imu_eta=arr(m.imu_eta),
        imu_S=arr(units.shape(m.imu_eta) if m.imu_eta.size else empty),
        imu_S1=arr(units.slope(m.imu_eta) if m.imu_eta.size else empty),
        sig_fj=arr(c.noise_imu[:, :2]),
        sig_wj=arr(c.noise_imu[:, 2]),
        tof_eta=arr(m.tof_eta),
        tof_S=arr(units.shape(m.tof_eta) if m.tof_eta.size else empty),
        tof_S1=arr(units.slope(m.tof_eta) if m.tof_eta.size else empty),
        tof_offset=arr(c.tof_offset),
        tof_var=arr(c.tof_std**2 + cfg.tof_model_std**2),
        strain_K=arr(m.strain_matrix()),
        strain_offset=arr(c.strain_offset),
        strain_var=arr(c.strain_std**2 + cfg.strain_model_std**2),
        aided=arr(aided),
        tip_row=arr(units.shape(m.rig.beam.length)),
        strain_pair=arr(cfg.combimode_error_scale * pair_errors if cfg.combimode_error_scale > 0 else pair_errors[:, :0]),
        res_omega=arr([2 * np.pi * f for group in units.frequencies_hz[m.gamma:] for f in group] + res_xi),
        res_damping=arr(np.full(m.residual + m.residual_xi, cfg.residual_damping)),
        res_participation=arr(m.residual_participation + m.residual_participation_xi),
        imu_S_xi=arr(imu_S_xi),
        imu_S1_xi=arr(imu_S1_xi),
        sig_xi=arr(sig_xi),
    )


class ImmsFilter:
    """The EKF of one configuration; holds the state between calls of ``process``."""

    def __init__(self, model: ImmsModel, calibration: RestCalibration, config: FilterConfig = FilterConfig(), *, t0: float):
        self.model = model
        self.calibration = calibration
        self.config = config
        n = model.state_size
        nu = len(model.selection.imus)
        g = model.gravity_eta
        # the rest guess of the inputs: [f_x, f_y] (a biaxial model's [f_x, f_y, f_z] at D, [f_x, f_y, f_z, ω_y] peripheral)
        rest_D = [-g, 0.0, 0.0] if model.biaxial else [-g, 0.0]
        rest_j = [-g, 0.0, 0.0, 0.0] if model.biaxial else [-g, 0.0]
        self.state = FilterState(
            x=np.zeros(n), P=np.eye(n) * config.initial_std**2, clock=np.array([float(t0), float(t0), np.nan]),
            held_fD=np.array(rest_D), held_wD=np.zeros(1), held_fj=np.tile(rest_j, (nu, 1)), held_wj=np.zeros(nu),
            prev_fD=np.array(rest_D), prev_wD=np.zeros(1), prev_fj=np.tile(rest_j, (nu, 1)), prev_wj=np.zeros(nu),
            held_real=np.zeros(1, dtype=np.bool_),
            last_seen=np.full(nu, float(t0)), active=np.ones(nu, dtype=np.bool_), pending=np.zeros(1, dtype=np.bool_),
        )
        self._tail = Events.empty(5 if model.biaxial else 3)
        n_channels = len(model.aiding_channels)
        self.counters = AidingCounters(
            accepted=np.zeros(n_channels, dtype=np.int64), rejected=np.zeros(n_channels, dtype=np.int64),
            nis_sum=np.zeros(n_channels), last_innovation=np.zeros(n_channels), degraded_time=np.zeros(nu),
        )
        self.arrays = model_arrays(model, calibration, config)

    @property
    def x(self) -> np.ndarray:
        """The state (n,) in the model's StateLayout."""
        return self.state.x

    @property
    def P(self) -> np.ndarray:
        return self.state.P

    @property
    def t(self) -> float:
        """The filter's time (s)."""
        return float(self.state.clock[0])

    @property
    def accepted(self) -> np.ndarray:
        return self.counters.accepted

    @property
    def rejected(self) -> np.ndarray:
        return self.counters.rejected

    def process(self, events: Events, *, final: bool = False) -> FilterOutput:
        """Run the filter over ``events`` (times must not precede the filter's time).

        Events after the last IMU sample at D wait for the next call (their inputs are
        interpolated towards the next sample); ``final=True`` processes them with held inputs.
        """
        if len(self._tail):
            events = _concat_events(self._tail, events)
        if len(events) > 1 and np.any(np.diff(events.t) < 0):
            # Batches that overlap in time (late deliveries) are merged into one time order.
            order = np.lexsort((events.kind, events.t))
            events = Events(events.t[order], events.kind[order], events.index[order], events.values[order])
        d_index = np.nonzero(events.kind == EVENT_IMU_D)[0]
        if final:
            cut = len(events)
        elif d_index.size < 2:
            cut = 0
        else:
            # The group of IMU samples at the last D time may be split across batches; the steps up
            # to the one before it see complete groups for their input interpolation.
            cut = int(np.searchsorted(events.t, events.t[d_index[-2]], side="right"))
        if events.t.size and events.t[0] < self.t:
            raise ValueError(f"events start at t={events.t[0]} before the filter's time {self.t}")
        self._tail = events.slice(cut, len(events))
        events = events.slice(0, cut)
        d_index = d_index[d_index < cut]
        next_d = np.full(len(events), -1, dtype=np.int64)
        if d_index.size:
            pos = np.searchsorted(d_index, np.arange(len(events)))
            has = pos < d_index.size
            next_d[has] = d_index[pos[has]]
        n = self.model.state_size
        capacity = int(np.count_nonzero(events.kind == EVENT_IMU_D)) + 1
        out = FilterOutputs(np.empty(capacity), np.empty((capacity, n)), np.empty((capacity, n)), np.empty(capacity))
        batch = EventArrays(np.ascontiguousarray(events.t, dtype=np.float64), np.ascontiguousarray(events.kind, dtype=np.int64),
                            np.ascontiguousarray(events.index, dtype=np.int64),
                            np.ascontiguousarray(events.values, dtype=np.float64), next_d)
        n_out = run_events(batch, self.arrays, self.state, out, self.counters)
        return FilterOutput(out.t[:n_out], out.x[:n_out], out.P[:n_out], out.var_e[:n_out])

    def flush(self) -> FilterOutput:
        """Process what waits for a next IMU sample and output the last state."""
        n = self.model.state_size
        if len(self._tail):
            out = self.process(Events.empty(self._tail.values.shape[1]), final=True)
            return FilterOutput.concatenate([out, self.flush()], n)
        if not self.state.pending[0]:
            return FilterOutput.concatenate([], n)
        self.state.pending[0] = False
        var_e = np.array([tip_variance(self.P, self.arrays.tip_row, self.model.state_layout.index.b)])
        return FilterOutput(np.array([self.t]), self.x[None, :].copy(), np.diag(self.P)[None, :].copy(), var_e)

    def diagnostics(self) -> dict:
        """Per aiding channel: accepted, rejected, mean NIS; degraded peripheral IMUs."""
        channels = self.model.aiding_channels
        c = self.counters
        per_channel = {
            name: {
                "accepted": int(c.accepted[i]),
                "rejected": int(c.rejected[i]),
                "mean_nis": float(c.nis_sum[i] / c.accepted[i]) if c.accepted[i] else None,
            }
            for i, name in enumerate(channels)
        }
        active = self.state.active
        degraded = [
            {"sensor": f"/imu/{name}", "silent_s": float(c.degraded_time[j]), "active": bool(active[j])}
            for j, name in enumerate(self.model.selection.imus)
            if c.degraded_time[j] > 0 or not active[j]
        ]
        return {"aiding": per_channel, "rejected": int(self.rejected.sum()), "degraded_imus": degraded}


@dataclass(frozen=True)
class EstimateResult:
    """Estimates of one run at the D-IMU sample times, with what the model derives from them."""

    model: ImmsModel
    calibration: RestCalibration
    t: np.ndarray
    x: np.ndarray
    P_diag: np.ndarray
    var_e: np.ndarray
    diagnostics: dict
    filter_seconds: float

    def _column(self, name: str) -> np.ndarray:
        return self.x[:, self.model.state_layout.position(name)]

    @property
    def d(self) -> np.ndarray:
        return self._column("d")

    @property
    def h(self) -> np.ndarray:
        return self._column("h")

    @property
    def phi(self) -> np.ndarray:
        """φ (rad); zeros for a configuration without an attitude state."""
        return self.model.state_layout.phi_of(self.x)

    @property
    def b(self) -> np.ndarray:
        return self.model.state_layout.b_of(self.x)

    @property
    def e(self) -> np.ndarray:
        """Tip deflection Δ(L) in the body frame (m), residual modes included."""
        return self.model.tip_deflection(self.x)

    def deflection(self, eta: np.ndarray | None = None) -> np.ndarray:
        """Δ(η) (m) at ``eta`` (default: the truth stations), residual modes included."""
        return self.model.deflection(self.x, eta)

    def curvature(self, eta: np.ndarray | None = None) -> np.ndarray:
        """∂²Δ/∂η² (1/m) at ``eta`` (default: the truth stations), residual modes included."""
        return self.model.curvature(self.x, eta)

    @property
    def b_xi(self) -> np.ndarray:
        """bξ (N, Γξ); (N, 0) for a planar model."""
        return self.model.state_layout.b_xi_of(self.x)

    @property
    def e_xi(self) -> np.ndarray:
        """Tip deflection Δξ(L) in the body frame (m); ValueError for a planar model."""
        return self.model.tip_deflection_xi(self.x)

    def deflection_xi(self, eta: np.ndarray | None = None) -> np.ndarray:
        """Δξ(η) (m) at ``eta`` (default: the truth stations); ValueError for a planar model."""
        return self.model.deflection_xi(self.x, eta)

    def curvature_xi(self, eta: np.ndarray | None = None) -> np.ndarray:
        """κξ (1/m) at ``eta`` (default: the truth stations); ValueError for a planar model."""
        return self.model.curvature_xi(self.x, eta)


def support_position_problem(bearing: SensorSeries | None, model: ImmsModel) -> str | None:
    """Why the support's position d cannot be observed with the ``bearing`` samples (None: none),
    or None.

    d is held by the bearing sensor, by the ToFs (they measure from the reflector, Eq. 18) or, for
    a support fixed to the ground (no bearing sensor in the rig), by d ≡ 0. A rig that declares a
    bearing sensor whose samples are missing, without selected ToFs, has nothing but the D
    accelerometer's double integral for d."""
    if model.fixed_support or model.selection.tofs:
        return None
    if bearing is not None and bearing.times.size and np.isfinite(bearing.values[:, 0]).any():
        return None
    return ("the support's position d is not observed: rig.json has a bearing sensor but the recording has no valid "
            f"{BEARING_TOPIC} sample and no ToF is selected, so d is the D accelerometer's double integral and drifts; "
            "if the support is fixed to the ground, remove the bearing sensor from rig.json (d ≡ 0)")
