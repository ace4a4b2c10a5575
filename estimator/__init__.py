"""The IMMS estimator: beam model, unit deformations, kinematic and aiding models, the EKF.

Lower layer: knows nothing of the service or the web.
"""

from ._beam import (
    GREENHILL_COEFFICIENT,
    BeamModel,
    BucklingError,
    NaturalModes,
    NodalShapes,
    assemble_beam,
    critical_load_factor,
    greenhill_length,
    natural_modes,
)
from ._calibration import (
    TABLE1_HZ,
    CalibrationParameter,
    CalibrationResult,
    Identifiability,
    calibrate,
    calibration_identifiability,
    modal_frequencies,
)
from ._damage_signatures import DamageSignatures, damage_signatures
from ._filter import (
    EstimateResult,
    Events,
    FilterConfig,
    FilterOutput,
    ImmsFilter,
    ImmsModel,
    Measurements,
    RestCalibration,
    SensorSeries,
    build_events,
    build_model,
    calibrate_at_rest,
    estimate,
)
from contract import Beam, PointMass, RigDescription, RigError, Sensor, StiffnessSegment, load_rig, parse_rig
from ._selection import SensorSelection, default_aided, effective_independence, select_sensors
from ._unit_deformations import MAX_UNIT_DEFORMATIONS, UnitDeformations, unit_deformations

__all__ = [
    "EstimateResult",
    "Events",
    "FilterConfig",
    "FilterOutput",
    "ImmsFilter",
    "ImmsModel",
    "Measurements",
    "RestCalibration",
    "SensorSelection",
    "SensorSeries",
    "build_events",
    "build_model",
    "calibrate_at_rest",
    "default_aided",
    "effective_independence",
    "estimate",
    "greenhill_length",
    "select_sensors",
    "GREENHILL_COEFFICIENT",
    "MAX_UNIT_DEFORMATIONS",
    "TABLE1_HZ",
    "Beam",
    "BeamModel",
    "BucklingError",
    "CalibrationParameter",
    "CalibrationResult",
    "Identifiability",
    "DamageSignatures",
    "NaturalModes",
    "NodalShapes",
    "PointMass",
    "RigDescription",
    "RigError",
    "Sensor",
    "StiffnessSegment",
    "UnitDeformations",
    "assemble_beam",
    "calibrate",
    "critical_load_factor",
    "calibration_identifiability",
    "damage_signatures",
    "load_rig",
    "modal_frequencies",
    "natural_modes",
    "parse_rig",
    "unit_deformations",
]
