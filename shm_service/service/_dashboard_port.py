"""The port between the monitoring service and the dashboard (package ``web``).

The dashboard is built against this file and the ``contract`` package only. The service
implements :class:`DashboardService` and hands it to ``web.Dashboard``; the dashboard calls it
from its own thread (viser runs its own thread and asyncio loop), so every method here is
thread-safe and returns the contract's frozen documents.

Agreed dashboard interface (implemented in ``web``; the service only calls it)::

    Dashboard(*, host: str, port: int, rig, units, layout: contract.StateLayout, stations,
              service: DashboardService)                     # one structure: pushed its data
    Dashboard(*, host: str, port: int, service: FleetDashboardService, fleet=True)
                                                              # a fleet: reads what its browsers select
    .url -> str
    .push_estimate(t_s: float, x: np.ndarray, sensor_states: dict[str, str],
                   truth_deflection: np.ndarray | None)      # >= 10 Hz, decimated by the service
    .push_spectra(spectrum: contract.SpectrumDocument)        # after every committed window
    .push_window(window: contract.WindowDocument)             # every committed window
    .push_alarm(alarm: contract.AlarmDocument)                # raised, escalated, cleared, acknowledged
    .stop()

A fleet's dashboard is pushed nothing: it polls ``structures_document()`` every few seconds for its
overview and, for each structure a browser shows (only those), ``live()`` a few times a second,
its status every second or two, its alarms, new trend rows and spectra after a new window. The
service behind the port may be the fleet in this process or the front of its worker processes
(which forwards ``live``, status and spectra to the structure's worker and reads the rows from the
database): the dashboard cannot tell.

``sensor_states`` maps a topic (``/imu/s1``) to one of ``contract.SENSOR_STATES``. ``x`` is the
estimator state vector read through ``layout`` (``contract.StateLayout``); ``units`` are the
model's unit deformations, whose ``modes`` label trends and spectra (``contract.ModeMap``).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol, runtime_checkable


from contract import (
    SENSOR_STATES,
    AlarmDocument,
    LiveEstimatesDocument,
    ServicePort,
    SpectrumDocument,
    StatusDocument,
    StructureModel,
    StructuresDocument,
    TrendRow,
)

__all__ = ["DashboardService", "FleetDashboardService", "SENSOR_STATES", "StructureModel", "start_dashboard"]

log = logging.getLogger("shm.serve")


@runtime_checkable
class DashboardService(Protocol):
    """What the running service offers the dashboard. All methods are thread-safe."""

    def status(self) -> StatusDocument:
        """The same document as ``GET /api/status`` (thresholds, baseline, sensors, sources…)."""
        ...

    def trends(self, from_s: float | None, to_s: float | None) -> list[TrendRow]:
        """Trend rows (one per window and eigenmode) with ``from_s <= window_start_s < to_s``
        (UNIX seconds; None = open)."""
        ...

    def alarms(self) -> list[AlarmDocument]:
        """All alarms, newest first."""
        ...

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        """Acknowledge an alarm as ``by`` (who: shown with the alarm); same rules as ``POST /api/alarms/{id}/ack``.

        Raises ``PermissionError`` on a missing or wrong token (or when no token is configured),
        ``KeyError`` when the alarm does not exist. Returns the updated alarm.
        """
        ...

    def set_paused(self, paused: bool) -> None:
        """Pause or resume the pushes to the dashboard (the monitoring itself never pauses)."""
        ...


@runtime_checkable
class FleetDashboardService(DashboardService, Protocol):
    """What a fleet offers its dashboard, per structure (ids as ``GET /api/structures`` lists
    them; an unknown id raises KeyError, a structure that cannot answer ``StructureUnavailable``,
    a LookupError). All methods are thread-safe."""

    def structures_document(self) -> StructuresDocument:
        """The same document as ``GET /api/structures`` (state, lag, windows, active alarms)."""
        ...

    def structure_model(self, structure_id: str) -> StructureModel:
        """How to draw the structure (built once per distinct rig by the service)."""
        ...

    def structure_status(self, structure_id: str) -> StatusDocument:
        """As ``GET /api/structures/{id}/status``."""
        ...

    def structure_trends(self, structure_id: str, from_s: float | None, to_s: float | None) -> list[TrendRow]:
        """As ``GET /api/structures/{id}/trends`` (``from_s <= window_start_s < to_s``)."""
        ...

    def structure_alarms(self, structure_id: str) -> list[AlarmDocument]:
        """The structure's alarms, newest first."""
        ...

    def structure_spectra(self, structure_id: str) -> SpectrumDocument | None:
        """Its latest window's spectra (None before its first window)."""
        ...

    def live(self, structure_id: str, after: int = 0) -> LiveEstimatesDocument:
        """Its estimates newer than ``after`` (a sequence number); a call keeps the structure
        keeping them for ``watch_s`` more: a structure nobody polls keeps none."""
        ...


def start_dashboard(service: ServicePort, settings: Any, structure: Any, token: str | None) -> Any:
    """``web.Dashboard`` on ``settings.dashboard`` for the single ``structure`` (a ``Structure``)
    or, with ``structure=None``, for the fleet behind ``service``; None (logged) when it cannot
    start: the monitoring runs without it."""
    try:
        import web

        Dashboard = web.Dashboard
    except (ImportError, AttributeError):
        log.warning("dashboard: web.Dashboard is not available; running without the dashboard")
        return None
    d = settings.dashboard
    try:
        if structure is None:
            dashboard = Dashboard(host=d.host, port=d.port, service=service, fleet=True, token=token)
        else:
            dashboard = Dashboard(host=d.host, port=d.port, rig=structure.rig, units=structure.model.units,
                                  layout=structure.model.state_layout, stations=structure.model.stations,
                                  service=service, token=token)
    except Exception as exc:
        log.warning("dashboard failed to start (%s); running without it", exc)
        return None
    log.info("dashboard at %s%s", getattr(dashboard, "url", "?"), " (the fleet)" if structure is None else "")
    return dashboard
