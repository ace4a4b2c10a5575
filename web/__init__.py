"""The live SHM dashboard (viser): deformed beam in 3D, spectra, trends, loads, alarms and status.

The service constructs one :class:`Dashboard` on its ``contract.ServicePort``; the dashboard
reads everything through it (one structure or a fleet alike: nothing is pushed in): the
overview, and for the structures its browsers show their model, live estimates, status, alarms,
trend rows, latest window, spectra and (a rig with hot spots) fatigue. Upper layer: imports the
``contract`` and gets the estimator's objects only through the port, never the service.

The parts it draws with are public too: the beam's geometry (pure numpy), the records the plots
read (``window_record``, ``loads_record``, ``spectrum_plot``, ...), one structure's feed
(``StructureFeed``) and the HTML it shows (``overview_html``, ``hot_spots_html``, ...).
"""

from ._dashboard import SENSOR_STATES, Dashboard
from ._data import (
    LoadsRecord,
    baseline_band,
    loads_record,
    spectrum_plot,
    thresholds_of,
    window_record,
    windows_from_trend_rows,
)
from ._feed import Snapshot, StructureFeed
from ._geometry import BeamState, centreline, parse_state, ribbon, ribbon_faces, tangent_angle, to_world, tof_rays
from ._html import HeaderInfo, header_html, hot_spots_html, overview_html, rates_text, severity, status_html
from ._loads import envelope_plot
from ._scene import nice_scale

__all__ = [
    "BeamState",
    "Dashboard",
    "HeaderInfo",
    "LoadsRecord",
    "SENSOR_STATES",
    "Snapshot",
    "StructureFeed",
    "baseline_band",
    "centreline",
    "envelope_plot",
    "header_html",
    "hot_spots_html",
    "loads_record",
    "nice_scale",
    "overview_html",
    "parse_state",
    "rates_text",
    "ribbon",
    "ribbon_faces",
    "severity",
    "spectrum_plot",
    "status_html",
    "tangent_angle",
    "thresholds_of",
    "to_world",
    "tof_rays",
    "window_record",
    "windows_from_trend_rows",
]
