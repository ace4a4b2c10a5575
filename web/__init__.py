"""The live SHM dashboard (viser): deformed beam in 3D, spectra, trends, alarms and status.

The service constructs one :class:`Dashboard` and feeds it (``push_estimate``, ``push_spectra``,
``push_window``, ``push_alarm``, with the ``contract``'s documents); the dashboard reads the rest
through a ``DashboardService`` (duck typed: ``status``, ``trends``, ``alarms``, ``acknowledge``,
``set_paused``). A fleet's dashboard (``Dashboard(..., fleet=True)``) is pushed nothing: it reads
a ``FleetDashboardService`` (overview, and for the structures its browsers choose their model,
live estimates, status, rows and spectra). Upper layer: imports the ``contract`` (state layout,
mode map, documents) and gets the estimator's objects only as arguments, never the service.
"""

from ._dashboard import SENSOR_STATES, Dashboard
from ._geometry import BeamState, centreline, parse_state, ribbon, ribbon_faces, tangent_angle, to_world, tof_rays

__all__ = [
    "BeamState",
    "Dashboard",
    "SENSOR_STATES",
    "centreline",
    "parse_state",
    "ribbon",
    "ribbon_faces",
    "tangent_angle",
    "to_world",
    "tof_rays",
]
