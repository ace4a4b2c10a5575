"""The virtual rig: a simulation of the plant (beam, bearing, sensors) used as a data source.

It shares the FE beam model with the estimator but none of its kinematic shortcuts.
"""

from ._record import SimulationSummary, simulate
from ._settings import (Damage, OperationalSettings, PlantSettings, SensorErrors, SimulationSettings, WindDirection,
                        WindStorm, parse_damage, settings_for_rig)
from ._virtual_rig import SAMPLE_RATE_HZ, SampleBlock, VirtualRig

__all__ = [
    "SAMPLE_RATE_HZ",
    "Damage",
    "OperationalSettings",
    "PlantSettings",
    "SampleBlock",
    "SensorErrors",
    "SimulationSummary",
    "SimulationSettings",
    "VirtualRig",
    "WindDirection",
    "WindStorm",
    "parse_damage",
    "settings_for_rig",
    "simulate",
]
